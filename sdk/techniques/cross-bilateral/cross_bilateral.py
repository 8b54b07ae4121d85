#!/usr/bin/env python3
"""Cross (joint) bilateral filter: each pixel's mean colour is replaced by a
weighted mean of its neighbours' mean colours, the weights coming from the
spatial distance and from how much the neighbours' geometry buffers (normal,
albedo, depth) differ (Eisemann and Durand 2004; Petschnigg et al. 2004).

    w(p, q) = exp(-|p - q|² / 2σs²)
            · exp(-|n_p - n_q|² / 2(σn² + V[n_p] + V[n_q]))
            · exp(-|a_p - a_q|² / 2(σa² + V[a_p] + V[a_q]))
            · exp(-ρ² / 2(σz² + V[ρ]))
            [· exp(-|c_p - c_q|² / 2(k² · 2V̄[c_p] + f² (|c_p|² + |c_q|²)))]

n, a, z, c are per-pixel means of the samples' NORMAL, TEXTURE_COLOR,
DEPTH and COLOR; V[·] is the variance of such a mean (sample variance /
spp), and ρ = (z_p - z_q) / (max(z_p, z_q) + ε) is the depth difference
relative to the farther depth. Adding the variances widens a bandwidth by
the spread the buffer's own noise adds to the differences, so a feature
blurred by depth of field or motion blur stops separating pixels it cannot
tell apart (variance-normalised feature distances, Rousselle, Manzi and
Zwicker 2013, here in additive form).

The bracketed colour term is the `colour` version (this script); the
`features` version (features_only.py) leaves it out. Features alone cannot
see edges with no geometric counterpart: a light source in a ceiling of
the same normal and albedo is smeared over the ceiling. The colour term
measures colour differences against the centre pixel's noise (V̄: its
colour variance averaged over 5×5 pixels, since 4 samples give a very
unreliable variance): a noisy pixel accepts neighbours within its noise, a
clean one (an emitter, the background) rejects different ones, and a
firefly is averaged away without spreading into its clean neighbours.

The result is normalised by Σw, and w(p, p) = 1, so it is exact on constant
images and always finite.
"""

import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

RADIUS = 8            # window 17×17: ±2.7σs, the spatial weight at the edge is 0.03
SIGMA_SPATIAL = 3.0   # pixels
SIGMA_NORMAL = 0.25   # |Δn| of unit normals: 0.25 is an angle of about 14°
SIGMA_ALBEDO = 0.1    # per-channel albedo difference, albedo in [0, 1]
SIGMA_DEPTH = 0.05    # relative depth difference: 5 %
COLOUR_K = 2.0        # colour differences tolerated, in standard deviations of the centre's noise
COLOUR_FLOOR = 0.01   # colour differences below 1 % of the colours' magnitude always tolerated
VARIANCE_WINDOW = 5   # pixels averaged into the centre's colour variance V̄

# Depths that are not a finite distance in front of the camera (a renderer
# may report a miss as inf or as a huge value) become 0, the Embree
# renderer's own convention for a miss, per sample before averaging.
BACKGROUND_DEPTH = 1e20

# Per sample: colour, normal, albedo, depth.
LAYOUT = ["COLOR_R", "COLOR_G", "COLOR_B",
          "NORMAL_X", "NORMAL_Y", "NORMAL_Z",
          "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B",
          "DEPTH"]
FEATURES = {"NORMAL": slice(3, 6), "TEXTURE_COLOR": slice(6, 9), "DEPTH": slice(9, 10)}


