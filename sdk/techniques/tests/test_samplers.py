"""Stratification tests of the Python sampler baselines.

Owns: checks, on the positions each technique sends (its ``points``
function, which the technique writes unchanged), of the property its
algorithm promises: nets for Sobol-Owen, b-adic boxes for Halton, fine and
coarse strata for CMJ, uniformity and determinism for independent sampling.

Run from the repository root: python3 -m unittest sdk/techniques/tests/test_samplers.py
The modules live in directories with dashes, so they are loaded by path,
with their folder on sys.path for the shared sampling.py; they need only
numpy (fbksd.client is imported by sampling.run alone).
"""

import importlib.util
import itertools
import sys
import unittest
from pathlib import Path

import numpy as np

TECHNIQUES = Path(__file__).resolve().parent.parent
PIXELS = (0, 1, 127, 12345, 2**20 + 7)  # several pixels, small and large indices
LARGEST_BELOW_ONE = np.nextafter(np.float32(1), np.float32(0))
PAIRS_2D = ((0, 1), (2, 3), (5, 6))  # image, lens, light; column 4 is time
TIME = 4


def load(directory: str, module: str):
    # A technique imports its sibling modules (sampling.py), as when it runs
    # as a script: its folder goes on the path first.
    folder = str(TECHNIQUES / directory)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    spec = importlib.util.spec_from_file_location(module, TECHNIQUES / directory / f"{module}.py")
    loaded = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loaded)
    return loaded


independent = load("independent", "independent")
sobol_owen = load("sobol-owen", "sobol_owen")
halton = load("halton", "halton")
cmj = load("cmj", "cmj")
ALL = (independent, sobol_owen, halton, cmj)


def each_once(cells: np.ndarray, count: int) -> bool:
    """Whether cells (integers) hit each of 0..count-1 exactly once."""
    return len(cells) == count and bool((np.bincount(cells, minlength=count) == 1).all())


def stratum(values: np.ndarray, strata: int) -> np.ndarray:
    return np.floor(values * strata).astype(np.int64)


def quadrant_pairs(module) -> float:
    """Pairs must be shuffled against each other: the mean, over 256 pixels
    of 16 samples, of how many distinct (image quadrant, lens quadrant)
    combinations a pixel's samples take. Sharing the sample order makes the
    image quadrant decide the lens quadrant (4 combinations); independent
    uniform samples give about 10.3."""
    quadrant = stratum(module.points_many(np.arange(256), 16), 2)
    image = quadrant[..., 0] * 2 + quadrant[..., 1]
    lens = quadrant[..., 2] * 2 + quadrant[..., 3]
    return float(np.mean([len(np.unique(c)) for c in image * 4 + lens]))


class Common(unittest.TestCase):
    """What every sampler owes: spp points of seven values in [0, 1)."""

    def test_shape_range_and_determinism(self):
        for module, pixel, spp in itertools.product(ALL, PIXELS, (1, 2, 4, 7, 16, 64)):
            with self.subTest(module=module.__name__, pixel=pixel, spp=spp):
                p = module.points(pixel, spp)
                self.assertEqual(p.shape, (spp, len(module.DIMENSIONS)))
                self.assertTrue(np.isfinite(p).all())
                self.assertTrue((p >= 0).all() and (p < 1).all())
                # The wire format is float32: the values must stay below 1 there too.
                self.assertTrue((p.astype(np.float32) <= LARGEST_BELOW_ONE).all())
                np.testing.assert_array_equal(p, module.points(pixel, spp))

    def test_tiles_get_the_same_points(self):
        """The technique computes a tile at once: the same as pixel by pixel."""
        for module in ALL:
            with self.subTest(module=module.__name__):
                many = module.points_many(np.array(PIXELS), 8)
                for row, pixel in zip(many, PIXELS):
                    np.testing.assert_array_equal(row, module.points(pixel, 8))

    def test_pixels_differ(self):
        for module in ALL:
            with self.subTest(module=module.__name__):
                first = [module.points(pixel, 16) for pixel in PIXELS]
                for a, b in itertools.combinations(first, 2):
                    self.assertFalse(np.array_equal(a, b))

    def test_image_coordinates_stay_in_their_pixel(self):
        fraction = np.array([0.0, 0.5, 1 - 2.0**-24, 1 - 2.0**-40])
        for module in ALL:
            for base in (0, 1, 127, 4095, 65535):
                with self.subTest(module=module.__name__, base=base):
                    value = module.image_coordinate(np.full(4, base), fraction)
                    self.assertEqual(value.dtype, np.float32)
                    self.assertTrue((value >= base).all() and (value < base + 1).all())

    def test_used_dimensions(self):
        class Info(dict):
            def has(self, key):
                return key in self

            def get(self, key):
                return self[key]

        for module in ALL:
            with self.subTest(module=module.__name__):
                self.assertEqual(module.used_dimensions(Info(random_parameters="IMAGE_X,IMAGE_Y,TIME")), [0, 1, 4])
                self.assertEqual(
                    module.used_dimensions(Info(random_parameters="IMAGE_X,IMAGE_Y,LENS_U,LENS_V,LIGHT_X,LIGHT_Y")),
                    [0, 1, 2, 3, 5, 6])
                self.assertEqual(module.used_dimensions(Info(has_dof=True, has_motion_blur=False)), [0, 1, 2, 3])
                self.assertEqual(module.used_dimensions(Info()), [0, 1])


