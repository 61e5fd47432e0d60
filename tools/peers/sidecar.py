"""A cdvol raw-stack sidecar (`cdvol info` describes one) read for the
peers: tools/peers/ct2vdb.py, vtk_render.py and vtk_integrators.py."""
import json, os

import numpy as np


def read(sidecar):
    """The sidecar's metadata and its samples, a flat array x fastest as
    in the raw file, in native byte order."""
    meta = json.load(open(sidecar))
    nx, ny, nz = meta["dims"]
    dt = {"i16": "<i2", "u16": "<u2", "u8": "u1", "f32": "<f4"}[meta["dtype"]]
    if meta.get("endian", "little") == "big":
        dt = dt.replace("<", ">")
    raw = os.path.join(os.path.dirname(sidecar), meta["data"])
    arr = np.fromfile(raw, dtype=dt, offset=meta.get("header_bytes", 0), count=nx * ny * nz)
    return meta, arr.astype(arr.dtype.newbyteorder("="))
