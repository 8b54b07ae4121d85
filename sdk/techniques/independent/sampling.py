"""Shared code of the Python samplers: the benchmark loop every sampler
runs, given its ``points_many(pixels, spp)`` function, and what that loop
needs around it.

Owns:

- ``DIMENSIONS``: the seven random parameters, in the column order of every
  sampler's ``points``/``points_many``;
- ``image_coordinate``: a pixel's index plus a fraction as a float32 image
  coordinate that stays inside the pixel;
- ``used_dimensions``: which of those columns the scene reads;
- ``mix``: the 64-bit hash the samplers draw their seeds and permutations from;
- ``run(points_many)``: the client. It sends the used columns as INPUT,
  computes each tile's positions at once with ``points_many`` (pixel index
  y·width + x, the tile's sample count), and reconstructs with a box filter
  (each pixel the mean of its samples' colours, in float64).

The samplers (independent.py, halton.py, sobol_owen.py, cmj.py) only supply
``points_many``; the other folders link this file from ``independent``, and
what is pushed holds the file itself. fbksd.client is imported by ``run``
alone, so the positions can be tested without the SDK.
"""

from typing import Callable

import numpy as np

# The seven random parameters, in the column order of ``points``.
DIMENSIONS = ("IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y")

# points_many(pixels, spp): (len(pixels), spp, len(DIMENSIONS)) in [0, 1).
PointsMany = Callable[[np.ndarray, int], np.ndarray]


def mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser: a well-mixed 64-bit hash of a uint64 array."""
    u64 = np.uint64
    z = z + u64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> u64(30))) * u64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> u64(27))) * u64(0x94D049BB133111EB)
    return z ^ (z >> u64(31))


def image_coordinate(base: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """base + fraction as float32, rounded down and kept below base + 1:
    rounding to nearest could move a sample into the next pixel."""
    base = np.asarray(base, dtype=np.float64)
    exact = base + fraction
    value = exact.astype(np.float32)
    value = np.where(value > exact, np.nextafter(value, np.float32(-np.inf)), value)
    return np.minimum(value, np.nextafter((base + 1).astype(np.float32), np.float32(-np.inf)))


def used_dimensions(info) -> list[int]:
    """Columns of ``points`` the scene reads: from its random_parameters list
    when it has one, else from has_dof/has_motion_blur; the image always."""
    if info.has("random_parameters"):
        names = set(str(info.get("random_parameters")).split(","))
    else:
        names = set()
        if info.has("has_dof") and info.get("has_dof"):
            names |= {"LENS_U", "LENS_V"}
        if info.has("has_motion_blur") and info.get("has_motion_blur"):
            names.add("TIME")
    return [d for d, name in enumerate(DIMENSIONS) if d < 2 or name in names]


def run(points_many: PointsMany) -> None:
    """The technique: max_spp samples per pixel at the positions
    ``points_many`` gives, each pixel the mean of its samples' colours."""
    import fbksd.client as fc

    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    width, spp = int(info.get("width")), int(info.get("max_spp"))
    used = used_dimensions(info)
    client.set_sample_layout([(DIMENSIONS[d], fc.INPUT) for d in used] + ["COLOR_R", "COLOR_G", "COLOR_B"])
    color = slice(len(used), len(used) + 3)
    result = client.get_result_buffer()

    def place(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, ns, _) = tile.shape
        (bx, by) = offset
        ys, xs = np.mgrid[by:by + ny, bx:bx + nx]
        p = points_many((ys * width + xs).ravel(), ns).reshape(ny, nx, ns, len(DIMENSIONS))
        tile[..., 0] = image_coordinate(xs[..., None], p[..., 0])
        tile[..., 1] = image_coordinate(ys[..., None], p[..., 1])
        for column, d in enumerate(used[2:], start=2):
            tile[..., column] = p[..., d]

    def consume(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, _, _) = tile.shape
        (bx, by) = offset
        result[by:by + ny, bx:bx + nx] = tile[..., color].mean(axis=2, dtype=np.float64)

    client.evaluate_input_samples(spp, place, consume)
    client.send_result()
