#!/usr/bin/env python3
"""Mitchell–Netravali reconstruction filter (Mitchell and Netravali,
"Reconstruction Filters in Computer Graphics", SIGGRAPH 1988), separable,
splatted by splat.py.

The cubic family k(x) of the paper with B = C = 1/3, the value the authors
recommend from their user study (on the line B + 2C = 1, between blurring
and ringing). Its support is |x| < 2 in units of the pixel spacing, so the
radius is 2 pixels and d is used unscaled. k integrates to 1 and has
negative lobes for 1 < |x| < 2: splat.py falls back to a pixel's box mean
where its weight sum is near zero, and negative results (ringing next to a
bright edge) are clamped to zero since radiance is never negative.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import splat  # noqa: E402

B = 1.0 / 3.0
C = 1.0 / 3.0
RADIUS = 2.0


def profile(d: np.ndarray) -> np.ndarray:
    x = np.abs(d)
    x2 = x * x
    x3 = x2 * x
    near = (12 - 9 * B - 6 * C) * x3 + (-18 + 12 * B + 6 * C) * x2 + (6 - 2 * B)
    far = (-B - 6 * C) * x3 + (6 * B + 30 * C) * x2 + (-12 * B - 48 * C) * x + (8 * B + 24 * C)
    return np.where(x < 1, near, np.where(x < 2, far, 0.0)) / 6.0


if __name__ == "__main__":
    splat.run("mitchell", profile, RADIUS, clamp_negative=True)
