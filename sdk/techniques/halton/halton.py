#!/usr/bin/env python3
"""Halton sampler with random digit permutations, per pixel, with a box filter.

Owns: the positions of every sample (``points``/``points_many``, pure
functions of the pixel index and the sample count). The benchmark loop
that sends them to the renderer and averages the colours of each pixel is
sampling.py, linked from ``independent``.

Sample i of a pixel has coordinate j equal to the radical inverse of i in
the j-th prime base (2, 3 for the image plane; 5, 7 lens; 11 time; 13, 17
light), with every digit put through a random permutation of 0..b-1 before
it is mirrored behind the radix point. The permutations are drawn per
pixel, per dimension and per digit position ("random digit scrambling"):
they map boxes of the b-adic grid onto boxes, so the first 2^a·3^b samples
still put exactly one point in every 1/2^a × 1/3^b box of the pixel, while
neighbouring pixels get independent patterns (their errors become noise
instead of a repeated structure), and the well-known correlation of the
unscrambled sequence between large bases (points on lines for 13, 17) goes.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import sampling  # noqa: E402
# Shared with the other samplers; tests/test_samplers.py reads them here too.
from sampling import DIMENSIONS, image_coordinate, used_dimensions  # noqa: E402, F401

BASES = (2, 3, 5, 7, 11, 13, 17)  # the first seven primes, one per column

SEED = 0x4A170  # the technique's fixed seed: changes every pixel's permutations
RESOLUTION_BITS = 24  # digits kept: enough that b^-digits ≤ 2^-24, float32's step below 1
ONE_BELOW = float(np.nextafter(np.float32(1), np.float32(0)))  # largest float32 < 1

_U64 = np.uint64


def digit_count(base: int) -> int:
    """Digits of a radical inverse in ``base`` worth computing: the fewest
    with base^-digits ≤ 2^-RESOLUTION_BITS."""
    digits = 1
    while base**digits < 2**RESOLUTION_BITS:
        digits += 1
    return digits


def digit_permutations(pixels: np.ndarray, dimension: int) -> np.ndarray:
    """perm[p, k, d]: what digit d at position k becomes, for each pixel:
    independent uniform permutations, by sorting hashed keys."""
    base, digits = BASES[dimension], digit_count(BASES[dimension])
    pixel_key = sampling.mix(pixels.astype(_U64) ^ _U64(SEED))
    position = np.arange(digits, dtype=_U64)[None, :, None]
    digit = np.arange(base, dtype=_U64)[None, None, :]
    keys = sampling.mix(sampling.mix(pixel_key[:, None, None] ^ _U64(dimension)) ^ (position * _U64(64) + digit))
    return np.argsort(keys, axis=2, kind="stable")


def scrambled_radical_inverse(index: np.ndarray, base: int, perm: np.ndarray) -> np.ndarray:
    """Radical inverse of ``index`` (spp,) in ``base`` with digit k replaced
    by perm[:, k, digit]: (pixels, spp) in [0, 1). The digits are summed as
    an integer, so the value is exact up to the final division."""
    digits = perm.shape[1]
    rest = index.copy()
    total = np.zeros((perm.shape[0], len(index)), dtype=np.int64)
    for k in range(digits):
        total = total * base + perm[:, k, rest % base]
        rest //= base
    # The dropped digits, scrambled, would be uniform: on average they put
    # the point in the middle of its finest cell, which also keeps it clear
    # of every cell boundary whatever the float rounding.
    return np.minimum((total + 0.5) / float(base**digits), ONE_BELOW)


def points_many(pixels: np.ndarray, spp: int) -> np.ndarray:
    """Positions of the first ``spp`` samples of each pixel: (len(pixels),
    spp, 7) in [0, 1), columns in DIMENSIONS order (image columns are the
    fraction within the pixel)."""
    pixels = np.atleast_1d(np.asarray(pixels, dtype=np.int64))
    index = np.arange(spp, dtype=np.int64)
    out = np.empty((len(pixels), spp, len(DIMENSIONS)))
    for d, base in enumerate(BASES):
        out[..., d] = scrambled_radical_inverse(index, base, digit_permutations(pixels, d))
    return out


def points(pixel_index: int, spp: int) -> np.ndarray:
    """Positions of one pixel's samples: (spp, 7) in [0, 1)."""
    return points_many(np.array([pixel_index]), spp)[0]


if __name__ == "__main__":
    sampling.run(points_many)
