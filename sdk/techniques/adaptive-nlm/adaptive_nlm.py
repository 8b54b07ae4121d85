#!/usr/bin/env python3
"""Adaptive sampling and non-local means filtering, after Rousselle, Knaus
and Zwicker, "Adaptive Rendering with Non-Local Means Filtering", ACM TOG
31(6), SIGGRAPH Asia 2012.

This file owns the technique but the filter: that (steps 2 and 3, and its
parameters) is nl_means.py, linked from nlm, and what is pushed holds the
file itself, so the repository stands alone:

1. A first pass spends a quarter of the budget (at least 2 spp) uniformly,
   at stratified positions the technique writes itself.
2. Every pixel's samples alternate between two half-buffers, A and B. The
   variance of their means comes from the sample variance, calibrated by
   the squared difference of A and B (`mean_variances`).
3. A is filtered with NL-means weights computed on B and B with weights
   computed on A; the image is the mean of the two filtered halves.
4. The squared difference of the filtered halves estimates the remaining
   error of the filtered image; relative to its squared value, it decides
   where the next pass's samples go (in whole samples).
5. Steps 2-4 repeat for a few passes; the last filtering is the result.

Everything lives in per-pixel sums and counts, so a pixel can hold any
number of samples. Positions come from fixed seeds: a run is reproducible.
"""

import os
import sys

# The renderer runs on the same cores: one BLAS thread, not one per core
# competing with it (must be set before numpy loads).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import fbksd.client as fc  # noqa: E402
import numpy as np  # noqa: E402

# The filter, with the paper's parameters (nl_means.py and README.md say why each has its value).
from nl_means import PATCH_RADIUS, box, filter_halves, mean_variances  # noqa: E402

# The sampling schedule.
FIRST_PASS_FRACTION = 0.25  # of the budget, uniformly (at least 2 spp, an even number)
ADAPTIVE_PASSES = 3         # passes after the first, each a share of what is left
RELATIVE_EPSILON = 1e-3     # the relative error is error / (value² + this)
ERROR_RADIUS = PATCH_RADIUS  # the error estimate is averaged over a 7×7 box
SEED = 2012

# Per sample: the position the technique chose, then the colour.
RGB = slice(2, 5)


# ---------------------------------------------------------- the half-buffers

