#!/usr/bin/env python3
"""A test technique: saves the per-pixel means of colour, albedo and normal
(what the oidn baseline gives OIDN) to the .npz file named by
$FBKSD_MEANS_OUT, and returns the colour mean. The renderer replays the
same samples for the same request, so these are the oidn baseline's inputs.
"""

import os

import fbksd.client as fc
import numpy as np

LAYOUT = ["COLOR_R", "COLOR_G", "COLOR_B", "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B",
          "NORMAL_X", "NORMAL_Y", "NORMAL_Z"]


def main() -> None:
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    width, height, spp = int(info.get("width")), int(info.get("height")), int(info.get("max_spp"))
    client.set_sample_layout(LAYOUT)
    means = np.zeros((height, width, len(LAYOUT)), dtype=np.float32)

    def consume(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, _, _) = tile.shape
        (bx, by) = offset
        means[by:by + ny, bx:bx + nx] = tile.mean(axis=2, dtype=np.float64)

    client.evaluate_samples(spp, consume)
    np.savez(os.environ["FBKSD_MEANS_OUT"], color=means[..., 0:3], albedo=means[..., 3:6], normal=means[..., 6:9])
    client.get_result_buffer()[:] = means[..., 0:3]
    client.send_result()


if __name__ == "__main__":
    main()
