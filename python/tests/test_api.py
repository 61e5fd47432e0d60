"""The package's API against oracles computed here with numpy: classes,
histogram, depth of a sphere; its errors; threads; the warm cache."""

import concurrent.futures
import pathlib
import sys

import numpy as np
import pytest

import cdvol
from conftest import ball


@pytest.fixture(scope="module")
def prepped(tmp_path_factory, phantom):
    a, spacing, positions = phantom
    out = tmp_path_factory.mktemp("api") / "ph.cdv"
    cdvol.prep(a, out, iso=300, spacing=spacing, positions=positions, progress=False)
    return cdvol.open(out), a


def test_classes_are_the_brute_force_classification(prepped):
    vol, a = prepped
    # A cell is an object cell when one of its 8 vertex samples is >= iso.
    m = np.maximum.reduce([a[dz:a.shape[0] - 1 + dz, dy:a.shape[1] - 1 + dy, dx:a.shape[2] - 1 + dx]
                           for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)])
    classes = vol.export("classes", progress=False)
    assert classes.shape == m.shape
    assert np.array_equal(classes, (m >= 300).astype(np.uint8))
    codes = vol.export("codes", progress=False)
    assert np.array_equal(codes == 255, m >= 300)


def test_histogram_counts_the_samples(prepped):
    vol, a = prepped
    counts, edges = vol.histogram()
    assert len(edges) == len(counts) + 1 and counts.sum() == a.size
    # Each bin holds the samples in [edge_i, edge_i+1).
    want = np.diff(np.searchsorted(np.sort(a.ravel()), edges, side="left"))
    assert np.array_equal(counts, want)


def test_info_presets_and_shape(prepped):
    vol, a = prepped
    assert vol.shape == a.shape
    info = vol.info
    assert info["dims"] == [a.shape[2], a.shape[1], a.shape[0]]
    assert info["modality"] == "CT"
    assert "ct-bone" in vol.presets and "ct-bone" in vol.preset_descriptions()


def test_depth_of_a_sphere_follows_its_curvature(tmp_path):
    # A sphere of radius R mm: seen orthographically, the depth at distance
    # r from the centre pixel exceeds the centre's by R - sqrt(R^2 - r^2).
    n, R = 64, 20.0
    cdvol.prep(ball(n, R), tmp_path / "s.cdv", iso=0.0, progress=False)
    vol = cdvol.open(tmp_path / "s.cdv")
    size, frame = 129, 64.0
    d = vol.depth((0, 0), iso=0.0, width=size, height=size, frame=frame)
    assert d.shape == (size, size) and d.dtype == np.float32
    px = frame / size
    jj, ii = np.meshgrid(np.arange(size), np.arange(size))
    r = np.hypot((jj - size // 2) * px, (ii - size // 2) * px)
    assert np.isnan(d[r > R + 2 * px]).all(), "rays past the rim miss"
    inside = r < R - 2 * px
    assert np.isfinite(d[inside]).all()
    want = d[size // 2, size // 2] + R - np.sqrt(R ** 2 - r[inside] ** 2)
    # Trilinear interpolation of a sampled distance field: within 0.05 mm.
    assert np.abs(d[inside] - want).max() < 0.05


def test_a_renderer_keeps_its_cache_warm(prepped):
    vol, _ = prepped
    r = vol.renderer(cache_mb=64)
    _, first = r.render((25, 5), width=64, height=64, return_stats=True)
    _, again = r.render((25, 5), width=64, height=64, return_stats=True)
    assert first["cache_misses"] > 0
    assert again["cache_misses"] == 0 and again["cache_hits"] > 0


def test_renders_in_threads_equal_serial_renders(prepped):
    vol, _ = prepped
    r = vol.renderer()
    views = [(az, el) for az in range(0, 360, 45) for el in (-20, 30)]
    serial = [r.render(v, width=80, height=60) for v in views]
    with concurrent.futures.ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda v: r.render(v, width=80, height=60), views))
    for v, s, t in zip(views, serial, threaded):
        assert np.array_equal(s, t), v


def test_paths_may_be_str_or_pathlib(tmp_path, phantom):
    a, spacing, positions = phantom
    cdvol.prep(a[12:22], str(tmp_path / "a.cdv"), iso=300, spacing=spacing, progress=False)
    assert cdvol.open(pathlib.Path(tmp_path / "a.cdv")).shape == (10,) + a.shape[1:]


@pytest.mark.parametrize("dtype", ["uint8", "int8", "uint16", "int32", "uint32", "int64",
                                   "uint64", "float32", "float64", "float16", "bool"])
def test_every_dtype_preps_with_its_values(tmp_path, dtype):
    rng = np.random.default_rng(1)
    a = (rng.integers(0, 2, (6, 7, 8)) * 100).astype(dtype)
    cdvol.prep(a, tmp_path / "d.cdv", iso=1, modality="CT", progress=False)
    vol = cdvol.open(tmp_path / "d.cdv")
    m = np.maximum.reduce([a[dz:5 + dz, dy:6 + dy, dx:7 + dx].astype(np.float64)
                           for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)])
    assert np.array_equal(vol.export("classes", progress=False), (m >= 1).astype(np.uint8))


