"""Fixtures of the Python package's tests: the cdvol command line (to
compare against), a phantom with slices of varying thickness, and the real
CT that tools/fetch-ct.sh fetches."""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cdvol_bin() -> pathlib.Path:
    """The `cdvol` binary: $CDVOL, else the one `cargo test` or `cargo
    build --release` left in target/."""
    for p in (os.environ.get("CDVOL"), REPO / "target/debug/cdvol", REPO / "target/release/cdvol"):
        if p and pathlib.Path(p).is_file():
            return pathlib.Path(p)
    pytest.fail("no cdvol binary: set CDVOL or run `cargo build` first")


def run(cdvol_bin, *args):
    """Runs the command line; fails the test with its stderr."""
    r = subprocess.run([str(cdvol_bin), *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, f"cdvol {' '.join(map(str, args))}: {r.stderr}"
    return r.stdout


def write_sidecar(dir: pathlib.Path, name: str, a: np.ndarray, spacing, positions=None) -> pathlib.Path:
    """`a` ([z, y, x]) as a raw stack with a sidecar in the input schema."""
    dtypes = {np.dtype("int16"): "i16", np.dtype("uint16"): "u16", np.dtype("uint8"): "u8",
              np.dtype("float32"): "f32"}
    raw = dir / f"{name}.raw"
    a.astype(a.dtype.newbyteorder("<")).tofile(raw)
    side = {
        "data": raw.name,
        "dims": [a.shape[2], a.shape[1], a.shape[0]],
        "dtype": dtypes[a.dtype],
        "endian": "little",
        "x": spacing[0],
        "y": spacing[1],
        "z": {"positions": list(positions)} if positions is not None else spacing[2],
        "origin": [0, 0, 0],
    }
    path = dir / f"{name}.json"
    path.write_text(json.dumps(side))
    return path


def spheres(shape=(37, 45, 52), seed=7) -> np.ndarray:
    """An int16 CT-like phantom [z, y, x]: air at -1000 with noise, a soft
    sphere (about 40 HU) holding a bone sphere (about 1000 HU), off
    centre, so views differ."""
    rng = np.random.default_rng(seed)
    z, y, x = np.indices(shape, dtype=np.float64)
    c = np.array(shape) / 2.0
    r_soft = ((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2) ** 0.5
    r_bone = ((z - c[0] - 3) ** 2 + (y - c[1] + 4) ** 2 + (x - c[2] - 5) ** 2) ** 0.5
    a = np.full(shape, -1000.0) + rng.normal(0, 15, shape)
    a[r_soft < 15] = 40 + rng.normal(0, 10, (r_soft < 15).sum())
    a[r_bone < 7] = 1000 + rng.normal(0, 30, (r_bone < 7).sum())
    return np.round(a).astype(np.int16)


def ball(n: int = 64, radius: float = 20.0) -> np.ndarray:
    """A float32 [z, y, x] field, 0 on a sphere of `radius` samples about
    the centre, rising inwards at 100 a sample (1 mm spacing)."""
    z, y, x = np.indices((n, n, n), dtype=np.float64)
    c = (n - 1) / 2
    r = np.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2)
    return (100.0 * (radius - r)).astype(np.float32)


@pytest.fixture(scope="session")
def phantom():
    """(array, spacing, positions): slices 1.0 and 1.6 mm apart in turn."""
    a = spheres()
    gaps = [1.0 if k % 2 == 0 else 1.6 for k in range(a.shape[0] - 1)]
    positions = np.concatenate([[0.0], np.cumsum(gaps)]).tolist()
    return a, (0.8, 0.9, 1.0), positions


@pytest.fixture(scope="session")
def real_ct():
    """(array [z, y, x] int16, sidecar path, spacing) of the real head CT."""
    side = REPO / "target/ct/cranium.json"
    if not side.is_file():
        pytest.fail(f"{side} is missing: run tools/fetch-ct.sh target/ct first")
    s = json.loads(side.read_text())
    nx, ny, nz = s["dims"]
    a = np.fromfile(side.parent / s["data"], dtype="<i2").reshape(nz, ny, nx)
    return a, side, (s["x"], s["y"], s["z"])
