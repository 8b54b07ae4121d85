#!/usr/bin/env python3

import fbksd.client as fc
import numpy as np

result = None

# step 5
def process_samples(tile, offset):
    (ny, nx, ns, ss) = tile.shape
    (bx, by) = offset
    res_window = result[by:by+ny, bx:bx+nx]
    np.mean(tile, out=res_window, axis=2)

# step 1
client = fc.BenchmarkClient()

# step 2
info = client.get_scene_info()
spp = info.get('max_spp')

# step 3
client.set_sample_layout(['COLOR_R', 'COLOR_G', 'COLOR_B'])
result = client.get_result_buffer()

# step 4
client.evaluate_samples(spp, process_samples)

# step 6
client.send_result()