# ---- Errors: a cdvol.Error subclass, with the library's message. ----

def test_a_complex_array_is_a_dtype_error(tmp_path):
    with pytest.raises(cdvol.DtypeError, match="complex"):
        cdvol.prep(np.zeros((4, 4, 4), np.complex64), tmp_path / "x.cdv", iso=1)
    assert not (tmp_path / "x.cdv").exists()
    with pytest.raises(TypeError):
        cdvol.prep(np.zeros((4, 4, 4), object), tmp_path / "x.cdv", iso=1)


@pytest.mark.parametrize("shape", [(5,), (5, 6), (2, 3, 4, 5)])
def test_a_shape_of_the_wrong_rank_is_a_shape_error(tmp_path, shape):
    with pytest.raises(cdvol.ShapeError, match=r"expected 3 axes indexed \[z, y, x\]"):
        cdvol.prep(np.zeros(shape, np.int16), tmp_path / "x.cdv", iso=1)


def test_64_bit_integers_beyond_32_bits_are_refused_by_their_range(tmp_path):
    a = np.zeros((3, 3, 3), np.int64)
    a[1, 1, 1] = 1 << 40
    with pytest.raises(cdvol.InputError, match="1099511627776"):
        cdvol.prep(a, tmp_path / "x.cdv", iso=1)


def test_bad_grids_are_named(tmp_path, phantom):
    a = phantom[0]
    with pytest.raises(cdvol.InputError, match="positions: 3 given, expected one per slice"):
        cdvol.prep(a, tmp_path / "x.cdv", iso=1, positions=[0, 1, 2])
    with pytest.raises(cdvol.InputError, match="spacing"):
        cdvol.prep(a, tmp_path / "x.cdv", iso=1, spacing=(1, 0, 1))
    with pytest.raises(cdvol.InputError, match="only with an array"):
        cdvol.prep(tmp_path / "in.nii", tmp_path / "x.cdv", iso=1, spacing=(1, 1, 1))


def test_a_classification_that_selects_nothing_writes_nothing(tmp_path, phantom):
    a = phantom[0]
    with pytest.raises(cdvol.PrepError, match="selects no cells.*allow_empty=True"):
        cdvol.prep(a, tmp_path / "e.cdv", iso=5000, progress=False)
    assert not (tmp_path / "e.cdv").exists()
    cdvol.prep(a, tmp_path / "e.cdv", iso=5000, allow_empty=True, progress=False)
    assert cdvol.open(tmp_path / "e.cdv").info["one_cells"] == 0


def test_an_iso_outside_the_files_range_is_a_look_error(prepped):
    vol, _ = prepped
    # Prepared at 300: a surface below it would need cells prep did not keep.
    with pytest.raises(cdvol.LookError, match="300"):
        vol.render(mode="surface", iso=-700.0, width=32, height=32)
    with pytest.raises(cdvol.LookError, match="no-such-preset"):
        vol.render(preset="no-such-preset", width=32, height=32)
    with pytest.raises(cdvol.LookError, match="expected 8"):
        vol.render(bit_depth=16)