def clean_depth(z: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(z) & (z > 0) & (z < BACKGROUND_DEPTH), z, 0.0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ijk,ijk->ij", a, b)


def cross_bilateral(colour: np.ndarray,
                    normal: np.ndarray | None, albedo: np.ndarray | None, depth: np.ndarray | None,
                    var_normal: np.ndarray | float = 0.0, var_albedo: np.ndarray | float = 0.0,
                    var_depth: np.ndarray | float = 0.0,
                    var_colour: np.ndarray | None = None) -> np.ndarray:
    """Filters colour (H, W, 3) guided by the normal (H, W, 3), albedo
    (H, W, 3) and depth (H, W) means; None leaves a feature out. var_*:
    (H, W) variance of each mean, summed over the feature's channels (or a
    scalar). var_colour, if given, adds the colour term."""
    (h, w, _) = colour.shape
    r = RADIUS
    inside = np.zeros((h + 2 * r, w + 2 * r), dtype=bool)
    inside[r:r + h, r:r + w] = True

    def padded(a):
        a = np.broadcast_to(np.asarray(a, dtype=np.float64), (h, w) + np.shape(a)[2:])
        return np.pad(a, [(r, r), (r, r)] + [(0, 0)] * (a.ndim - 2))

    guides = []  # (padded mean, padded variance, σ²) of the vector features
    for (mean, var, sigma) in ((normal, var_normal, SIGMA_NORMAL), (albedo, var_albedo, SIGMA_ALBEDO)):
        if mean is not None:
            guides.append((padded(mean), padded(var), sigma * sigma))
    if depth is not None:
        z = clean_depth(np.asarray(depth, dtype=np.float64))
        # ε keeps ρ finite where both depths are 0 (two background pixels: ρ = 0).
        positive = z[z > 0]
        eps = 1e-3 * (float(positive.mean()) if positive.size else 1.0)
        zp, vzp = padded(z), padded(var_depth)
    c = padded(colour)
    centre = (slice(r, r + h), slice(r, r + w))
    if var_colour is not None:
        noise = 2.0 * COLOUR_K ** 2 * 2.0 * ndimage.uniform_filter(
            np.asarray(var_colour, dtype=np.float64), size=VARIANCE_WINDOW, mode="nearest")
        magnitude = _dot(c[centre], c[centre])

    total = np.zeros((h, w, 3))
    weights = np.zeros((h, w))
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            q = (slice(r + dy, r + dy + h), slice(r + dx, r + dx + w))
            exponent = np.full((h, w), (dx * dx + dy * dy) / (2.0 * SIGMA_SPATIAL ** 2))
            for (mean, var, s2) in guides:
                diff = mean[centre] - mean[q]
                exponent += _dot(diff, diff) / (2.0 * (s2 + var[centre] + var[q]))
            if depth is not None:
                scale = np.maximum(zp[centre], zp[q]) + eps
                rho = (zp[centre] - zp[q]) / scale
                exponent += rho * rho / (2.0 * (SIGMA_DEPTH ** 2 + (vzp[centre] + vzp[q]) / (scale * scale)))
            if var_colour is not None:
                diff = c[centre] - c[q]
                d2 = _dot(diff, diff)
                spread = noise + 2.0 * COLOUR_FLOOR ** 2 * (magnitude + _dot(c[q], c[q]))
                # spread is 0 only where both colours are 0, and then so is d2.
                exponent += np.divide(d2, spread, out=np.zeros_like(d2), where=spread > 0)
            wq = np.exp(-exponent) * inside[q]
            weights += wq
            total += wq[..., None] * c[q]
    return total / weights[..., None]


class PixelStats:
    """Per-pixel mean of every layout component and variance of each mean,
    filled tile by tile."""

    def __init__(self, width: int, height: int, size: int) -> None:
        self.mean = np.zeros((height, width, size))
        self.var = np.zeros((height, width, size))
        self.nonzero = np.zeros(size, dtype=bool)

    def add(self, tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, ns, _) = tile.shape
        (bx, by) = offset
        s = np.asarray(tile, dtype=np.float64)
        s = np.where(np.isfinite(s), s, 0.0)
        s[..., FEATURES["DEPTH"]] = clean_depth(s[..., FEATURES["DEPTH"]])
        self.nonzero |= (s != 0).any(axis=(0, 1, 2))
        self.mean[by:by + ny, bx:bx + nx] = s.mean(axis=2)
        # At 1 spp the variance is unknown: 0, trusting the features fully.
        if ns > 1:
            self.var[by:by + ny, bx:bx + nx] = s.var(axis=2, ddof=1) / ns


def main(colour_term: bool = True) -> None:
    import fbksd.client as fc

    name = "cross-bilateral" + ("" if colour_term else " (features)")
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    (width, height) = (int(info.get("width")), int(info.get("height")))
    spp = int(info.get("max_spp"))
    client.set_sample_layout([*LAYOUT])
    result = client.get_result_buffer()
    stats = PixelStats(width, height, len(LAYOUT))
    client.evaluate_samples(spp, stats.add)

    # A renderer that does not compute a feature fills it with zeros (the
    # procedural renderer does); such a term would be 1 everywhere anyway,
    # so it is left out, and said.
    present = {}
    for feature, part in FEATURES.items():
        present[feature] = bool(stats.nonzero[part].any())
        if not present[feature]:
            print(f"{name}: the renderer provided no {feature} (every sample is 0): "
                  f"filtering without it", file=sys.stderr)
    if colour_term and spp < 2:
        print(f"{name}: no colour variance at 1 spp: filtering without the colour term",
              file=sys.stderr)
    m, v = stats.mean, stats.var
    image = cross_bilateral(
        m[..., 0:3],
        m[..., 3:6] if present["NORMAL"] else None,
        m[..., 6:9] if present["TEXTURE_COLOR"] else None,
        m[..., 9] if present["DEPTH"] else None,
        v[..., 3:6].sum(axis=-1), v[..., 6:9].sum(axis=-1), v[..., 9],
        v[..., 0:3].sum(axis=-1) if colour_term and spp > 1 else None)
    result[...] = image.astype(np.float32)
    client.send_result()


if __name__ == "__main__":
    main(colour_term=True)
