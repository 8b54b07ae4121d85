"""The FBKSD technique API for Python.

Compatible with the original ``fbksd.client`` (thesis appendix B)::

    import fbksd.client as fc
    client = fc.BenchmarkClient()
    spp = client.get_scene_info().get('max_spp')
    client.set_sample_layout(['COLOR_R', 'COLOR_G', 'COLOR_B'])
    result = client.get_result_buffer()            # (height, width, 3) float32
    def consume(tile, offset):                     # tile: (h, w, spp, sample_size)
        (ny, nx, ns, ss) = tile.shape
        (bx, by) = offset
        result[by:by + ny, bx:bx + nx] = tile.mean(axis=2)
    client.evaluate_samples(spp, consume)
    client.send_result()

Added: ``evaluate_input_samples`` (adaptive sampling: the technique writes
INPUT parameters such as ``('IMAGE_X', fc.INPUT)`` before rendering),
``evaluate_sample_count`` / ``evaluate_input_sample_count`` (a number of
samples rather than samples per pixel), ``remaining_samples``, and
``FbksdError`` for failures.
"""

from fbksd._native import INPUT, OUTPUT, BenchmarkClient, FbksdError, SceneInfo

__all__ = ["BenchmarkClient", "SceneInfo", "FbksdError", "INPUT", "OUTPUT"]
