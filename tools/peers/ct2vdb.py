#!/usr/bin/python3
"""Raw CT stack (cdvol sidecar JSON) -> OpenVDB FloatGrid of *negated* values.

Run with Debian's /usr/bin/python3 (python3-openvdb, python3-numpy).
The grid is negated so that `vdb_tool -iso2ls iso=-T` makes bone (HU >= T)
the inside (negative) of the level set, as OpenVDB expects. Voxel (i, j, k)
sits at (i*sx, j*sy, k*sz) mm, like cdvol's and VTK's sample positions.

usage: ct2vdb.py SIDECAR.json OUT.vdb
"""
import json, os, sys, time
import numpy as np
import pyopenvdb as vdb

import sidecar

t0 = time.perf_counter()  # after the imports
side, out = sys.argv[1], sys.argv[2]
meta, a = sidecar.read(side)
nx, ny, nz = meta["dims"]
a = a.reshape(nz, ny, nx).transpose(2, 1, 0)  # -> [x, y, z]
a = np.ascontiguousarray(-a.astype(np.float32))
air = float(a.max())  # negated air: outside of the level set
g = vdb.FloatGrid(background=air)
g.copyFromArray(a, ijk=(0, 0, 0), tolerance=0.0)
sx, sy, sz = meta["x"], meta["y"], meta["z"]
g.transform = vdb.createLinearTransform(
    [[sx, 0, 0, 0], [0, sy, 0, 0], [0, 0, sz, 0], list(meta.get("origin", [0, 0, 0])) + [1]]
)
g.name = "ct_neg"
vdb.write(out, grids=[g])
print(json.dumps({"convert_s": time.perf_counter() - t0, "active_voxels": g.activeVoxelCount(),
                  "openvdb": ".".join(map(str, vdb.LIBRARY_VERSION))}))
