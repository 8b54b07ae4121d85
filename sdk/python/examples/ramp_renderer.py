#!/usr/bin/env python3
"""A renderer in Python on ``fbksd.renderer``: colour is a closed-form
function of where a sample lies (red the image x across the width, green
the image y down the height, blue the lens u), so what a technique gets
back can be checked exactly. ``fbksd run -r ramp_renderer.py -s scene.json``;
the scene file is ``{"width": W, "height": H}``.
"""
import json
import sys

import fbksd.renderer as fr

with open(sys.argv[1]) as f:
    scene = json.load(f)
width, height = scene["width"], scene["height"]
offsets = {}


def scene_info():
    return {"width": width, "height": height, "max_depth": 1, "has_dof": True,
            "random_parameters": "IMAGE_X,IMAGE_Y,LENS_U,LENS_V"}


def set_layout(elements):
    offsets.clear()
    for name, number, offset, io in elements:
        if name not in fr.PARAMETERS and name not in ("COLOR_R", "COLOR_G", "COLOR_B"):
            raise ValueError(f"{name} is not computed by the ramp renderer")
        offsets[name] = offset


def fill(tile, positions, samples):
    columns = {"COLOR_R": positions[:, 0] / width, "COLOR_G": positions[:, 1] / height, "COLOR_B": positions[:, 2]}
    for name, values in columns.items():
        if name in offsets:
            samples[:, offsets[name]] = values


fr.RenderingServer(scene_info, fill, set_layout).run()
