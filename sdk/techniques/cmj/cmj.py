#!/usr/bin/env python3
"""Correlated multi-jittered sampler (Kensler 2013), with a box filter.

Owns: the positions of every sample (``points``/``points_many``, pure
functions of the pixel index and the sample count). The benchmark loop
that sends them to the renderer and averages the colours of each pixel is
sampling.py, linked from ``independent``.

For n = m·k samples (m columns, k rows, m the largest divisor of n not
above √n) sample s sits in coarse cell (s mod m, s div m) of the m × k grid;
inside it, its column of the n × n fine grid is chosen by one permutation of
the k rows and its row by one permutation of the m columns, shared by all
cells ("correlated": Kensler's fix for the clumping of independently
shuffled multi-jittering), plus a uniform jitter inside the fine cell. So
every coarse cell, every fine column and every fine row holds exactly one
sample. Each 2-D pair (image, lens, light) has its own pattern and its own
shuffle of the sample order, so that pairs are not correlated with each
other; time takes the first coordinate of a pattern of its own (one
sample in each of n intervals). Everything is drawn from hashes of the pixel index.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import sampling  # noqa: E402
# Shared with the other samplers; tests/test_samplers.py reads them here too.
from sampling import DIMENSIONS, image_coordinate, used_dimensions  # noqa: E402, F401

# Which pattern each column belongs to, and which coordinate of it it is.
PAIRS = ((0, 1), (2, 3), (4, None), (5, 6))

SEED = 0xC3A1  # the technique's fixed seed: changes every pixel's pattern
ONE_BELOW = float(np.nextafter(np.float32(1), np.float32(0)))  # largest float32 < 1

_U64 = np.uint64


def grid(n: int) -> tuple[int, int]:
    """(columns, rows) of the coarse grid for n samples: the most nearly
    square exact factorisation, columns ≤ rows (a prime n gives 1 × n)."""
    m = int(np.sqrt(n))
    while n % m:
        m -= 1
    return m, n // m


def _hashes(pixels: np.ndarray, pair: int, role: int, count: int) -> np.ndarray:
    """(pixels, count) uint64 hashes for one pair and role."""
    key = sampling.mix(sampling.mix(pixels.astype(_U64) ^ _U64(SEED)) ^ _U64(pair * 8 + role))
    return sampling.mix(key[:, None] ^ np.arange(count, dtype=_U64)[None, :])


def _permutations(pixels: np.ndarray, pair: int, role: int, count: int) -> np.ndarray:
    """An independent uniform permutation of 0..count-1 per pixel, by sorting
    hashed keys (Kensler permutes by cycle-walking a hash so that one sample
    can be computed alone; here a pixel's samples are made together)."""
    return np.argsort(_hashes(pixels, pair, role, count), axis=1, kind="stable")


def _jitter(pixels: np.ndarray, pair: int, role: int, count: int) -> np.ndarray:
    """(pixels, count) uniform numbers in (0, 1): the middles of 2^24 equal
    intervals, so a point never lies on a stratum boundary, where float
    rounding could decide its stratum."""
    return ((_hashes(pixels, pair, role, count) >> _U64(40)).astype(np.float64) + 0.5) * 2.0**-24


def pattern(pixels: np.ndarray, n: int, pair: int) -> tuple[np.ndarray, np.ndarray]:
    """One correlated multi-jittered pattern of n points per pixel, in a
    shuffled order: x and y, each (pixels, n)."""
    m, k = grid(n)
    s = np.arange(n)
    column, row = s % m, s // m
    column_shuffle = _permutations(pixels, pair, 0, k)  # fine column within a cell, by row
    row_shuffle = _permutations(pixels, pair, 1, m)  # fine row within a cell, by column
    x = (column + (column_shuffle[:, row] + _jitter(pixels, pair, 2, n)) / k) / m
    y = (row + (row_shuffle[:, column] + _jitter(pixels, pair, 3, n)) / m) / k
    order = _permutations(pixels, pair, 4, n)
    x, y = np.take_along_axis(x, order, axis=1), np.take_along_axis(y, order, axis=1)
    return np.minimum(x, ONE_BELOW), np.minimum(y, ONE_BELOW)


def points_many(pixels: np.ndarray, spp: int) -> np.ndarray:
    """Positions of the ``spp`` samples of each pixel: (len(pixels), spp, 7)
    in [0, 1), columns in DIMENSIONS order (image columns are the fraction
    within the pixel)."""
    pixels = np.atleast_1d(np.asarray(pixels, dtype=np.int64))
    out = np.empty((len(pixels), spp, len(DIMENSIONS)))
    for pair, (first, second) in enumerate(PAIRS):
        x, y = pattern(pixels, spp, pair)
        out[..., first] = x
        if second is not None:
            out[..., second] = y
    return out


def points(pixel_index: int, spp: int) -> np.ndarray:
    """Positions of one pixel's samples: (spp, 7) in [0, 1)."""
    return points_many(np.array([pixel_index]), spp)[0]


if __name__ == "__main__":
    sampling.run(points_many)
