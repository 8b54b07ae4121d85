"""The FBKSD renderer API for Python: serve a scene to ``fbksd run``.

The counterpart of the original C++ ``RenderingServer`` and
``SamplesPipe``, for renderers with a Python interface (Mitsuba 3's
``renderers/mitsuba/fbksd-mitsuba`` is one)::

    import fbksd.renderer as fr

    def scene_info():                      # plain values
        return {"width": 64, "height": 48, "max_depth": 5, "random_parameters": "IMAGE_X,IMAGE_Y"}

    def set_layout(elements):              # [(name, number, offset, "INPUT"|"OUTPUT")]
        for name, number, offset, io in elements:
            if name not in ("IMAGE_X", "IMAGE_Y", "COLOR_R", "COLOR_G", "COLOR_B"):
                raise ValueError(f"{name} is not computed by this renderer")

    def fill(tile, positions, samples):
        # positions: (n, 7) float64, one row of PARAMETERS per sample, drawn
        # by the SDK's stratified sampler (INPUT values are the technique's);
        # samples: (n, sample_size) float32, a zero-copy view of the shared
        # tile: write every OUTPUT feature. tile: x0, y0, x1, y1, spp for
        # pixel tiles or first, count for free samples; keys, (n,) uint64,
        # one per sample, for the renderer's own random numbers (a pure
        # function of the request, the pixel and the sample's index, as the
        # built-in renderers' are: derive them from it and any sample
        # replays, whatever tile it comes in).
        samples[:, 2] = positions[:, 0] / 64.0

    fr.RenderingServer(scene_info, fill, set_layout).run()

The OUTPUT random parameters are already written into ``samples``; the
renderer writes features only. An exception in a callback ends the request
with the exception's message and traceback for the technique and the
manager's log.

A renderer whose scenes join a service's pool also makes their
references (``fbksd-<renderer> reference [--key] DIR...``, as
``fbksd-mitsuba`` does): ``scene_digest``, ``reference_key`` and
``note_reference_key`` are the rules every renderer shares for the note
beside a reference (``reference.json``: ``generator``,
``samples_per_pixel``, ``scene_digest``; a reference is current when its
note's key is the key it would have now), and ``FEATURE_BUFFERS`` at ``FEATURE_BUFFER_SPP`` the
feature images made with it. ``scene_meta`` reads and checks a scene's
``fbksd-scene.json`` as the built-in renderers do.
"""

from fbksd._native import (
    FEATURE_BUFFER_SPP,
    FEATURE_BUFFERS,
    RenderingServer,
    note_reference_key,
    reference_key,
    scene_digest,
    scene_meta,
)

# The order of the columns of ``positions``.
PARAMETERS = ("IMAGE_X", "IMAGE_Y", "LENS_U", "LENS_V", "TIME", "LIGHT_X", "LIGHT_Y")

__all__ = [
    "RenderingServer",
    "PARAMETERS",
    "scene_digest",
    "reference_key",
    "note_reference_key",
    "scene_meta",
    "FEATURE_BUFFERS",
    "FEATURE_BUFFER_SPP",
]
