#!/usr/bin/env python3
"""Non-local means with dual-buffer variance estimation: a denoiser after
Rousselle, Knaus and Zwicker, "Adaptive Rendering with Non-Local Means
Filtering", ACM TOG 31(6), SIGGRAPH Asia 2012 (the filter of that paper,
without its adaptive sampling; see adaptive-nlm for that).

This file owns the technique; the filter itself (steps 2 and 3, and its
parameters) is nl_means.py, which adaptive-nlm links:

1. Each pixel's samples are split in two halves, A (even sample index) and
   B (odd), giving two half-buffer means and the pixels' sample variance.
2. The variance of each half-buffer mean is estimated from the sample
   variance, calibrated by the squared difference of the two half-buffers
   (see `mean_variances`).
3. A is filtered with NL-means weights computed on B, and B with weights
   computed on A (cross filtering: a buffer's weights never depend on its
   own noise). The result is the mean of the two filtered halves.

With a single sample per pixel there are no halves: the result is then the
samples themselves (the box filter), and the technique log says so.
"""

import os
import sys

# The renderer runs on the same cores: one BLAS thread, not one per core
# competing with it (must be set before numpy loads).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import fbksd.client as fc  # noqa: E402
import numpy as np  # noqa: E402

from nl_means import filter_halves, mean_variances  # noqa: E402


def main() -> None:
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    (width, height) = (int(info.get("width")), int(info.get("height")))
    spp = int(info.get("max_spp"))
    client.set_sample_layout(["COLOR_R", "COLOR_G", "COLOR_B"])

    mean_a = np.zeros((height, width, 3))
    mean_b = np.zeros((height, width, 3))
    sample_variance = np.zeros((height, width, 3))

    def consume(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, ns, _) = tile.shape
        (bx, by) = offset
        region = (slice(by, by + ny), slice(bx, bx + nx))
        # A sample that is not a finite number carries no usable radiance.
        x = np.nan_to_num(tile.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        mean_a[region] = x[:, :, 0::2].mean(axis=2)
        if ns >= 2:
            mean_b[region] = x[:, :, 1::2].mean(axis=2)
            sample_variance[region] = x.var(axis=2, ddof=1)

    client.evaluate_samples(spp, consume)

    result = client.get_result_buffer()
    if spp < 2:
        print("nlm: 1 sample per pixel, no half-buffers to estimate the variance from: "
              "returning the unfiltered samples", file=sys.stderr)
        result[:] = mean_a
    else:
        (n_a, n_b) = ((spp + 1) // 2, spp // 2)
        (var_a, var_b) = mean_variances(mean_a, mean_b, n_a, n_b, sample_variance)
        # The mean of A filtered with weights from B and B filtered with weights from A.
        filtered = filter_halves(mean_a, mean_b, var_a, var_b).mean(axis=0)
        # Only an overflow could make the filter non-finite: keep those pixels' means.
        box_mean = (n_a * mean_a + n_b * mean_b) / spp
        result[:] = np.where(np.isfinite(filtered), filtered, box_mean)
    client.send_result()


if __name__ == "__main__":
    main()
