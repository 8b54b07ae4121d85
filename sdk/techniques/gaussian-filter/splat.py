"""Shared code of the reconstruction filters: splatting samples through a
separable pixel filter, and the benchmark loop around it.

Every sample (IMAGE_X, IMAGE_Y, colour) contributes w·colour and w to each
pixel whose centre (x + 0.5, y + 0.5) lies within the filter's radius of the
sample's position, with w = f(x + 0.5 - IMAGE_X) · f(y + 0.5 - IMAGE_Y). A
pixel is Σ w·colour / Σ w. Dividing by the weights actually received (not
by the filter's integral) makes the estimate exact on a constant image,
whatever the sample positions and at the image border.

The filter modules (gaussian.py, mitchell.py) only supply the 1D profile
f and its radius.
"""

import math
import sys
from typing import Callable

import numpy as np

Profile = Callable[[np.ndarray], np.ndarray]

# A pixel whose weight sum is below this fraction of the number of samples
# inside it falls back to the box mean of those samples. With a positive
# filter the sum is never that small; with Mitchell–Netravali's negative
# lobes it can be, and dividing by a sum near zero (or below it) would
# amplify the colours without bound. The profiles integrate to 1, so Σw is
# about the pixel's sample count on average; 0.1 catches only degenerate
# placements (the minimum over a 64×64 simulation at 1 spp was 0.21).
FALLBACK_FRACTION = 0.1


class Splatter:
    """Accumulates samples of one image, tile by tile, then resolves it."""

    def __init__(self, width: int, height: int, profile: Profile, radius: float) -> None:
        self.width, self.height = width, height
        self.profile, self.radius = profile, radius
        # Pixel offsets whose centre can be within `radius` of a sample in
        # the pixel (the sample is up to half a pixel from its own centre).
        self.reach = max(0, math.ceil(radius + 0.5) - 1)
        r = self.reach
        # Padded by `reach` on every side, so a tile's splat is one slice
        # addition; samples near a tile edge land in the neighbours' pixels.
        # Rows 0..3: Σw, Σw·R, Σw·G, Σw·B.
        self.sums = np.zeros((4, height + 2 * r, width + 2 * r), dtype=np.float64)
        # The box fallback: Σ colour and the count of each pixel's own samples.
        self.box = np.zeros((3, height, width), dtype=np.float64)
        self.count = np.zeros((height, width), dtype=np.float64)

    def add(self, x: np.ndarray, y: np.ndarray, colour: np.ndarray, offset: tuple[int, int]) -> None:
        """Adds the samples of one tile.

        x, y: (ny, nx, spp) sample positions in absolute pixel coordinates;
        colour: (ny, nx, spp, 3); offset: (x0, y0) of the tile's first pixel.
        """
        (ny, nx, ns) = x.shape
        (bx, by) = offset
        r = self.reach
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        colour = np.asarray(colour, dtype=np.float64)
        # A sample's own pixel is its place in the tile, not floor(IMAGE_X):
        # a float32 x + 0.99999 may round up to the next integer.
        px = (bx + np.arange(nx, dtype=np.float64))[None, :, None]
        py = (by + np.arange(ny, dtype=np.float64))[:, None, None]
        wx = [self.profile(px + (dx + 0.5) - x) for dx in range(-r, r + 1)]
        wy = [self.profile(py + (dy + 0.5) - y) for dy in range(-r, r + 1)]

        # Flat index of each sample's own pixel in a tile-local buffer with
        # the same padding as `sums`.
        lw, lh = nx + 2 * r, ny + 2 * r
        own = ((np.arange(ny)[:, None] + r) * lw + (np.arange(nx)[None, :] + r))[:, :, None]
        own = np.broadcast_to(own, (ny, nx, ns)).ravel()
        channels = [colour[..., c].ravel() for c in range(3)]
        local = np.zeros((4, lh * lw), dtype=np.float64)
        for j, dy in enumerate(range(-r, r + 1)):
            for i, dx in enumerate(range(-r, r + 1)):
                w = (wy[j] * wx[i]).ravel()
                index = own + (dy * lw + dx)
                local[0] += np.bincount(index, weights=w, minlength=lh * lw)
                for c in range(3):
                    local[c + 1] += np.bincount(index, weights=w * channels[c], minlength=lh * lw)
        self.sums[:, by:by + lh, bx:bx + lw] += local.reshape(4, lh, lw)

        self.box[:, by:by + ny, bx:bx + nx] += np.moveaxis(colour.sum(axis=2), -1, 0)
        self.count[by:by + ny, bx:bx + nx] += ns

    def resolve(self, clamp_negative: bool = False) -> tuple[np.ndarray, int]:
        """The (height, width, 3) image, and how many pixels fell back to the box mean."""
        r = self.reach
        inside = self.sums[:, r:r + self.height, r:r + self.width]
        weight = inside[0]
        box = self.box / np.maximum(self.count, 1.0)
        good = weight > FALLBACK_FRACTION * self.count
        image = np.where(good, inside[1:] / np.where(good, weight, 1.0), box)
        if clamp_negative:
            # Negative lobes can ring below zero next to bright edges;
            # radiance cannot be negative.
            image = np.maximum(image, 0.0)
        return np.moveaxis(image, 0, -1), int(np.count_nonzero(~good & (self.count > 0)))


def run(name: str, profile: Profile, radius: float, clamp_negative: bool = False) -> None:
    """The technique: asks the renderer for positions and colours, splats, sends."""
    import fbksd.client as fc

    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    (width, height) = (int(info.get("width")), int(info.get("height")))
    spp = int(info.get("max_spp"))
    client.set_sample_layout(
        [("IMAGE_X", fc.OUTPUT), ("IMAGE_Y", fc.OUTPUT), "COLOR_R", "COLOR_G", "COLOR_B"]
    )
    result = client.get_result_buffer()
    splatter = Splatter(width, height, profile, radius)

    def consume(tile: np.ndarray, offset: tuple[int, int]) -> None:
        splatter.add(tile[..., 0], tile[..., 1], tile[..., 2:5], offset)

    client.evaluate_samples(spp, consume)
    (image, fallbacks) = splatter.resolve(clamp_negative)
    if fallbacks:
        print(f"{name}: {fallbacks} pixel(s) with a near-zero weight sum used their box mean",
              file=sys.stderr)
    result[...] = image.astype(np.float32)
    client.send_result()
