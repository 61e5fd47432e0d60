"""A 2 GiB numpy.memmap preps in bounded memory: the array is read where it
lies, slice by slice, and each slice's pages are given back."""

import os
import subprocess
import sys
import textwrap

import numpy as np

import cdvol

N = 1024  # 1024^3 uint16: 2 GiB


def test_a_2_gib_memmap_preps_under_512_mib(tmp_path):
    raw = tmp_path / "big.raw"
    # Written with plain writes, not through a memmap: a child's peak
    # resident set starts from its parent's at the fork, so the parent
    # must stay small too.
    yy, xx = np.indices((N, N))
    with open(raw, "wb") as f:
        for z in range(N):
            # A ball of radius 400 samples in a dim background.
            r2 = (xx - 512) ** 2 + (yy - 512) ** 2 + (z - 512) ** 2
            f.write(np.where(r2 < 400 ** 2, 2000, 100).astype(np.uint16).tobytes())
    # Measured in a process of its own: its peak resident set is the prep's
    # plus the interpreter's and numpy's.
    script = textwrap.dedent(f"""
        import resource, numpy as np, cdvol
        a = np.memmap({str(raw)!r}, mode="r", dtype=np.uint16, shape=({N}, {N}, {N}))
        r = cdvol.prep(a, {str(tmp_path / "big.cdv")!r}, iso=1000, progress=False)
        print(r["one_cells"], resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    one_cells, peak_kib = map(int, out.stdout.split())
    print(f"2 GiB memmap prep: peak RSS {peak_kib / 1024:.0f} MiB")
    assert one_cells > 0
    assert peak_kib < 512 * 1024, f"peak RSS {peak_kib / 1024:.0f} MiB"
    assert cdvol.open(tmp_path / "big.cdv").shape == (N, N, N)
    os.remove(raw)