class HalfBuffers:
    """Per-pixel sums of the samples of half A (0) and half B (1).

    A pixel's samples alternate between the halves in the order they
    arrive, so the halves' counts differ by at most one. Which half a
    sample joins never depends on its value, and every half is a set of
    unbiased samples of the pixel, so both half-buffers estimate the pixel.
    """

    def __init__(self, width: int, height: int) -> None:
        (self.width, self.height) = (width, height)
        pixels = width * height
        self.total = np.zeros(pixels, dtype=np.int64)
        self.count = np.zeros((2, pixels))
        self.sum = np.zeros((2, pixels, 3))
        self.squares = np.zeros((2, pixels, 3))

    def add(self, samples: np.ndarray) -> None:
        """Adds rendered samples (n, 5), in the order of the layout."""
        x = np.clip(samples[:, 0].astype(np.int64), 0, self.width - 1)
        y = np.clip(samples[:, 1].astype(np.int64), 0, self.height - 1)
        # Grouped by pixel, in the order of arrival within each pixel.
        order = np.argsort(y * self.width + x, kind="stable")
        pixel = (y * self.width + x)[order]
        # A sample that is not a finite number carries no usable radiance.
        rgb = np.nan_to_num(samples[order, RGB].astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        starts = np.flatnonzero(np.r_[True, pixel[1:] != pixel[:-1]])
        sizes = np.diff(np.r_[starts, len(pixel)])
        group = np.repeat(np.arange(len(starts)), sizes)
        touched = pixel[starts]
        rank = np.arange(len(pixel)) - starts[group]
        half = (self.total[touched][group] + rank) % 2
        for h in (0, 1):
            mine = half == h
            self.count[h, touched] += np.bincount(group[mine], minlength=len(touched))
            for c in range(3):
                value = rgb[mine, c]
                self.sum[h, touched, c] += np.bincount(group[mine], weights=value, minlength=len(touched))
                self.squares[h, touched, c] += np.bincount(group[mine], weights=value ** 2, minlength=len(touched))
        self.total[touched] += sizes

    def filtered(self) -> tuple[np.ndarray, np.ndarray]:
        """The two filtered half-buffers, (H, W, 3) each."""
        shape = (self.height, self.width)
        n = np.maximum(self.count, 1)[..., None]
        (mean_a, mean_b) = (self.sum / n).reshape((2,) + shape + (3,))
        total = np.maximum(self.total, 2)[:, None]
        sums = self.sum.sum(axis=0)
        sample_variance = np.maximum(self.squares.sum(axis=0) - sums ** 2 / total, 0) / (total - 1)
        (n_a, n_b) = n.reshape((2,) + shape + (1,))
        (var_a, var_b) = mean_variances(mean_a, mean_b, n_a, n_b, sample_variance.reshape(shape + (3,)))
        filtered = filter_halves(mean_a, mean_b, var_a, var_b).astype(np.float64)
        return (filtered[0], filtered[1])

    def mean(self) -> np.ndarray:
        """The box filter: each pixel's mean, (H, W, 3)."""
        n = np.maximum(self.total, 1)[:, None]
        return (self.sum.sum(axis=0) / n).reshape(self.height, self.width, 3)


# ----------------------------------------------------------------- sampling

def inside(pixel: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """pixel + fraction as float32, kept below pixel + 1 (rounding could reach it)."""
    position = (pixel + fraction).astype(np.float32)
    return np.minimum(position, np.nextafter((pixel + 1).astype(np.float32), np.float32(0)))


def place_uniform(tile: np.ndarray, offset: tuple[int, int]) -> None:
    """Stratified positions: each half of a pixel's samples (even and odd
    sample indices) is a Latin hypercube of its own, m samples in m columns
    and m rows of the pixel, so each half is stratified by itself."""
    (ny, nx, ns, _) = tile.shape
    (bx, by) = offset
    rng = np.random.default_rng([SEED, 0, bx, by])
    m = ns // 2
    strata = np.broadcast_to(np.arange(m), (ny, nx, m))
    column = (bx + np.arange(nx))[None, :, None]
    row = (by + np.arange(ny))[:, None, None]
    for h in (0, 1):
        tile[:, :, h::2, 0] = inside(column, (strata + rng.random((ny, nx, m))) / m)
        tile[:, :, h::2, 1] = inside(row, (rng.permuted(strata, axis=2) + rng.random((ny, nx, m))) / m)


def whole_samples(count: int, weight: np.ndarray) -> np.ndarray:
    """count samples shared in proportion to weight, as whole numbers
    (floors, then one more for the largest remainders)."""
    if not np.all(np.isfinite(weight)) or weight.sum() <= 0:
        weight = np.ones_like(weight)
    share = count * weight / weight.sum()
    extra = np.floor(share).astype(np.int64)
    leftover = int(count - extra.sum())
    extra[np.argsort(-(share - extra), kind="stable")[:leftover]] += 1
    return extra


def relative_error(filtered_a: np.ndarray, filtered_b: np.ndarray) -> np.ndarray:
    """Estimated squared error of the filtered image relative to its squared
    value, per pixel, flattened. Var[(A' + B') / 2] ≈ (A' - B')² / 4 when the
    filtered halves have independent errors of equal size; one pair per
    pixel is a noisy estimate, hence the average over a small box."""
    image = (filtered_a + filtered_b) / 2
    error = ((filtered_a - filtered_b) ** 2 / 4 / (image ** 2 + RELATIVE_EPSILON)).mean(axis=2)
    return box(error, ERROR_RADIUS).ravel()


def request(client, buffers: HalfBuffers, targets: np.ndarray, width: int, stream: int) -> None:
    """Renders one sample in each pixel of targets (flat pixel indices, with
    repeats), at independent uniform positions in the pixel."""
    cursor = [0]

    def place(samples: np.ndarray) -> None:
        start = cursor[0]
        chunk = targets[start:start + len(samples)]
        cursor[0] = start + len(samples)
        # One generator per chunk, seeded by the pass and the chunk's start: reproducible.
        rng = np.random.default_rng([SEED, stream, start])
        samples[:, 0] = inside(chunk % width, rng.random(len(chunk)))
        samples[:, 1] = inside(chunk // width, rng.random(len(chunk)))

    if len(targets):
        client.evaluate_input_sample_count(len(targets), place, buffers.add)


def main() -> None:
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    (width, height) = (int(info.get("width")), int(info.get("height")))
    pixels = width * height
    client.set_sample_layout([("IMAGE_X", fc.INPUT), ("IMAGE_Y", fc.INPUT), "COLOR_R", "COLOR_G", "COLOR_B"])
    buffers = HalfBuffers(width, height)
    result = client.get_result_buffer()

    budget_spp = client.remaining_samples() // pixels
    if budget_spp < 2:
        print("adaptive-nlm: fewer than 2 samples per pixel, no half-buffers to estimate the "
              "variance from: one sample per pixel in turn, and their mean", file=sys.stderr)
        request(client, buffers, np.arange(client.remaining_samples()) % pixels, width, 0)
        result[:] = buffers.mean()
        client.send_result()
        return

    first_spp = max(2, 2 * int(budget_spp * FIRST_PASS_FRACTION / 2))
    client.evaluate_input_samples(first_spp, place_uniform,
                                  lambda tile, offset: buffers.add(tile.reshape(-1, tile.shape[-1])))

    for number in range(1, ADAPTIVE_PASSES + 1):
        remaining = client.remaining_samples()
        if remaining == 0:
            break
        # An equal share of what is left for each pass still to come, but
        # at least one sample per pixel (on average) per pass; the last pass
        # takes everything.
        passes_left = ADAPTIVE_PASSES - number + 1
        count = remaining // max(1, min(passes_left, remaining // pixels))
        (filtered_a, filtered_b) = buffers.filtered()
        extra = whole_samples(count, relative_error(filtered_a, filtered_b))
        request(client, buffers, np.repeat(np.arange(pixels), extra), width, number)

    (filtered_a, filtered_b) = buffers.filtered()
    image = (filtered_a + filtered_b) / 2
    # Only an overflow could make the filter non-finite: keep those pixels' means.
    result[:] = np.where(np.isfinite(image), image, buffers.mean())
    client.send_result()


if __name__ == "__main__":
    main()
