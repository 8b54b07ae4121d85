#!/usr/bin/env python3
"""Owen-scrambled, shuffled Sobol sampler (Burley 2020), with a box filter.

Owns: the positions of every sample (``points``/``points_many``, pure
functions of the pixel index and the sample count). The benchmark loop
that sends them to the renderer and averages the colours of each pixel is
sampling.py, linked from ``independent``.

Each pixel draws its own sequence from the first two Sobol dimensions, a
(0,2)-sequence: the van der Corput sequence and the second Sobol dimension.
Every 2-D pair of random parameters (image, lens, light; time takes the
first coordinate of its own pair) gets

- its own shuffle of the sample index: a nested uniform (Owen) scramble of
  the index, which maps the first 2^m indices onto another aligned block of
  2^m indices, so every power-of-two prefix is still a (0,m,2)-net while the
  pairs stop being correlated with each other;
- its own Owen scramble of each coordinate, done as Burley describes: the
  bits are reversed, put through a Laine–Karras hash (each output bit flips
  as a function of less significant bits only), and reversed back.

Seeds are hashes of (pixel index, pair, role), so any tile can be computed
alone and a run is reproducible.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import sampling  # noqa: E402
# Shared with the other samplers; tests/test_samplers.py reads them here too.
from sampling import DIMENSIONS, image_coordinate, used_dimensions  # noqa: E402, F401

# Which pair each column belongs to, and which coordinate of the pair it is.
PAIRS = ((0, 1), (2, 3), (4, None), (5, 6))

SEED = 0x50B0_1E5  # the technique's fixed seed: changes every pixel's sequence

_U32 = np.uint32
_U64 = np.uint64


def _seed(pixels: np.ndarray, pair: int, role: int) -> np.ndarray:
    """A 32-bit seed per pixel for one pair and role (0 index, 1 x, 2 y)."""
    z = sampling.mix(sampling.mix(pixels.astype(_U64) ^ _U64(SEED)) ^ _U64(pair * 4 + role))
    return (z >> _U64(32)).astype(_U32)


def reverse_bits(x: np.ndarray) -> np.ndarray:
    """Reverses the 32 bits of each uint32."""
    x = x.astype(_U32)
    for shift, mask in ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF)):
        x = ((x >> _U32(shift)) & _U32(mask)) | ((x & _U32(mask)) << _U32(shift))
    return (x >> _U32(16)) | (x << _U32(16))


def laine_karras(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Burley's Laine–Karras-style hash: adding the seed and xor-ing in
    products with even constants only ever changes a bit as a function of
    the bits below it, which is what makes it a nested scramble once the
    bits are reversed. Constants as published in the paper."""
    x = x + seed
    for constant in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6):
        x = x ^ (x * _U32(constant))
    return x


def owen_scramble(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Nested uniform scramble of 32-bit fractions (or indices): bit k (from
    the top) flips as a function of the seed and the bits above it."""
    return reverse_bits(laine_karras(reverse_bits(x), seed))


def sobol_2d(index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first two Sobol dimensions as 32-bit fractions. The first is the
    van der Corput sequence (bit reversal); the second's generator matrix is
    Pascal's triangle mod 2 (primitive polynomial x + 1): each direction
    number is the previous one xor-ed with itself shifted right by one."""
    x = reverse_bits(index)
    y = np.zeros_like(index, dtype=_U32)
    direction = 1 << 31
    for bit in range(32):
        y ^= np.where((index >> _U32(bit)) & _U32(1), _U32(direction), _U32(0))
        direction ^= direction >> 1
    return x, y


def _unit(bits: np.ndarray) -> np.ndarray:
    """The top 24 bits as a float in [0, 1): exact in float32, never 1."""
    return (bits >> _U32(8)).astype(np.float64) * 2.0**-24


def points_many(pixels: np.ndarray, spp: int) -> np.ndarray:
    """Positions of the first ``spp`` samples of each pixel: (len(pixels),
    spp, 7) in [0, 1), columns in DIMENSIONS order (image columns are the
    fraction within the pixel)."""
    pixels = np.atleast_1d(np.asarray(pixels, dtype=np.int64))
    index = np.broadcast_to(np.arange(spp, dtype=_U32), (len(pixels), spp))
    out = np.empty((len(pixels), spp, len(DIMENSIONS)))
    for pair, (first, second) in enumerate(PAIRS):
        shuffled = owen_scramble(index, _seed(pixels, pair, 0)[:, None])
        x, y = sobol_2d(shuffled)
        out[..., first] = _unit(owen_scramble(x, _seed(pixels, pair, 1)[:, None]))
        if second is not None:
            out[..., second] = _unit(owen_scramble(y, _seed(pixels, pair, 2)[:, None]))
    return out


def points(pixel_index: int, spp: int) -> np.ndarray:
    """Positions of one pixel's samples: (spp, 7) in [0, 1)."""
    return points_many(np.array([pixel_index]), spp)[0]


if __name__ == "__main__":
    sampling.run(points_many)
