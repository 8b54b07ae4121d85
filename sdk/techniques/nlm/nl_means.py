"""The non-local means filter of Rousselle, Knaus and Zwicker, "Adaptive
Rendering with Non-Local Means Filtering", ACM TOG 31(6), SIGGRAPH Asia
2012, shared by the nlm denoiser and the adaptive-nlm sampler.

Owns the filter and its parameters, given two half-buffers A and B of a
pixel's samples and their sample variance:

- ``mean_variances``: the variance of each half-buffer mean, the sample
  variance calibrated by the squared difference of the two halves;
- ``cross_filter``: NL-means, each buffer filtered with weights computed on
  the other (a buffer's weights never depend on its own noise);
- ``filter_halves``: the two filtered halves, from the means and variances;
- ``box``: the window mean both of these use.

How the halves are filled, and what is made of the filtered halves, is the
techniques'. nlm/README.md documents the method and every parameter;
adaptive-nlm links this file from nlm, and what is pushed holds the file
itself. No fbksd import: the filter runs on plain arrays.
"""

import numpy as np
from scipy.ndimage import uniform_filter

# The parameters of the paper; nlm/README.md says why each has its value.
WINDOW_RADIUS = 10     # r: neighbours q lie in the 21×21 window around p
PATCH_RADIUS = 3       # f: patches are 7×7
K = 0.45               # k: filter strength (bandwidth in units of the noise)
ALPHA = 1.0            # α: strength of the variance cancellation
EPSILON = 1e-10        # ε: keeps the distance finite where the variance is 0
VARIANCE_RADIUS = 10   # the calibration of the sample variance averages over 21×21


def box(image: np.ndarray, radius: int) -> np.ndarray:
    """Mean over the (2·radius + 1)² window around each pixel of (H, W, ...)."""
    size = (2 * radius + 1, 2 * radius + 1) + (1,) * (image.ndim - 2)
    return uniform_filter(image, size=size, mode="reflect")


def mean_variances(mean_a, mean_b, n_a, n_b, sample_variance):
    """Variance of the half-buffer means A and B, per pixel and channel.

    mean_a, mean_b, sample_variance: (H, W, 3); n_a, n_b: sample counts of
    the halves (scalars or (H, W, 1)). The sample variance has the image's
    detail but is wrong whenever the samples are not independent (a
    stratified or low-discrepancy sampler makes the mean's variance smaller
    than σ²/n). The buffer estimate (A - B)² / (1/n_a + 1/n_b) has the right
    expectation whatever the sampler, but one squared difference per pixel
    is very noisy. Their ratio, each averaged over a window, calibrates the
    sample variance: the detail of one with the expectation of the other.
    """
    buffer_variance = (mean_a - mean_b) ** 2 / (1.0 / n_a + 1.0 / n_b)
    calibration = box(buffer_variance, VARIANCE_RADIUS)
    reference = box(sample_variance, VARIANCE_RADIUS)
    # Where every sample in the window agrees, both are 0: nothing to calibrate.
    ratio = np.where(reference > 0, calibration / np.where(reference > 0, reference, 1.0), 1.0)
    per_sample = sample_variance * ratio
    return per_sample / n_a, per_sample / n_b


def cross_filter(values: np.ndarray, guides: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """NL-means: filters values[i] with weights computed on guides[i].

    All three are (N, 3, H, W) float32: channel-first, so that each offset's
    work is a few whole-array operations. The distance between the patches
    around p and q = p + o is the mean over the patch and the channels of

        ((u_p - u_q)² - α (Var_p + min(Var_p, Var_q))) / (ε + k² (Var_p + Var_q))

    and the weight exp(-max(0, d²)). Subtracting the variances removes the
    noise's own contribution to E[(u_p - u_q)²]; the min keeps a noisier
    neighbour from cancelling more than p's own noise.
    """
    (_, _, h, w) = values.shape
    (r, f) = (WINDOW_RADIUS, PATCH_RADIUS)
    pad = r + f
    # Patches that reach past the border see the image mirrored.
    spec = ((0, 0), (0, 0), (pad, pad), (pad, pad))
    guide = np.pad(guides, spec, mode="symmetric")
    # Var_p + min(Var_p, Var_q) = min(2 Var_p, Var_p + Var_q), and with V = k² Var the
    # distance is ((u_p - u_q)² - (α/k²) min(2 V_p, V_p + V_q)) / (ε + V_p + V_q):
    # the same value in fewer operations per offset.
    variance = np.pad(variances * np.float32(K * K), spec, mode="symmetric")
    twice = 2 * variance
    cancel = np.float32(ALPHA / (K * K))
    # Σ w (u_q - u_p) rather than Σ w u_q: a constant image comes out exact.
    change = np.zeros_like(values)
    total = np.zeros((values.shape[0], 1, h, w), dtype=values.dtype)
    for dy in range(-r, r + 1):
        (y0, y1) = (max(0, -dy), min(h, h - dy))
        for dx in range(-r, r + 1):
            (x0, x1) = (max(0, -dx), min(w, w - dx))
            if y0 >= y1 or x0 >= x1:
                continue
            # Pixels p whose neighbour q = p + (dx, dy) is inside the image,
            # grown by the patch radius: their distances feed the patch sums.
            (ny, nx) = (y1 - y0, x1 - x0)
            p = (..., slice(pad + y0 - f, pad + y1 + f), slice(pad + x0 - f, pad + x1 + f))
            q = (..., slice(pad + y0 + dy - f, pad + y1 + dy + f), slice(pad + x0 + dx - f, pad + x1 + dx + f))
            both = variance[p] + variance[q]
            cancelled = np.minimum(twice[p], both)
            cancelled *= cancel
            distance = guide[p] - guide[q]
            distance *= distance
            distance -= cancelled
            both += EPSILON
            distance /= both
            patch = uniform_filter(distance.mean(axis=1), size=(1, 2 * f + 1, 2 * f + 1), mode="nearest")
            d2 = patch[:, f:f + ny, f:f + nx]
            weight = np.exp(-np.maximum(d2, 0))
            here = values[..., y0:y1, x0:x1]
            change[..., y0:y1, x0:x1] += weight[:, None] * (values[..., y0 + dy:y1 + dy, x0 + dx:x1 + dx] - here)
            total[:, 0, y0:y1, x0:x1] += weight
    # total >= 1: the weight of p itself is exp(0).
    return values + change / total


def filter_halves(mean_a, mean_b, var_a, var_b) -> np.ndarray:
    """A filtered with weights from B and B with weights from A: float32
    (2, H, W, 3), the filtered A first. The inputs are (H, W, 3): the
    half-buffer means and the variances of those means."""
    def channels_first(*images):
        return np.ascontiguousarray(np.stack(images).transpose(0, 3, 1, 2), dtype=np.float32)

    filtered = cross_filter(channels_first(mean_a, mean_b),
                            channels_first(mean_b, mean_a),
                            channels_first(var_b, var_a))
    return filtered.transpose(0, 2, 3, 1)