def test_a_bad_view_is_a_view_error(prepped):
    vol, _ = prepped
    with pytest.raises(cdvol.ViewError, match="anterior, posterior"):
        vol.render("sideways")
    with pytest.raises(cdvol.ViewError):
        vol.render((0, 0), width=0)


def test_a_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(cdvol.FileNotFound, match="nothing.cdv"):
        cdvol.open(tmp_path / "nothing.cdv")
    with pytest.raises(FileNotFoundError, match="nothing.nii"):
        cdvol.prep(tmp_path / "nothing.nii", tmp_path / "x.cdv", iso=1)
    assert not (tmp_path / "x.cdv").exists()


def test_a_memmap_is_not_written_over(tmp_path):
    src = np.memmap(tmp_path / "v.raw", mode="w+", dtype=np.int16, shape=(4, 5, 6))
    src[:] = 500
    src.flush()
    before = (tmp_path / "v.raw").read_bytes()
    with pytest.raises(cdvol.PrepError, match="v.raw"):
        cdvol.prep(np.memmap(tmp_path / "v.raw", mode="r", dtype=np.int16, shape=(4, 5, 6)),
                   tmp_path / "v.raw", iso=1)
    assert (tmp_path / "v.raw").read_bytes() == before


def test_progress_draws_bars_where_asked(tmp_path, phantom, capfd, monkeypatch):
    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "q.cdv", iso=300, spacing=spacing, progress=True)
    assert capfd.readouterr().err == "", "no bar when stderr is not a terminal"
    monkeypatch.setitem(sys.modules, "ipykernel", object())  # as in a notebook
    cdvol.prep(a, tmp_path / "q.cdv", iso=300, spacing=spacing, progress=True)
    err = capfd.readouterr().err
    assert "classify + forward DT" in err, err


def test_a_sequence_of_slices_preps_as_the_stacked_array(tmp_path, phantom):
    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "a.cdv", iso=300, spacing=spacing, positions=positions,
               progress=False)
    # Slices as separate arrays, every other one in Fortran order.
    slices = [np.asfortranarray(s) if z % 2 else s.copy() for z, s in enumerate(a)]
    cdvol.prep(slices, tmp_path / "s.cdv", iso=300, spacing=spacing, positions=positions,
               progress=False)
    va, vs = cdvol.open(tmp_path / "a.cdv"), cdvol.open(tmp_path / "s.cdv")
    for what in ("values", "codes"):
        assert np.array_equal(va.export(what, progress=False), vs.export(what, progress=False))
    assert np.array_equal(va.render((20, 30), width=64, height=64),
                          vs.render((20, 30), width=64, height=64))
    with pytest.raises(cdvol.ShapeError, match=r"slice 3: \(45, 51\) int16, expected"):
        cdvol.prep([s if z != 3 else s[:, :-1] for z, s in enumerate(a)], tmp_path / "x.cdv",
                   iso=300)
    with pytest.raises(cdvol.DtypeError, match="slice 2"):
        cdvol.prep([s if z != 2 else s.astype(np.float32) for z, s in enumerate(a)],
                   tmp_path / "x.cdv", iso=300)
    with pytest.raises(cdvol.ShapeError, match="slice 0 of shape"):
        cdvol.prep([a, a], tmp_path / "x.cdv", iso=300)


def test_partial_strides_read_the_field_not_its_neighbours(tmp_path):
    rec = np.zeros((8, 9, 10), dtype=[("flag", "u1"), ("hu", "<i2")])
    rec["hu"] = np.indices((8, 9, 10)).sum(0) * 10
    rec["flag"] = 255
    cdvol.prep(rec["hu"], tmp_path / "r.cdv", iso=50, progress=False)
    cdvol.prep(np.ascontiguousarray(rec["hu"]), tmp_path / "c.cdv", iso=50, progress=False)
    r, c = cdvol.open(tmp_path / "r.cdv"), cdvol.open(tmp_path / "c.cdv")
    for what in ("values", "classes"):
        assert np.array_equal(r.export(what, progress=False), c.export(what, progress=False))