class Independent(unittest.TestCase):
    def test_uniform_moments(self):
        """Deterministic (fixed seed), so the bounds are checked once for
        all: 5 standard deviations of the mean over 2^20 values per column."""
        p = independent.points_many(np.arange(4096), 256).reshape(-1, 7)
        count = len(p)
        self.assertTrue((np.abs(p.mean(axis=0) - 0.5) < 5 * np.sqrt(1 / 12 / count)).all(), p.mean(axis=0))
        self.assertTrue((np.abs(p.var(axis=0) - 1 / 12) < 0.002).all(), p.var(axis=0))
        # Columns are independent: no correlation between any two.
        correlation = np.corrcoef(p.T) - np.eye(7)
        self.assertLess(np.abs(correlation).max(), 5 / np.sqrt(count))
        # And the histogram is flat: 64 bins within 5 standard deviations.
        counts = np.bincount(stratum(p[:, 0], 64), minlength=64)
        expected = count / 64
        self.assertLess(np.abs(counts - expected).max(), 5 * np.sqrt(expected))

    def test_prefix(self):
        """Sample i of a pixel does not depend on how many are asked for."""
        np.testing.assert_array_equal(independent.points(9, 64)[:16], independent.points(9, 16))


class SobolOwen(unittest.TestCase):
    def test_every_power_of_two_prefix_is_a_net(self):
        """For n = 2^m the points of every 2-D pair form a (0,m,2)-net: each
        2^a × 2^(m−a) grid has one point per cell; time has one per 1/n."""
        for pixel, m in itertools.product(PIXELS, range(9)):
            n = 2**m
            p = sobol_owen.points(pixel, n)
            for x, y in PAIRS_2D:
                for a in range(m + 1):
                    with self.subTest(pixel=pixel, n=n, pair=(x, y), grid=(2**a, 2**(m - a))):
                        cells = stratum(p[:, x], 2**a) * 2**(m - a) + stratum(p[:, y], 2**(m - a))
                        self.assertTrue(each_once(cells, n))
            with self.subTest(pixel=pixel, n=n, dimension="TIME"):
                self.assertTrue(each_once(stratum(p[:, TIME], n), n))

    def test_prefix(self):
        """A sequence, not a set: the first 16 of 256 are the 16 alone."""
        np.testing.assert_array_equal(sobol_owen.points(9, 256)[:16], sobol_owen.points(9, 16))

    def test_pairs_are_decorrelated(self):
        self.assertGreater(quadrant_pairs(sobol_owen), 8)


class Halton(unittest.TestCase):
    @staticmethod
    def sizes(b1: int, b2: int, limit: int):
        for a, b in itertools.product(range(12), range(12)):
            if b1**a * b2**b <= limit:
                yield a, b

    def check_boxes(self, x: int, y: int, limit: int):
        b1, b2 = halton.BASES[x], halton.BASES[y]
        for pixel, (a, b) in itertools.product(PIXELS, self.sizes(b1, b2, limit)):
            n = b1**a * b2**b
            p = halton.points(pixel, n)
            with self.subTest(pixel=pixel, n=n, boxes=(b1**a, b2**b)):
                self.assertTrue(each_once(stratum(p[:, x], b1**a) * b2**b + stratum(p[:, y], b2**b), n))

    def test_image_boxes(self):
        """For n = 2^a·3^b every 1/2^a × 1/3^b box holds one of the first n."""
        self.check_boxes(0, 1, 1000)

    def test_lens_boxes(self):
        self.check_boxes(2, 3, 400)

    def test_light_boxes(self):
        self.check_boxes(5, 6, 300)

    def test_time_intervals(self):
        for pixel, n in itertools.product(PIXELS, (1, 11, 121)):
            with self.subTest(pixel=pixel, n=n):
                self.assertTrue(each_once(stratum(halton.points(pixel, n)[:, TIME], n), n))

    def test_digits_reach_float32_resolution(self):
        for base in halton.BASES:
            self.assertLessEqual(float(base) ** -halton.digit_count(base), 2.0**-24)


class CorrelatedMultiJittered(unittest.TestCase):
    SIZES = tuple(range(1, 41)) + (49, 64, 100, 128, 256, 1024)

    def test_grid_is_exact_and_near_square(self):
        for n in self.SIZES:
            m, k = cmj.grid(n)
            self.assertEqual(m * k, n)
            self.assertLessEqual(m, k)
            # No divisor of n lies between m and √n.
            self.assertFalse(any(n % d == 0 for d in range(m + 1, int(np.sqrt(n)) + 1)))
        self.assertEqual(cmj.grid(16), (4, 4))
        self.assertEqual(cmj.grid(8), (2, 4))
        self.assertEqual(cmj.grid(7), (1, 7))

    def test_fine_rows_columns_and_coarse_cells(self):
        for pixel, n in itertools.product(PIXELS, self.SIZES):
            m, k = cmj.grid(n)
            p = cmj.points(pixel, n)
            for x, y in PAIRS_2D:
                with self.subTest(pixel=pixel, n=n, pair=(x, y)):
                    self.assertTrue(each_once(stratum(p[:, x], n), n), "fine columns")
                    self.assertTrue(each_once(stratum(p[:, y], n), n), "fine rows")
                    self.assertTrue(each_once(stratum(p[:, x], m) * k + stratum(p[:, y], k), n), "coarse cells")
            with self.subTest(pixel=pixel, n=n, dimension="TIME"):
                self.assertTrue(each_once(stratum(p[:, TIME], n), n))

    def test_pairs_are_decorrelated(self):
        self.assertGreater(quadrant_pairs(cmj), 8)

if __name__ == "__main__":
    unittest.main()
