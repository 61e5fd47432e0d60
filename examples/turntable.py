"""From a CT on disk to a contact sheet of a turntable, through numpy.

    python examples/turntable.py [SIDECAR] [OUT.png]

Loads the head CT that tools/fetch-ct.sh fetches (a raw stack and its
sidecar) into a numpy array, prepares it, reads the histogram of its
values, picks the skin's iso value from it (the valley between air and
soft tissue), renders 12 views around the head into one numpy stack, and
saves them as a 4 x 3 contact sheet. CI runs it (.ci/run).
"""

import json
import pathlib
import sys
import tempfile

import numpy as np
from PIL import Image

import cdvol

repo = pathlib.Path(__file__).resolve().parents[1]
sidecar = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else repo / "target/ct/cranium.json")
out = pathlib.Path(sys.argv[2] if len(sys.argv) > 2 else "turntable.png")

# 1. The CT as an array indexed [z, y, x], and its grid in mm.
side = json.loads(sidecar.read_text())
nx, ny, nz = side["dims"]
ct = np.fromfile(sidecar.parent / side["data"], dtype="<i2").reshape(nz, ny, nx)
spacing = (side["x"], side["y"], side["z"])
print(f"CT {ct.shape} {ct.dtype}, spacing {spacing} mm, values {ct.min()} to {ct.max()}")

with tempfile.TemporaryDirectory() as tmp:
    # 2. One file for every CT look (envelope "ct"), then its histogram.
    packed = pathlib.Path(tmp) / "head.cdv"
    cdvol.prep(ct, packed, spacing=spacing, envelope=["ct"])
    vol = cdvol.open(packed)
    counts, edges = vol.histogram()
    centres = 0.5 * (edges[:-1] + edges[1:])

    # 3. The skin: the least populated value between the air peak and the
    # soft-tissue peak, on a histogram smoothed over 50 HU.
    width = max(1, int(round(50 / (edges[1] - edges[0]))))
    smooth = np.convolve(counts, np.ones(width) / width, mode="same")
    air = centres[np.argmax(np.where(centres < -500, smooth, -1))]
    tissue = centres[np.argmax(np.where((centres > -200) & (centres < 200), smooth, -1))]
    between = (centres > air) & (centres < tissue)
    iso = float(centres[between][np.argmin(smooth[between])])
    print(f"air peak {air:.0f} HU, soft-tissue peak {tissue:.0f} HU: skin iso {iso:.0f} HU")

    # 4. A turntable into one (12, H, W, 4) stack, on one warm renderer.
    # Every frame is as wide as the diagonal of the volume's footprint, so
    # nothing leaves it as the volume turns and the head keeps its size.
    (x0, x1), (y0, y1), _ = (a["extent_mm"] for a in vol.info["axes"])
    frame = float(np.hypot(x1 - x0, y1 - y0))
    renderer = vol.renderer()
    frames = np.stack([
        renderer.render((az, 10), iso=iso, mode="surface", width=256, height=256, frame=frame)
        for az in range(0, 360, 30)
    ])
    print(f"turntable {frames.shape} {frames.dtype}")

# 5. A 4 x 3 contact sheet (RGB; the coverage channel is left out).
rows = [np.concatenate(list(frames[r * 4:(r + 1) * 4, :, :, :3]), axis=1) for r in range(3)]
Image.fromarray(np.concatenate(rows, axis=0)).save(out)
print(f"wrote {out}")
