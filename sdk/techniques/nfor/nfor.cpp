// The NFOR filter: feature prefiltering, collaborative first-order
// regression with cross-half NL-means colour weights, and per-pixel
// selection among candidate filters by an estimated MSE. Written from the
// paper's description (Bitterli et al. 2016); README.md lists the parameters.
//
// Speed: the image is cut into square tiles processed in parallel. For one
// tile, the NL-means distances of every window offset are computed once per
// guide (separable patch sums) and shared by all candidates; the regression
// runs offset by offset over a tile row so the normal equations of the row
// stay in L1 and the inner loops vectorise across pixels. Collaborative
// filtering scatters predictions into neighbouring tiles, so tiles run in
// four phases (tile parity in x and y) that never write the same pixel.
#include "nfor.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>

#ifdef _OPENMP
#include <omp.h>
#endif

// Hot kernels get an AVX2+FMA clone next to the baseline one, picked at run
// time: the image is built once for any x86-64 machine.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define NFOR_HOT __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define NFOR_HOT
#endif

namespace nfor {
namespace {

constexpr int kUnknowns = kFeatureChannels + 1; // intercept + slopes
constexpr int kMatrixTerms = kUnknowns * (kUnknowns + 1) / 2;
constexpr int kTerms = kMatrixTerms + kUnknowns * 3; // normal matrix + right-hand sides
constexpr int kTile = 32;                           // >= 2 * window radius, see the phases
// Keeps an all-zero-variance pair from dividing by zero.
constexpr float kEps = 1e-10f;
// A per-pixel distance this large already gives a zero weight; capping it
// keeps the patch sums finite.
constexpr float kMaxDistance = 1e4f;

using Clock = std::chrono::steady_clock;

// exp(-x) for x >= 0, branch-free so loops over it vectorise: 2^t with t
// split by the round-to-nearest magic number into an integer (exponent
// bits) and a fraction in [-0.5, 0.5] (Taylor series); relative error
// below 1e-5 (from rounding t), and exp(-x) is clamped at 2^-125.
inline float expNeg(float x)
{
    constexpr float kMagic = 12582912.0f; // 1.5 · 2^23
    const float t = std::max(x * -1.44269504f, -125.0f);
    const float shifted = t + kMagic;
    const float f = (t - (shifted - kMagic)) * 0.693147181f;
    const int32_t i = __builtin_bit_cast(int32_t, shifted) - __builtin_bit_cast(int32_t, kMagic);
    const float p = 1.0f + f * (1.0f + f * (0.5f + f * (1.0f / 6 + f * (1.0f / 24 + f * (1.0f / 120 + f * (1.0f / 720))))));
    return p * __builtin_bit_cast(float, (i + 127) << 23);
}

// Mean over the (2R+1)² box clipped to the image, one plane; summed-area table in double.
void boxFilter(const float* in, int W, int H, int R, float* out)
{
    std::vector<double> sat((size_t)(W + 1) * (H + 1), 0.0);
    for (int y = 0; y < H; ++y) {
        double row = 0;
        for (int x = 0; x < W; ++x) {
            row += in[(size_t)y * W + x];
            sat[(size_t)(y + 1) * (W + 1) + x + 1] = sat[(size_t)y * (W + 1) + x + 1] + row;
        }
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; ++y) {
        const int y0 = std::max(0, y - R), y1 = std::min(H, y + R + 1);
        for (int x = 0; x < W; ++x) {
            const int x0 = std::max(0, x - R), x1 = std::min(W, x + R + 1);
            const double s = sat[(size_t)y1 * (W + 1) + x1] - sat[(size_t)y0 * (W + 1) + x1] - sat[(size_t)y1 * (W + 1) + x0] +
                             sat[(size_t)y0 * (W + 1) + x0];
            out[(size_t)y * W + x] = (float)(s / ((double)(x1 - x0) * (y1 - y0)));
        }
    }
}

// An NL-means guide: mean and variance planes, padded by replicating the border.
struct Guide {
    int C = 0, W = 0, H = 0, P = 0, Wp = 0;
    size_t plane = 0;
    std::vector<float> mean, var;
    std::ptrdiff_t index(int x, int y) const { return (std::ptrdiff_t)(y + P) * Wp + (x + P); }
};

Guide makeGuide(const float* mean, const float* var, int C, int W, int H, int P)
{
    Guide g;
    g.C = C, g.W = W, g.H = H, g.P = P, g.Wp = W + 2 * P;
    g.plane = (size_t)g.Wp * (H + 2 * P);
    g.mean.resize(g.plane * C);
    g.var.resize(g.plane * C);
    const size_t N = (size_t)W * H;
    for (int c = 0; c < C; ++c)
        for (int y = -P; y < H + P; ++y) {
            const int sy = std::min(std::max(y, 0), H - 1);
            for (int x = -P; x < W + P; ++x) {
                const int sx = std::min(std::max(x, 0), W - 1);
                const size_t s = c * N + (size_t)sy * W + sx, d = c * g.plane + g.index(x, y);
                g.mean[d] = mean[s];
                g.var[d] = var[s];
            }
        }
    return g;
}

struct Tile {
    int x0, y0, w, h;
};

std::vector<Tile> tiles(int W, int H)
{
    std::vector<Tile> out;
    for (int y = 0; y < H; y += kTile)
        for (int x = 0; x < W; x += kTile)
            out.push_back(Tile{x, y, std::min(kTile, W - x), std::min(kTile, H - y)});
    return out;
}

// Per-pixel NL-means distance between p and p + (dx, dy) (Rousselle et al.'s
// variance-cancelling form), over the tile grown by `apron`; row stride w + 2·apron.
NFOR_HOT void pixelDistances(const Guide& g, const Tile& t, int apron, int dx, int dy, float* D)
{
    const int rw = t.w + 2 * apron, rh = t.h + 2 * apron;
    const float invC = 1.0f / (float)g.C;
    const std::ptrdiff_t shift = (std::ptrdiff_t)dy * g.Wp + dx;
    for (int ry = 0; ry < rh; ++ry) {
        float* __restrict out = D + (size_t)ry * rw;
        const std::ptrdiff_t p = g.index(t.x0 - apron, t.y0 - apron + ry);
        for (int i = 0; i < rw; ++i)
            out[i] = 0.0f;
        for (int c = 0; c < g.C; ++c) {
            const float* __restrict mp = g.mean.data() + c * g.plane + p;
            const float* __restrict vp = g.var.data() + c * g.plane + p;
            const float* __restrict mq = mp + shift;
            const float* __restrict vq = vp + shift;
            for (int i = 0; i < rw; ++i) {
                const float d = mp[i] - mq[i], a = vp[i], b = vq[i];
                out[i] += (d * d - (a + std::min(a, b))) / (kEps + a + b);
            }
        }
        for (int i = 0; i < rw; ++i)
            out[i] = std::min(out[i] * invC, kMaxDistance);
    }
}

// Patch distance: the mean of D over the (2f+1)² patch around each tile
// pixel, written at dist[ty * kTile + tx]. V: scratch of one region row.
NFOR_HOT void patchAverage(const float* D, const Tile& t, int apron, int f, float* V, float* dist)
{
    const int rw = t.w + 2 * apron;
    const float inv = 1.0f / (float)((2 * f + 1) * (2 * f + 1));
    float* __restrict v = V;
    for (int ty = 0; ty < t.h; ++ty) {
        // Column sums over the patch rows, slid down by one row at a time
        // (D is capped, so the float running sum stays accurate).
        const float* top = D + (size_t)(ty + apron - f) * rw;
        if (ty == 0) {
            for (int i = 0; i < rw; ++i)
                v[i] = top[i];
            for (int k = 1; k <= 2 * f; ++k) {
                const float* __restrict r = top + (size_t)k * rw;
                for (int i = 0; i < rw; ++i)
                    v[i] += r[i];
            }
        } else {
            const float* __restrict in = top + (size_t)(2 * f) * rw;
            const float* __restrict gone = top - rw;
            for (int i = 0; i < rw; ++i)
                v[i] += in[i] - gone[i];
        }
        float* __restrict out = dist + (size_t)ty * kTile;
        for (int tx = 0; tx < t.w; ++tx)
            out[tx] = 0.0f;
        for (int k = -f; k <= f; ++k) {
            const float* __restrict s = v + apron + k;
            for (int tx = 0; tx < t.w; ++tx)
                out[tx] += s[tx];
        }
        for (int tx = 0; tx < t.w; ++tx)
            out[tx] *= inv;
    }
}

NFOR_HOT void toWeights(const float* dist, size_t n, float invK2, float* w)
{
    for (size_t i = 0; i < n; ++i)
        w[i] = expNeg(std::max(dist[i], 0.0f) * invK2);
}

// Columns [lo, hi) of tile row ty whose neighbour at (dx, dy) lies in the image; false if none.
bool span(const Tile& t, int ty, int dx, int dy, int W, int H, int& lo, int& hi)
{
    const int yi = t.y0 + ty + dy;
    if (yi < 0 || yi >= H)
        return false;
    lo = std::max(0, -(t.x0 + dx));
    hi = std::min(t.w, W - (t.x0 + dx));
    return lo < hi;
}

// acc[c][tx] += w · data[c](neighbour), acc[C][tx] += w, over one row span.
NFOR_HOT void gatherSpan(const float* w, const float* data, size_t N, int C, int lo, int hi, float* acc)
{
    for (int c = 0; c < C; ++c) {
        const float* __restrict d = data + c * N;
        float* __restrict a = acc + c * kTile;
        for (int tx = lo; tx < hi; ++tx)
            a[tx] += w[tx] * d[tx];
    }
    float* __restrict a = acc + C * kTile;
    for (int tx = lo; tx < hi; ++tx)
        a[tx] += w[tx];
}

// NL-means (gather form): out = Σ w·data / Σ w over the (2r+1)² window, weights from `g`.
void nlMeans(const Guide& g, int r, int f, float k, const float* data, int C, float* out)
{
    const int W = g.W, H = g.H;
    const size_t N = (size_t)W * H;
    const std::vector<Tile> all = tiles(W, H);
    const float invK2 = 1.0f / (k * k);
#pragma omp parallel
    {
        std::vector<float> D((size_t)(kTile + 2 * f) * (kTile + 2 * f)), V(kTile + 2 * f);
        std::vector<float> dist(kTile * kTile), w(kTile * kTile), acc((size_t)(C + 1) * kTile * kTile);
#pragma omp for schedule(dynamic)
        for (size_t ti = 0; ti < all.size(); ++ti) {
            const Tile t = all[ti];
            std::fill(acc.begin(), acc.end(), 0.0f);
            for (int dy = -r; dy <= r; ++dy)
                for (int dx = -r; dx <= r; ++dx) {
                    pixelDistances(g, t, f, dx, dy, D.data());
                    patchAverage(D.data(), t, f, f, V.data(), dist.data());
                    toWeights(dist.data(), dist.size(), invK2, w.data());
                    for (int ty = 0; ty < t.h; ++ty) {
                        int lo, hi;
                        if (!span(t, ty, dx, dy, W, H, lo, hi))
                            continue;
                        const size_t n0 = (size_t)(t.y0 + ty + dy) * W + t.x0 + dx;
                        gatherSpan(w.data() + ty * kTile, data + n0, N, C, lo, hi,
                                   acc.data() + (size_t)ty * kTile * (C + 1));
                    }
                }
            for (int ty = 0; ty < t.h; ++ty) {
                const float* a = acc.data() + (size_t)ty * kTile * (C + 1);
                for (int tx = 0; tx < t.w; ++tx) {
                    const size_t i = (size_t)(t.y0 + ty) * W + t.x0 + tx;
                    const float ws = a[C * kTile + tx]; // >= 1: a pixel's weight to itself is 1
                    for (int c = 0; c < C; ++c)
                        out[c * N + i] = ws > 0.0f ? a[c * kTile + tx] / ws : data[c * N + i];
                }
            }
        }
    }
}

// Normal equations of one row span for K window offsets (dx, dy + k),
// k < K: with x = [1, F(neighbour) − F(centre)], M += w·x·xᵀ (upper
// triangle) and R += w·x·yᵀ. acc[term][tx], term-major, kTile columns.
// Neighbour k's features, colour and weights are at k·rows, k·rows and
// k·wRows past those of neighbour 0. Taking K = 2 neighbours per call
// halves the loads and stores of the accumulators, the kernel's bottleneck.
template<int K>
inline __attribute__((always_inline)) void accumulateBody(const float* w, size_t wRows, const float* Fc, const float* Fn,
                                                          const float* Yn, size_t rows, size_t N, int lo, int hi, float* acc)
{
#pragma omp simd
    for (int tx = lo; tx < hi; ++tx) {
        float x[K][kUnknowns], y[K][3], ww[K];
#pragma GCC unroll 4
        for (int k = 0; k < K; ++k) {
            ww[k] = w[k * wRows + tx];
            x[k][0] = 1.0f;
#pragma GCC unroll 8
            for (int j = 0; j < kFeatureChannels; ++j)
                x[k][j + 1] = Fn[k * rows + j * N + tx] - Fc[j * N + tx];
#pragma GCC unroll 4
            for (int c = 0; c < 3; ++c)
                y[k][c] = Yn[k * rows + c * N + tx];
        }
        int m = 0;
#pragma GCC unroll 8
        for (int a = 0; a < kUnknowns; ++a) {
            float s[K];
#pragma GCC unroll 4
            for (int k = 0; k < K; ++k)
                s[k] = ww[k] * x[k][a];
#pragma GCC unroll 8
            for (int b = a; b < kUnknowns; ++b, ++m) {
                float sum = acc[m * kTile + tx];
#pragma GCC unroll 4
                for (int k = 0; k < K; ++k)
                    sum += s[k] * x[k][b];
                acc[m * kTile + tx] = sum;
            }
#pragma GCC unroll 4
            for (int c = 0; c < 3; ++c) {
                float sum = acc[(kMatrixTerms + 3 * a + c) * kTile + tx];
#pragma GCC unroll 4
                for (int k = 0; k < K; ++k)
                    sum += s[k] * y[k][c];
                acc[(kMatrixTerms + 3 * a + c) * kTile + tx] = sum;
            }
        }
    }
}

NFOR_HOT void accumulate1(const float* w, const float* Fc, const float* Fn, const float* Yn, size_t N, int lo, int hi, float* acc)
{
    accumulateBody<1>(w, 0, Fc, Fn, Yn, 0, N, lo, hi, acc);
}

NFOR_HOT void accumulate2(const float* w, size_t wRows, const float* Fc, const float* Fn, const float* Yn, size_t rows, size_t N,
                          int lo, int hi, float* acc)
{
    accumulateBody<2>(w, wRows, Fc, Fn, Yn, rows, N, lo, hi, acc);
}

// Collaborative step for one row span and K offsets (dx, dy + k): each
// centre's fit predicts its neighbours, accumulated with the regression
// weight. beta[term][tx] with stride kTile·kTile; out: RGB and weight
// planes at neighbour 0, neighbour k at k·rows past it. K = 2 shares the
// loads of the coefficients.
template<int K>
inline __attribute__((always_inline)) void scatterBody(const float* w, size_t wRows, const float* beta, const float* Fc,
                                                       const float* Fn, size_t rows, size_t N, int lo, int hi, float* out)
{
    constexpr size_t B = (size_t)kTile * kTile;
#pragma omp simd
    for (int tx = lo; tx < hi; ++tx) {
        float p[K][3];
#pragma GCC unroll 4
        for (int k = 0; k < K; ++k)
            for (int c = 0; c < 3; ++c)
                p[k][c] = beta[c * B + tx];
#pragma GCC unroll 8
        for (int j = 0; j < kFeatureChannels; ++j) {
            const float fc = Fc[j * N + tx];
            const float b0 = beta[(3 * j + 3) * B + tx], b1 = beta[(3 * j + 4) * B + tx], b2 = beta[(3 * j + 5) * B + tx];
#pragma GCC unroll 4
            for (int k = 0; k < K; ++k) {
                const float x = Fn[k * rows + j * N + tx] - fc;
                p[k][0] += b0 * x;
                p[k][1] += b1 * x;
                p[k][2] += b2 * x;
            }
        }
#pragma GCC unroll 4
        for (int k = 0; k < K; ++k) {
            const float ww = w[k * wRows + tx];
            float* o = out + k * rows;
            o[tx] += ww * p[k][0];
            o[N + tx] += ww * p[k][1];
            o[2 * N + tx] += ww * p[k][2];
            o[3 * N + tx] += ww;
        }
    }
}

NFOR_HOT void scatter1(const float* w, const float* beta, const float* Fc, const float* Fn, size_t N, int lo, int hi, float* out)
{
    scatterBody<1>(w, 0, beta, Fc, Fn, 0, N, lo, hi, out);
}

NFOR_HOT void scatter2(const float* w, size_t wRows, const float* beta, const float* Fc, const float* Fn, size_t rows, size_t N,
                       int lo, int hi, float* out)
{
    scatterBody<2>(w, wRows, beta, Fc, Fn, rows, N, lo, hi, out);
}

// Solves the ridge-regularised normal equations of the first n centres of
// a tile row (Cholesky in double, vectorised across centres). A centre whose
// system is still not positive definite, or whose solution is not finite,
// falls back to the intercept alone: the NL-means weighted mean.
// beta[(3·unknown + channel) · stride + tx].
NFOR_HOT void solveRow(const float* acc, int n, float ridge, float* beta, size_t stride)
{
    // Packed upper-triangle index of (a, b), a <= b, as accumulated.
    auto upper = [](int a, int b) { return a * kUnknowns - a * (a - 1) / 2 + (b - a); };
    double L[kUnknowns][kUnknowns][kTile], inv[kUnknowns][kTile], X[kUnknowns][3][kTile];
    double w0[kTile], ok[kTile], s[kTile];
    for (int tx = 0; tx < n; ++tx) {
        w0[tx] = acc[tx];
        ok[tx] = w0[tx] > 0.0 && std::isfinite(w0[tx]) ? 1.0 : 0.0;
    }
    for (int i = 0; i < kUnknowns; ++i)
        for (int j = 0; j <= i; ++j) {
            const float* m = acc + (size_t)upper(j, i) * kTile;
            for (int tx = 0; tx < n; ++tx)
                s[tx] = m[tx];
            for (int k = 0; k < j; ++k)
                for (int tx = 0; tx < n; ++tx)
                    s[tx] -= L[i][k][tx] * L[j][k][tx];
            if (i != j) {
                for (int tx = 0; tx < n; ++tx)
                    L[i][j][tx] = s[tx] * inv[j][tx];
                continue;
            }
            const double r = i > 0 ? ridge : 0.0;
            for (int tx = 0; tx < n; ++tx) {
                const double d = s[tx] + r * w0[tx];
                const bool good = d > 1e-12 * w0[tx];
                ok[tx] = good ? ok[tx] : 0.0;
                L[i][i][tx] = std::sqrt(good ? d : 1.0); // keeps a bad lane finite; its result is replaced
                inv[i][tx] = 1.0 / L[i][i][tx];
            }
        }
    for (int c = 0; c < 3; ++c) {
        for (int i = 0; i < kUnknowns; ++i) {
            const float* rhs = acc + (size_t)(kMatrixTerms + 3 * i + c) * kTile;
            for (int tx = 0; tx < n; ++tx)
                s[tx] = rhs[tx];
            for (int k = 0; k < i; ++k)
                for (int tx = 0; tx < n; ++tx)
                    s[tx] -= L[i][k][tx] * X[k][c][tx];
            for (int tx = 0; tx < n; ++tx)
                X[i][c][tx] = s[tx] * inv[i][tx];
        }
        for (int i = kUnknowns - 1; i >= 0; --i) {
            for (int tx = 0; tx < n; ++tx)
                s[tx] = X[i][c][tx];
            for (int k = i + 1; k < kUnknowns; ++k)
                for (int tx = 0; tx < n; ++tx)
                    s[tx] -= L[k][i][tx] * X[k][c][tx];
            for (int tx = 0; tx < n; ++tx)
                X[i][c][tx] = s[tx] * inv[i][tx];
        }
    }
    for (int tx = 0; tx < n; ++tx) {
        bool good = ok[tx] != 0.0;
        for (int i = 0; i < kUnknowns; ++i)
            for (int c = 0; c < 3; ++c)
                good = good && std::isfinite(X[i][c][tx]);
        for (int i = 0; i < kUnknowns; ++i)
            for (int c = 0; c < 3; ++c) {
                const double mean = w0[tx] > 0.0 ? acc[(size_t)(kMatrixTerms + c) * kTile + tx] / w0[tx] : 0.0;
                const double v = good ? X[i][c][tx] : (i == 0 ? mean : 0.0);
                beta[(3 * i + c) * stride + tx] = (float)v;
            }
    }
}

// What the regression of one tile needs besides its weights.
struct RegressionData {
    int W, H, r;
    float ridge;
    const float* F; // normalised prefiltered features, kFeatureChannels planes
};

// First-order regression of colour Y over one tile, weights w[offset][ty·kTile + tx],
// then the collaborative scatter into out (RGB + weight planes).
void regressTile(const RegressionData& d, const Tile& t, const float* w, const float* Y, float* acc, float* beta, float* out)
{
    const int W = d.W, H = d.H, r = d.r, side = 2 * r + 1;
    const size_t N = (size_t)W * H;
    constexpr size_t TT = (size_t)kTile * kTile;
    // Offsets go by column dx, two rows dy at a time (see accumulateBody).
    auto visit = [&](int ty, auto&& one, auto&& two) {
        const int y = t.y0 + ty;
        const int dyLo = std::max(-r, -y), dyHi = std::min(r, H - 1 - y);
        const size_t c0 = (size_t)y * W + t.x0;
        for (int dx = -r; dx <= r; ++dx) {
            const int lo = std::max(0, -(t.x0 + dx)), hi = std::min(t.w, W - (t.x0 + dx));
            if (lo >= hi)
                continue;
            for (int dy = dyLo; dy <= dyHi; dy += 2) {
                const size_t n0 = (size_t)((std::ptrdiff_t)c0 + (std::ptrdiff_t)dy * W + dx);
                const float* wo = w + (size_t)((dy + r) * side + dx + r) * TT + ty * kTile;
                if (dy < dyHi)
                    two(wo, c0, n0, lo, hi);
                else
                    one(wo, c0, n0, lo, hi);
            }
        }
    };
    const size_t wRows = (size_t)side * TT;
    for (int ty = 0; ty < t.h; ++ty) {
        std::fill(acc, acc + (size_t)kTerms * kTile, 0.0f);
        visit(
            ty, [&](const float* wo, size_t c0, size_t n0, int lo, int hi) { accumulate1(wo, d.F + c0, d.F + n0, Y + n0, N, lo, hi, acc); },
            [&](const float* wo, size_t c0, size_t n0, int lo, int hi) {
                accumulate2(wo, wRows, d.F + c0, d.F + n0, Y + n0, W, N, lo, hi, acc);
            });
        solveRow(acc, t.w, d.ridge, beta + (size_t)ty * kTile, TT);
    }
    for (int ty = 0; ty < t.h; ++ty) {
        const float* b = beta + (size_t)ty * kTile;
        visit(
            ty, [&](const float* wo, size_t c0, size_t n0, int lo, int hi) { scatter1(wo, b, d.F + c0, d.F + n0, N, lo, hi, out + n0); },
            [&](const float* wo, size_t c0, size_t n0, int lo, int hi) {
                scatter2(wo, wRows, b, d.F + c0, d.F + n0, W, N, lo, hi, out + n0);
            });
    }
}

void logLine(std::string* log, const char* fmt, double a = 0, double b = 0)
{
    if (!log)
        return;
    char line[256];
    std::snprintf(line, sizeof line, fmt, a, b);
    *log += line;
    *log += '\n';
}

double seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

} // namespace

std::vector<float> denoise(const Input& in, const Params& params, std::string* log)
{
    const int W = in.width, H = in.height;
    const size_t N = (size_t)W * H;
    const bool single = in.spp < 2;
    const int halves = single ? 1 : 2;
    const int r = params.windowRadius;
    auto start = Clock::now();
#ifdef _OPENMP
    logLine(log, "threads: %.0f", omp_get_max_threads());
#endif

    // Colour and feature statistics: [h] is half h (single: only [0]).
    std::vector<float> Y[2], Yvar[2], F[2], Fvar[2];
    for (int h = 0; h < halves; ++h) {
        Y[h] = in.color[h];
        Yvar[h] = in.colorVar[h];
        F[h] = in.feature[h];
        Fvar[h] = in.featureVar[h];
    }
    const double nA = single ? 1.0 : (double)((in.spp + 1) / 2), nB = single ? 0.0 : (double)(in.spp / 2);
    if (single) {
        // One sample per pixel: the variance of the mean is that of the
        // sample, estimated from the 3×3 neighbourhood.
        auto spatial = [&](const std::vector<float>& mean, int C, std::vector<float>& var) {
            var.assign(mean.size(), 0.0f);
            std::vector<float> sq(N), m(N), m2(N);
            for (int c = 0; c < C; ++c) {
                for (size_t i = 0; i < N; ++i)
                    sq[i] = mean[c * N + i] * mean[c * N + i];
                boxFilter(mean.data() + c * N, W, H, 1, m.data());
                boxFilter(sq.data(), W, H, 1, m2.data());
                for (size_t i = 0; i < N; ++i)
                    var[c * N + i] = std::max(0.0f, m2[i] - m[i] * m[i]);
            }
        };
        spatial(Y[0], 3, Yvar[0]);
        spatial(F[0], kFeatureChannels, Fvar[0]);
    } else {
        // Correlated (stratified) samples make the sample variance
        // overestimate the variance of the mean; the squared half-buffer
        // difference is unbiased but noisy. Scale the former by their ratio,
        // both box-smoothed.
        std::vector<float> half(N), sample(N), hs(N), ss(N);
        for (size_t i = 0; i < N; ++i) {
            double a = 0, b = 0;
            for (int c = 0; c < 3; ++c) {
                const double d = Y[0][c * N + i] - Y[1][c * N + i];
                a += d * d * (nA * nB) / ((nA + nB) * (nA + nB)); // (Y_A − Y_B)² · n_A n_B / n² estimates var(Y)
                b += Yvar[0][c * N + i] * nA / (nA + nB);          // s² / n
            }
            half[i] = (float)a;
            sample[i] = (float)b;
        }
        boxFilter(half.data(), W, H, params.varianceRatioRadius, hs.data());
        boxFilter(sample.data(), W, H, params.varianceRatioRadius, ss.data());
        double sumRatio = 0;
        for (size_t i = 0; i < N; ++i) {
            const float ratio = std::min(std::max((hs[i] + 1e-12f) / (ss[i] + 1e-12f), 0.0625f), 16.0f);
            sumRatio += ratio;
            for (int h = 0; h < 2; ++h)
                for (int c = 0; c < 3; ++c)
                    Yvar[h][c * N + i] *= ratio;
        }
        logLine(log, "half-buffer / sample variance ratio: mean %.3f", sumRatio / (double)N);
    }
    logLine(log, "statistics: %.3f s", seconds(start));

    // Feature prefiltering: each half filtered with NL-means weights from
    // the other half (its own at 1 spp), per feature group.
    auto stage = Clock::now();
    std::vector<float> features(kFeatureChannels * N);
    {
        const int P = params.prefilterRadius + params.prefilterPatch;
        std::vector<float> filtered[2];
        for (int h = 0; h < halves; ++h)
            filtered[h].resize(kFeatureChannels * N);
        for (int g = 0; g < kFeatureGroups; ++g) {
            const int c0 = kGroupBegin[g], C = kGroupBegin[g + 1] - c0;
            for (int h = 0; h < halves; ++h) {
                const int other = single ? 0 : 1 - h;
                const Guide guide = makeGuide(F[other].data() + c0 * N, Fvar[other].data() + c0 * N, C, W, H, P);
                nlMeans(guide, params.prefilterRadius, params.prefilterPatch, params.prefilterK, F[h].data() + c0 * N, C,
                        filtered[h].data() + c0 * N);
            }
        }
        for (size_t i = 0; i < kFeatureChannels * N; ++i)
            features[i] = single ? filtered[0][i] : 0.5f * (filtered[0][i] + filtered[1][i]);
    }
    // Global standardisation: the ridge then means the same for every feature
    // and scene scale; a constant feature becomes 0 and drops out.
    for (int c = 0; c < kFeatureChannels; ++c) {
        float* f = features.data() + c * N;
        double s = 0, s2 = 0;
        for (size_t i = 0; i < N; ++i)
            s += f[i];
        const double mean = s / (double)N;
        for (size_t i = 0; i < N; ++i)
            s2 += (f[i] - mean) * (f[i] - mean);
        const double sd = std::sqrt(s2 / (double)N);
        const double scale = sd > 1e-6 * (std::fabs(mean) + 1e-30) && sd > 1e-30 ? 1.0 / sd : 0.0;
        for (size_t i = 0; i < N; ++i)
            f[i] = (float)((f[i] - mean) * scale);
    }
    logLine(log, "feature prefilter: %.3f s", seconds(stage));

    // Candidate regressions: half h is fitted with colour weights from the other half.
    stage = Clock::now();
    const std::vector<Candidate> candidates = single ? std::vector<Candidate>{params.singleBuffer} : params.candidates;
    const int nc = (int)candidates.size();
    std::vector<int> radii; // distinct patch radii, their distances shared by candidates
    for (const Candidate& c : candidates)
        if (std::find(radii.begin(), radii.end(), c.patchRadius) == radii.end())
            radii.push_back(c.patchRadius);
    const int fmax = *std::max_element(radii.begin(), radii.end());
    std::vector<Guide> guides;
    for (int h = 0; h < halves; ++h)
        guides.push_back(makeGuide(Y[h].data(), Yvar[h].data(), 3, W, H, r + fmax));
    std::vector<std::vector<float>> outs((size_t)nc * halves, std::vector<float>(4 * N, 0.0f));
    const RegressionData rd{W, H, r, params.ridge, features.data()};
    const std::vector<Tile> all = tiles(W, H);
    const int tilesX = (W + kTile - 1) / kTile;
    const int offsets = (2 * r + 1) * (2 * r + 1);
    constexpr size_t TT = (size_t)kTile * kTile;
    for (int phase = 0; phase < 4; ++phase) {
#pragma omp parallel
        {
            const int rw = kTile + 2 * fmax;
            std::vector<float> D((size_t)rw * rw), V(rw), dist(radii.size() * offsets * TT), w(offsets * TT);
            std::vector<float> acc((size_t)kTerms * kTile), beta((size_t)kUnknowns * 3 * TT);
#pragma omp for schedule(dynamic)
            for (size_t ti = 0; ti < all.size(); ++ti) {
                const int tx = (int)(ti % tilesX), ty = (int)(ti / tilesX);
                if ((tx & 1) + 2 * (ty & 1) != phase)
                    continue;
                const Tile t = all[ti];
                for (int h = 0; h < halves; ++h) {
                    const Guide& guide = guides[single ? 0 : 1 - h];
                    int o = 0;
                    for (int dy = -r; dy <= r; ++dy)
                        for (int dx = -r; dx <= r; ++dx, ++o) {
                            pixelDistances(guide, t, fmax, dx, dy, D.data());
                            for (size_t u = 0; u < radii.size(); ++u)
                                patchAverage(D.data(), t, fmax, radii[u], V.data(), dist.data() + (u * offsets + o) * TT);
                        }
                    for (int c = 0; c < nc; ++c) {
                        const size_t u = std::find(radii.begin(), radii.end(), candidates[c].patchRadius) - radii.begin();
                        toWeights(dist.data() + u * offsets * TT, (size_t)offsets * TT,
                                  1.0f / (candidates[c].k * candidates[c].k), w.data());
                        regressTile(rd, t, w.data(), Y[h].data(), acc.data(), beta.data(), outs[(size_t)c * halves + h].data());
                    }
                }
            }
        }
    }
    // Normalise the collaborative sums; every pixel has its own fit's weight 1.
    for (auto& o : outs)
        for (size_t i = 0; i < N; ++i) {
            const float ws = o[3 * N + i];
            for (int c = 0; c < 3; ++c)
                o[c * N + i] = ws > 0.0f ? o[c * N + i] / ws : 0.0f;
        }
    logLine(log, "regression (%.0f candidates): %.3f s", nc, seconds(stage));

    stage = Clock::now();
    std::vector<float> result(3 * N);
    std::vector<float> Yall(3 * N);
    for (size_t i = 0; i < 3 * N; ++i)
        Yall[i] = single ? Y[0][i] : (float)((nA * Y[0][i] + nB * Y[1][i]) / (nA + nB));
    if (single) {
        for (size_t i = 0; i < 3 * N; ++i)
            result[i] = outs[0][i];
    } else {
        // Selection: per candidate, variance of the output ≈ (A − B)²/4 and
        // bias ≈ output − input, both smoothed with NL-means weights of the
        // mean output (smoothing the signed residual averages its noise away
        // while the edge-aware weights keep a bias from cancelling across an
        // edge); then each pixel blends the candidates by smoothed indicators
        // of the lowest estimated MSE.
        std::vector<float> combined((size_t)nc * 3 * N), guideMean(3 * N, 0.0f), guideVar(3 * N, 0.0f);
        std::vector<float> data((size_t)nc * 6 * N);
        for (int c = 0; c < nc; ++c) {
            const float* a = outs[(size_t)c * 2].data();
            const float* b = outs[(size_t)c * 2 + 1].data();
            for (size_t i = 0; i < 3 * N; ++i) {
                const float m = 0.5f * (a[i] + b[i]), v = 0.25f * (a[i] - b[i]) * (a[i] - b[i]);
                combined[c * 3 * N + i] = m;
                data[(c * 6) * N + i] = m - Yall[i];
                data[(c * 6 + 3) * N + i] = v;
                guideMean[i] += m / (float)nc;
                guideVar[i] += v / (float)nc;
            }
        }
        std::vector<float> smoothVar(3 * N);
        for (int c = 0; c < 3; ++c)
            boxFilter(guideVar.data() + c * N, W, H, 1, smoothVar.data() + c * N);
        const Guide guide = makeGuide(guideMean.data(), smoothVar.data(), 3, W, H, params.selectionRadius + params.selectionPatch);
        std::vector<float> smoothed(data.size());
        nlMeans(guide, params.selectionRadius, params.selectionPatch, params.selectionK, data.data(), nc * 6, smoothed.data());
        std::vector<float> indicator((size_t)nc * N, 0.0f), blend((size_t)nc * N);
        std::vector<double> chosen(nc, 0.0);
        for (size_t i = 0; i < N; ++i) {
            int best = 0;
            float bestMse = INFINITY;
            for (int c = 0; c < nc; ++c) {
                float mse = 0;
                for (int ch = 0; ch < 3; ++ch) {
                    const float bias = smoothed[(c * 6 + ch) * N + i];
                    mse += bias * bias + smoothed[(c * 6 + 3 + ch) * N + i];
                }
                if (mse < bestMse) {
                    bestMse = mse;
                    best = c;
                }
            }
            indicator[best * N + i] = 1.0f;
            chosen[best] += 1.0;
        }
        nlMeans(guide, params.selectionRadius, params.selectionPatch, params.selectionK, indicator.data(), nc, blend.data());
        for (size_t i = 0; i < N; ++i) {
            float total = 0;
            for (int c = 0; c < nc; ++c)
                total += blend[c * N + i];
            for (int ch = 0; ch < 3; ++ch) {
                float v = 0;
                for (int c = 0; c < nc; ++c)
                    v += blend[c * N + i] * combined[(c * 3 + ch) * N + i];
                result[ch * N + i] = total > 0.0f ? v / total : combined[ch * N + i];
            }
        }
        for (int c = 0; c < nc; ++c)
            logLine(log, "candidate %.0f chosen at %.1f%% of pixels", c, 100.0 * chosen[c] / (double)N);
    }
    logLine(log, "selection: %.3f s", seconds(stage));

    // Interleave; any non-finite value falls back to the pixel mean. A
    // first-order fit can overshoot below zero next to dark edges: where a
    // channel's input is nowhere negative, its output is clamped at zero.
    std::vector<float> rgb(3 * N);
    size_t fallbacks = 0;
    for (int c = 0; c < 3; ++c) {
        const float floor = *std::min_element(Yall.begin() + c * N, Yall.begin() + (c + 1) * N) >= 0.0f ? 0.0f : -INFINITY;
        for (size_t i = 0; i < N; ++i) {
            float v = result[c * N + i];
            if (!std::isfinite(v)) {
                v = std::isfinite(Yall[c * N + i]) ? Yall[c * N + i] : 0.0f;
                ++fallbacks;
            }
            rgb[3 * i + c] = std::max(v, floor);
        }
    }
    logLine(log, "non-finite values replaced: %.0f; total %.3f s", (double)fallbacks, seconds(start));
    return rgb;
}

} // namespace nfor
