"""TIFF stacks written by tifffile, as reconstruction software and ImageJ
write them, read by `cdvol prep`: every sample back exactly (through
`cdvol export --what values`, the classification keeping every cell),
the voxel size from ImageJ and OME-XML metadata, and a directory with a
slice missing or doubled refused by name."""

import json
import pathlib
import subprocess

import numpy as np
import pytest

tifffile = pytest.importorskip("tifffile", reason="tifffile is installed by .ci/run")

from conftest import run  # noqa: E402


def volume(dtype, shape=(7, 19, 23), seed=3):
    """A random volume [z, y, x] of `dtype` spanning much of its range."""
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return (rng.standard_normal(shape) * 1000).astype(dtype)
    info = np.iinfo(dtype)
    lo, hi = max(info.min, -30000), min(info.max, 60000)
    return rng.integers(lo, hi, size=shape, endpoint=True).astype(dtype)


def values_back(cdvol_bin, tmp_path, src, a):
    """Preps `src` so that every cell is kept (iso below the data) and
    returns its values as `cdvol export` writes them, shaped as `a`."""
    out = tmp_path / "v.cdv"
    iso = float(a.min()) - 1.0
    run(cdvol_bin, "prep", "-q", src, "-o", out, "--iso", iso)
    run(cdvol_bin, "export", "-q", out, "--what", "values", "-o", tmp_path / "dump.json")
    side = json.loads((tmp_path / "dump.json").read_text())
    dt = {"u8": "u1", "i8": "i1", "u16": "<u2", "i16": "<i2", "u32": "<u4", "i32": "<i4",
          "f32": "<f4", "f64": "<f8", "i64": "<i8"}[side["dtype"]]
    got = np.fromfile(tmp_path / side["data"], dtype=dt)
    assert list(side["dims"]) == [a.shape[2], a.shape[1], a.shape[0]]
    return got.reshape(a.shape), side


def info(cdvol_bin, src):
    return json.loads(run(cdvol_bin, "info", "--json", src))


@pytest.mark.parametrize("dtype", ["uint8", "int8", "uint16", "int16", "uint32", "int32", "float32"])
@pytest.mark.parametrize("form", ["strips", "tiles-big-endian-zlib", "lzw"])
def test_a_directory_of_slices_reads_every_value(tmp_path, cdvol_bin, dtype, form):
    a = volume(dtype)
    d = tmp_path / "slices"
    d.mkdir()
    kw = {}
    if form == "tiles-big-endian-zlib":
        kw = dict(tile=(16, 16), byteorder=">", compression="zlib")
    elif form == "lzw":
        kw = dict(compression="lzw", rowsperstrip=5)
    # Numbers in natural order only: slice 2 before slice 10.
    for z in range(a.shape[0]):
        tifffile.imwrite(d / f"rec_{z + 1}.tif", a[z], **kw)
    got, _ = values_back(cdvol_bin, tmp_path, d, a)
    assert np.array_equal(got, a)


def test_a_multi_page_imagej_stack_gives_values_and_voxel_size(tmp_path, cdvol_bin):
    a = volume("uint16", shape=(9, 20, 17))
    f = tmp_path / "stack.tif"
    # 5 um pixels, 20 um slices, as ImageJ writes them.
    tifffile.imwrite(f, a, imagej=True, resolution=(1 / 5.0, 1 / 5.0),
                     metadata={"spacing": 20.0, "unit": "micron", "axes": "ZYX"})
    got, _ = values_back(cdvol_bin, tmp_path, f, a)
    assert np.array_equal(got, a)
    i = info(cdvol_bin, f)
    text = json.dumps(i)
    assert "ImageJ" in text, text
    sp = [ax["spacing_min"] for ax in i["axes"]]
    assert sp == pytest.approx([0.005, 0.005, 0.02]), sp


def test_an_ome_tiff_gives_values_and_voxel_size(tmp_path, cdvol_bin):
    a = volume("float32", shape=(6, 15, 14))
    f = tmp_path / "scan.ome.tif"
    tifffile.imwrite(f, a, ome=True, metadata={
        "axes": "ZYX", "PhysicalSizeX": 0.5, "PhysicalSizeY": 0.25, "PhysicalSizeZ": 2.0})
    got, _ = values_back(cdvol_bin, tmp_path, f, a)
    assert np.array_equal(got, a)
    sp = [ax["spacing_min"] for ax in info(cdvol_bin, f)["axes"]]
    assert sp == pytest.approx([0.0005, 0.00025, 0.002]), sp


def test_a_missing_or_doubled_slice_is_refused_by_name(tmp_path, cdvol_bin):
    a = volume("uint16", shape=(5, 8, 9))
    d = tmp_path / "gap"
    d.mkdir()
    for z in [0, 1, 3, 4]:
        tifffile.imwrite(d / f"s_{z:03d}.tif", a[z])
    r = subprocess.run([str(cdvol_bin), "prep", str(d), "-o", str(tmp_path / "x.cdv"),
                        "--iso", "0"], capture_output=True, text=True)
    assert r.returncode != 0
    assert "s_003.tif" in r.stderr and "slice 2 is missing" in r.stderr, r.stderr
    tifffile.imwrite(d / "s_2.tif", a[2])
    tifffile.imwrite(d / "s_002.tif", a[2])
    r = subprocess.run([str(cdvol_bin), "prep", str(d), "-o", str(tmp_path / "x.cdv"),
                        "--iso", "0"], capture_output=True, text=True)
    assert r.returncode != 0
    assert "slice number 2 again" in r.stderr, r.stderr
    assert not (tmp_path / "x.cdv").exists()


def test_a_sidecar_gives_the_slice_positions_of_a_stack(tmp_path, cdvol_bin):
    """Slices of varying thickness: a JSON sidecar names the directory and
    gives the z positions; x and y come from the ImageJ metadata."""
    a = volume("int16", shape=(6, 12, 10))
    d = tmp_path / "rec"
    d.mkdir()
    for z in range(a.shape[0]):
        tifffile.imwrite(d / f"slice{z:02d}.tif", a[z], imagej=True,
                         resolution=(1 / 0.4, 1 / 0.4), metadata={"unit": "mm"})
    z = [0.0, 1.0, 2.0, 4.0, 6.5, 9.0]
    side = tmp_path / "rec.json"
    side.write_text(json.dumps({"tiff": "rec", "z": {"positions": z}}))
    got, _ = values_back(cdvol_bin, tmp_path, side, a)
    assert np.array_equal(got, a)
    axes = info(cdvol_bin, side)["axes"]
    assert axes[2]["extent"] == [0.0, 9.0] and axes[2]["uniform"] is False
    assert axes[2]["spacing_min"] == pytest.approx(1.0) and axes[2]["spacing_max"] == pytest.approx(2.5)
    assert axes[0]["spacing_min"] == pytest.approx(0.4)
    # A key that is not one of the sidecar's, and positions of the wrong count.
    side.write_text(json.dumps({"tiff": "rec", "z": {"positions": z}, "dtype": "u16"}))
    r = subprocess.run([str(cdvol_bin), "info", str(side)], capture_output=True, text=True)
    assert r.returncode != 0 and "dtype" in r.stderr and "rec.json" in r.stderr, r.stderr
    side.write_text(json.dumps({"tiff": "rec", "z": {"positions": z[:-1]}}))
    r = subprocess.run([str(cdvol_bin), "info", str(side)], capture_output=True, text=True)
    assert r.returncode != 0 and "z" in r.stderr and "rec.json" in r.stderr, r.stderr