def test_keyword_values_are_checked_by_name(tmp_path, prepped):
    vol, a = prepped
    for kw in (dict(width=-1), dict(width=2 ** 33), dict(height=0)):
        with pytest.raises(cdvol.ViewError, match=next(iter(kw))):
            vol.render(**kw)
    with pytest.raises(cdvol.RenderError, match="cache_mb"):
        vol.renderer(cache_mb=0)
    for kw in (dict(brick=-1), dict(zstd_level=2 ** 40)):
        with pytest.raises(cdvol.PrepError, match=next(iter(kw))):
            cdvol.prep(a, tmp_path / "k.cdv", **kw)
    with pytest.raises(cdvol.ShapeError, match="0 slices"):
        cdvol.prep([], tmp_path / "k.cdv")
    with pytest.raises(cdvol.DtypeError, match="masked"):
        cdvol.prep(np.ma.masked_array(a), tmp_path / "k.cdv", iso=300)
    assert np.array_equal(vol.render(background=None, width=32, height=32),
                          vol.render(width=32, height=32))


def test_an_envelope_may_be_one_name(tmp_path, phantom):
    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "e.cdv", envelope="ct", spacing=spacing, progress=False)
    assert "ct-bone" in cdvol.open(tmp_path / "e.cdv").presets


def test_a_crop_of_the_whole_volume_changes_nothing_and_a_cut_face_is_flat(tmp_path):
    # A ball of radius 20 mm; the plane x = 31.5 (its centre) keeps x <= 31.5.
    n, R = 64, 20.0
    c = (n - 1) / 2
    cdvol.prep(ball(n, R), tmp_path / "s.cdv", iso=0.0, progress=False)
    vol = cdvol.open(tmp_path / "s.cdv")
    box = ((0, n - 1), (0, n - 1), (0, n - 1))
    for mode in ("surface", "mip"):
        assert np.array_equal(vol.render((90, 0), mode=mode, iso=0.0, width=96, height=96),
                              vol.render((90, 0), mode=mode, iso=0.0, width=96, height=96, crop=box))
    size, frame = 129, 64.0
    # Azimuth 90: the eye on the +x side, looking towards -x.
    whole = vol.depth((90, 0), iso=0.0, width=size, height=size, frame=frame)
    cut = vol.depth((90, 0), iso=0.0, width=size, height=size, frame=frame,
                    clip=[(-1.0, 0.0, 0.0, -c)])
    px = frame / size
    jj, ii = np.meshgrid(np.arange(size), np.arange(size))
    r = np.hypot((jj - size // 2) * px, (ii - size // 2) * px)
    disk = r < R - 2 * px
    # The cut face lies on the plane: R deeper than the ball's near pole.
    assert np.abs(cut[disk] - (whole[size // 2, size // 2] + R)).max() < 0.05
    assert np.isnan(cut[r > R + 2 * px]).all()
    with pytest.raises(cdvol.LookError, match="non-zero normal"):
        vol.render(clip=[(0, 0, 0, 1)])
    with pytest.raises(cdvol.LookError, match="outside the volume"):
        vol.render(crop=((100, 120), (0, 10), (0, 10)))


def test_integrators_are_chosen_by_name(prepped):
    vol, _ = prepped
    kw = dict(mode="mip", width=40, height=40, bit_depth=32)
    faces = vol.render((30, 20), integrate="step", **kw)
    # ``step`` alone implies the stepping integrator (the MIP's faces).
    assert np.array_equal(vol.render((30, 20), step=0.5, **kw), faces)
    assert vol.render((30, 20), integrate="segment", **kw).shape == faces.shape
    with pytest.raises(cdvol.LookError, match='"segment", "step" or "reference"'):
        vol.render((30, 20), integrate="exactly", **kw)
