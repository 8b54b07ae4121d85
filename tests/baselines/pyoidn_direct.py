#!/usr/bin/env python3
"""Applies Intel Open Image Denoise through pyoidn, directly, to the means
saved by feature_means.py, in the way the oidn baseline documents (its
README): albedo and normal each denoised by an RT filter of their own, then
the HDR colour with those as clean auxiliary images. Writes the image as
raw little-endian float32.

    python3 pyoidn_direct.py means.npz out.f32
"""

import sys

import numpy as np
import pyoidn


def rt_filter(device, images, output, **flags):
    """Runs one RT filter over `images` (OIDN image name → array) into `output`."""
    with pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT) as f:
        for name, image in images.items():
            f.set_image(name, np.ascontiguousarray(image, dtype=np.float32), pyoidn.OIDN_FORMAT_FLOAT3)
        f.set_image(pyoidn.OIDN_IMAGE_OUTPUT, output, pyoidn.OIDN_FORMAT_FLOAT3)
        for flag, value in flags.items():
            f.set_bool(flag, value)
        f.commit()
        f.execute()
    assert device.get_error() is None, device.get_error()
    return output


def main() -> None:
    (means, out) = sys.argv[1:3]
    with np.load(means) as m:
        colour, albedo, normal = np.maximum(m["color"], 0), np.clip(m["albedo"], 0, 1), np.clip(m["normal"], -1, 1)
    with pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU) as device:
        device.commit()
        albedo = rt_filter(device, {pyoidn.OIDN_IMAGE_ALBEDO: albedo}, np.zeros_like(albedo))
        normal = rt_filter(device, {pyoidn.OIDN_IMAGE_NORMAL: normal}, np.zeros_like(normal))
        image = rt_filter(device, {pyoidn.OIDN_IMAGE_COLOR: colour, pyoidn.OIDN_IMAGE_ALBEDO: albedo,
                                   pyoidn.OIDN_IMAGE_NORMAL: normal}, np.zeros_like(colour), hdr=True, cleanAux=True)
    image.astype("<f4").tofile(out)


if __name__ == "__main__":
    main()
