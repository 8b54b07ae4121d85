#!/usr/bin/env python3
"""Intel Open Image Denoise (OIDN) on the per-pixel means: colour, albedo
(TEXTURE_COLOR) and normal (NORMAL), through pyoidn's device/filter API.

`denoise(colour, albedo, normal)` is the whole method, importable on its
own; `main()` is the benchmark loop that feeds it the means.

The auxiliary images are means of a few samples: noisy wherever depth of
field, motion blur or an edge inside a pixel makes the first hit vary. OIDN
offers two ways to handle that: give them as they are with cleanAux off
(the network then discounts their noise), or denoise each one first with
its own RT filter and tell the colour filter they are clean (cleanAux on),
which OIDN's documentation recommends for final-frame quality. We do the
latter (see README.md for the measured difference).
"""

import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pyoidn  # noqa: E402


def _run(device: "pyoidn.Device", inputs: dict[str, np.ndarray], hdr: bool | None,
         clean_aux: bool = False) -> np.ndarray:
    """One RT filter execution; inputs maps OIDN image names to (H, W, 3) float32 arrays."""
    first = next(iter(inputs.values()))
    output = np.zeros_like(first)
    with pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT) as flt:
        for name, image in inputs.items():
            flt.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
        flt.set_image(pyoidn.OIDN_IMAGE_OUTPUT, output, pyoidn.OIDN_FORMAT_FLOAT3)
        if hdr is not None:
            flt.set_bool("hdr", hdr)
        flt.set_bool("cleanAux", clean_aux)
        flt.commit()
        flt.execute()
    error = device.get_error()
    if error is not None:
        raise RuntimeError(f"OIDN: {error}")
    return output


def _prepared(a: np.ndarray | None, low: float, high: float) -> np.ndarray | None:
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float32)
    return np.ascontiguousarray(np.clip(np.where(np.isfinite(a), a, 0.0), low, high), dtype=np.float32)


def denoise(colour: np.ndarray, albedo: np.ndarray | None = None, normal: np.ndarray | None = None,
            prefilter_aux: bool = True) -> np.ndarray:
    """Denoises a (H, W, 3) linear HDR colour image guided by albedo in [0, 1]
    and normals in [-1, 1] (world space, any length: a mean of unit normals
    is shorter where they disagree, which OIDN accepts). Either guide may be
    None; OIDN takes a normal only together with an albedo, so a normal
    without albedo is dropped. Returns a new (H, W, 3) float32 image."""
    # Radiance is non-negative and finite; OIDN's HDR mode expects exactly that.
    colour = np.ascontiguousarray(
        np.maximum(np.where(np.isfinite(colour), colour, 0.0), 0.0), dtype=np.float32)
    albedo = _prepared(albedo, 0.0, 1.0)
    normal = _prepared(normal, -1.0, 1.0) if albedo is not None else None

    # CPU device; numThreads left at its default (0: one thread per core).
    with pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU) as device:
        device.commit()
        if prefilter_aux and albedo is not None:
            # An auxiliary image alone as input: the RT filter denoises it.
            albedo = _run(device, {pyoidn.OIDN_IMAGE_ALBEDO: albedo}, None)
            if normal is not None:
                normal = _run(device, {pyoidn.OIDN_IMAGE_NORMAL: normal}, None)
        inputs = {pyoidn.OIDN_IMAGE_COLOR: colour}
        if albedo is not None:
            inputs[pyoidn.OIDN_IMAGE_ALBEDO] = albedo
        if normal is not None:
            inputs[pyoidn.OIDN_IMAGE_NORMAL] = normal
        return _run(device, inputs, True, clean_aux=prefilter_aux and albedo is not None)


LAYOUT = ["COLOR_R", "COLOR_G", "COLOR_B",
          "TEXTURE_COLOR_R", "TEXTURE_COLOR_G", "TEXTURE_COLOR_B",
          "NORMAL_X", "NORMAL_Y", "NORMAL_Z"]


def main() -> None:
    import fbksd.client as fc

    client = fc.BenchmarkClient()
    info = client.get_scene_info()
    (width, height) = (int(info.get("width")), int(info.get("height")))
    spp = int(info.get("max_spp"))
    client.set_sample_layout([*LAYOUT])
    result = client.get_result_buffer()
    means = np.zeros((height, width, len(LAYOUT)), dtype=np.float64)

    def consume(tile: np.ndarray, offset: tuple[int, int]) -> None:
        (ny, nx, _, _) = tile.shape
        (bx, by) = offset
        means[by:by + ny, bx:bx + nx] = tile.mean(axis=2, dtype=np.float64)

    client.evaluate_samples(spp, consume)

    # A renderer that does not compute a feature fills it with zeros (the
    # procedural renderer does). An all-zero albedo or normal would tell the
    # network the scene is black or has no surfaces, so it is left out.
    has_albedo = bool(means[..., 3:6].any())
    has_normal = bool(means[..., 6:9].any())
    if not has_albedo:
        print("oidn: the renderer provided no TEXTURE_COLOR (every sample is 0): denoising without albedo"
              + (" and normal (OIDN uses a normal only with an albedo)" if has_normal else ""),
              file=sys.stderr)
    if not has_normal:
        print("oidn: the renderer provided no NORMAL (every sample is 0): denoising without it",
              file=sys.stderr)
    result[...] = denoise(means[..., 0:3],
                          means[..., 3:6] if has_albedo else None,
                          means[..., 6:9] if has_normal else None)
    client.send_result()


if __name__ == "__main__":
    main()
