"""Renders a scene exported by `fbksd-embree export-mitsuba` with Mitsuba 3
(variant llvm_ad_rgb, path tracer at the same maximum depth) and prints
samples per second on one thread and on all cores, best of three.

Usage: python3 mitsuba_bench.py EXPORT_DIR SPP [OUT.exr]

Depth: pbrt's maxdepth counts bounces; Mitsuba's max_depth counts path
vertices including the camera's first hit, so Mitsuba gets maxdepth + 1.
Russian roulette starts where pbrt's does (after the first bounce).
"""
import json
import os
import sys
import time

import mitsuba as mi

mi.set_variant("llvm_ad_rgb")
import drjit as dr  # noqa: E402  (after the variant is set)


def load(export_dir):
    with open(os.path.join(export_dir, "scene.json")) as f:
        desc = json.load(f)
    m = mi.ScalarTransform4f(desc["camera_to_world"])
    # pbrt's camera x points right on the image, Mitsuba's points left.
    to_world = m @ mi.ScalarTransform4f().scale([-1, 1, 1])
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": desc["max_depth"] + 1, "rr_depth": 2},
        "sensor": {
            "type": "perspective",
            "fov": desc["fov"],
            "fov_axis": "smaller",
            "to_world": to_world,
            "film": {"type": "hdrfilm", "width": desc["width"], "height": desc["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent"},
        },
    }
    for i, s in enumerate(desc["shapes"]):
        shape = {
            "type": "ply",
            "filename": os.path.join(export_dir, s["ply"]),
            "face_normals": True,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": s["reflectance"]}},
        }
        if s["emitter"] is not None:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": s["emitter"]}}
        scene[f"shape{i}"] = shape
    return mi.load_dict(scene), desc


def main():
    export_dir, spp = sys.argv[1], int(sys.argv[2])
    out = sys.argv[3] if len(sys.argv) > 3 else None
    scene, desc = load(export_dir)
    samples = desc["width"] * desc["height"] * spp
    line = f"mitsuba llvm_ad_rgb {desc['width']}x{desc['height']} x {spp} spp, max depth {desc['max_depth']}:"
    cores = os.cpu_count()
    for threads in (1, cores):
        dr.set_thread_count(threads)
        # The first render also compiles the kernel; it is not timed.
        image = mi.render(scene, spp=spp, seed=100)
        dr.eval(image)
        best = float("inf")
        for seed in range(3 if threads > 1 else 1):
            t = time.perf_counter()
            image = mi.render(scene, spp=spp, seed=seed)
            dr.eval(image)
            dr.sync_thread()
            best = min(best, time.perf_counter() - t)
        line += f"  {threads} thread{'s' if threads > 1 else ''}: {samples / best / 1e6:.2f} M samples/s"
        if out and threads == cores:
            mi.util.write_bitmap(out, image)
    print(line)


if __name__ == "__main__":
    main()
