#!/usr/bin/env python3
"""The conformance technique, Python edition: the twin of
tests/src/bin/fbksd-conformance-technique.rs (see there for the scenarios
and the dump format); keep the three editions equivalent."""

import os

import fbksd.client as fc
import numpy as np

PARAMS = ["IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y"]
FEATURES = [
    "COLOR_R", "COLOR_G", "COLOR_B", "DIRECT_LIGHT_R", "DIRECT_LIGHT_G", "DIRECT_LIGHT_B", "DEPTH",
    "WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z",
    "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B",
    "WORLD_X_NS", "WORLD_Y_NS", "WORLD_Z_NS", "NORMAL_X_NS", "NORMAL_Y_NS", "NORMAL_Z_NS",
    "TEXTURE_COLOR_R_NS", "TEXTURE_COLOR_G_NS", "TEXTURE_COLOR_B_NS",
    "DIFFUSE_COLOR_R", "DIFFUSE_COLOR_G", "DIFFUSE_COLOR_B",
]
NUMBERED = ["WORLD_X", "WORLD_Y", "WORLD_Z", "NORMAL_X", "NORMAL_Y", "NORMAL_Z",
            "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B"]


def params(x, y, s):
    """Exact binary fractions (computed in float64, stored as float32)."""
    return [
        x + ((s % 4) + 0.5) / 4,
        y + (((3 * s) % 8) + 0.5) / 8,
        ((x + 3 * y + s) % 8) / 8,
        ((x + s) % 4) / 4,
        ((y + 5 * s) % 16) / 16,
        (s % 2) / 2,
        ((x * y + s) % 32) / 32,
    ]


def main():
    scenario = os.environ["FBKSD_CONFORMANCE"]
    out = open(os.environ["FBKSD_CONFORMANCE_OUT"], "wb")
    io = fc.INPUT if scenario.startswith("input-") else fc.OUTPUT
    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    w, h, max_spp = info.get("width"), info.get("height"), info.get("max_spp")

    layout = [(p, io) for p in PARAMS] + FEATURES + [(n, 1) for n in NUMBERED]
    client.set_sample_layout(layout)
    size = client.sample_size()

    def record(rect, spp, data):
        samples = data.reshape(-1, size)
        out.write(np.array(list(rect) + [spp, size], dtype="<u4").tobytes())
        out.write(np.array([len(samples)], dtype="<u8").tobytes())
        out.write(samples.astype("<f4").tobytes())

    def dump_tile(tile, offset):
        (ny, nx, ns, _) = tile.shape
        (bx, by) = offset
        record((bx, bx + nx, by, by + ny), ns, tile)

    def dump_samples(samples):
        record((0, 0, 0, 0), 0, samples)

    if scenario == "spp":
        client.evaluate_samples(1, dump_tile)
        client.evaluate_samples(max_spp - 1, dump_tile)
    elif scenario == "count":
        client.evaluate_sample_count(w * h + 7, dump_samples)
        client.evaluate_sample_count(max_spp * w * h - (w * h + 7), dump_samples)
    elif scenario == "input-spp":
        def produce(tile, offset):
            (ny, nx, ns, _) = tile.shape
            (bx, by) = offset
            y, x, s = np.meshgrid(np.arange(by, by + ny), np.arange(bx, bx + nx), np.arange(ns), indexing="ij")
            tile[..., :7] = np.stack(params(x, y, s), axis=-1)
        client.evaluate_input_samples(max_spp, produce, dump_tile)
    elif scenario == "input-count":
        next_k = [0]

        def produce(samples):
            k = np.arange(next_k[0], next_k[0] + len(samples))
            next_k[0] += len(samples)
            samples[:, :7] = np.stack(params(k % w, (k // w) % h, k // (w * h)), axis=-1)
        client.evaluate_input_sample_count(max_spp * w * h, produce, dump_samples)
    else:
        raise SystemExit(f"unknown scenario {scenario}")
    out.close()
    client.send_result()


main()
