#!/usr/bin/env python3
"""Variance-driven adaptive sampling: a sampler written against fbksd.client.

1. Half the budget (at least 2 spp) goes uniformly: stratified jittered
   positions the technique writes itself (IMAGE_X/IMAGE_Y are INPUT).
2. The rest goes to pixels in proportion to the relative variance of their
   mean, var / (n * (mean² + 1e-3)), as whole samples (largest remainders).
3. Each pixel is the mean of all its samples.

Positions come from a fixed seed, so a run is reproducible.
"""

import fbksd.client as fc
import numpy as np

RGB = slice(2, 5)


def main() -> None:
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    width, height = int(info.get("width")), int(info.get("height"))
    max_spp = int(info.get("max_spp"))
    pixels = width * height
    rng = np.random.default_rng(20191)

    client.set_sample_layout([("IMAGE_X", fc.INPUT), ("IMAGE_Y", fc.INPUT), "COLOR_R", "COLOR_G", "COLOR_B"])
    sums = np.zeros((pixels, 3))
    squares = np.zeros(pixels)
    counts = np.zeros(pixels)

    def accumulate(samples: np.ndarray) -> None:
        """Adds samples (n, 5) to the pixel they lie in."""
        x = np.clip(samples[:, 0].astype(np.int64), 0, width - 1)
        y = np.clip(samples[:, 1].astype(np.int64), 0, height - 1)
        index = y * width + x
        rgb = samples[:, RGB].astype(np.float64)
        for c in range(3):
            sums[:, c] += np.bincount(index, weights=rgb[:, c], minlength=pixels)
        squares[:] += np.bincount(index, weights=rgb.mean(axis=1) ** 2, minlength=pixels)
        counts[:] += np.bincount(index, minlength=pixels)

    # Pass 1: uniform, stratified in a sqrt(spp) grid per pixel where possible.
    first_spp = max_spp if max_spp < 4 else max(2, max_spp // 2)

    def place_uniform(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, ns, _) = tile.shape
        (bx, by) = offset
        strata = np.arange(ns)
        tile[..., 0] = bx + np.arange(nx)[None, :, None] + (strata + rng.random((ny, nx, ns))) / ns
        tile[..., 1] = by + np.arange(ny)[:, None, None] + rng.permuted(np.broadcast_to(
            (strata + rng.random(ns)) / ns, (ny, nx, ns)), axis=2)

    def consume_tile(tile: np.ndarray, offset: tuple[int, int]) -> None:
        accumulate(tile.reshape(-1, tile.shape[-1]))

    client.evaluate_input_samples(first_spp, place_uniform, consume_tile)

    # Pass 2: the rest of the budget where the estimate is least certain.
    remaining = client.remaining_samples()
    if remaining > 0:
        n = np.maximum(counts, 1)
        mean = sums.mean(axis=1) / n
        variance = np.maximum(squares / n - mean ** 2, 0) * n / np.maximum(n - 1, 1)
        weight = variance / (n * (mean ** 2 + 1e-3)) + 1e-12
        share = remaining * weight / weight.sum()
        extra = np.floor(share).astype(np.int64)
        leftover = int(remaining - extra.sum())
        extra[np.argsort(-(share - extra), kind="stable")[:leftover]] += 1
        targets = np.repeat(np.arange(pixels), extra)
        cursor = [0]

        def place_adaptive(samples: np.ndarray) -> None:
            start = cursor[0]
            chunk = targets[start:start + len(samples)]
            cursor[0] = start + len(samples)
            samples[:, 0] = (chunk % width) + rng.random(len(chunk))
            samples[:, 1] = (chunk // width) + rng.random(len(chunk))

        client.evaluate_input_sample_count(int(remaining), place_adaptive, accumulate)

    result = client.get_result_buffer()
    result[:] = (sums / np.maximum(counts, 1)[:, None]).reshape(height, width, 3)
    client.send_result()


if __name__ == "__main__":
    main()
