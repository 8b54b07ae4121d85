#!/usr/bin/env python3
"""Independent uniform random sampler, with a box filter.

Owns: the positions of every sample (``points``/``points_many``, pure
functions of the pixel index and the sample count). The benchmark loop
that sends them to the renderer and averages the colours of each pixel is
sampling.py, which the other samplers link.

Every coordinate of every sample is an independent uniform number: a hash
of (technique seed, pixel index, sample index, dimension). No stratification
at all: this is plain Monte Carlo, the baseline every sampler must beat.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import sampling  # noqa: E402
# Shared with the other samplers; tests/test_samplers.py reads them here too.
from sampling import DIMENSIONS, image_coordinate, used_dimensions  # noqa: E402, F401

SEED = 0x1D3  # the technique's fixed seed: changes every pixel's numbers

_U64 = np.uint64


def points_many(pixels: np.ndarray, spp: int) -> np.ndarray:
    """Positions of the first ``spp`` samples of each pixel: (len(pixels),
    spp, 7) in [0, 1), columns in DIMENSIONS order (image columns are the
    fraction within the pixel). 24 bits each: exact in float32, never 1."""
    pixels = np.atleast_1d(np.asarray(pixels, dtype=np.int64))
    pixel_key = sampling.mix(pixels.astype(_U64) ^ _U64(SEED))[:, None, None]
    counter = np.arange(spp, dtype=_U64)[None, :, None] * _U64(len(DIMENSIONS))
    counter = counter + np.arange(len(DIMENSIONS), dtype=_U64)[None, None, :]
    bits = sampling.mix(pixel_key ^ counter) >> _U64(40)
    return bits.astype(np.float64) * 2.0**-24


def points(pixel_index: int, spp: int) -> np.ndarray:
    """Positions of one pixel's samples: (spp, 7) in [0, 1)."""
    return points_many(np.array([pixel_index]), spp)[0]


if __name__ == "__main__":
    sampling.run(points_many)
