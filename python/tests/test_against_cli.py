"""A numpy array prepared and rendered from Python gives what the command
line gives for the same volume as a raw stack with a sidecar."""

import numpy as np
import pytest
from PIL import Image

import cdvol
from conftest import run, write_sidecar

VIEWS = [(30, 20), (0, 0), (200, -35), (90, 89), (300, 5)]


def png(path):
    return np.asarray(Image.open(path))


@pytest.mark.parametrize("order", ["C", "F"])
def test_array_prep_renders_as_the_cli_prep_of_its_sidecar(tmp_path, cdvol_bin, phantom, order):
    a, spacing, positions = phantom
    side = write_sidecar(tmp_path, "ph", a, spacing, positions)
    run(cdvol_bin, "prep", side, "--envelope", "ct", "-o", tmp_path / "cli.cdv")
    arr = np.asfortranarray(a) if order == "F" else a
    report = cdvol.prep(arr, tmp_path / "py.cdv", envelope=["ct"], spacing=spacing,
                        positions=positions, progress=False)
    assert report["cells"] == 36 * 44 * 51
    cli, py = cdvol.open(tmp_path / "cli.cdv"), cdvol.open(tmp_path / "py.cdv")
    # The same samples and the same distance codes.
    for what in ("values", "codes", "classes"):
        assert np.array_equal(py.export(what, progress=False), cli.export(what, progress=False)), what
    looks = [dict(mode="surface", iso=300.0), dict(mode="composite", preset="ct-bone"),
             dict(mode="mip", preset="ct-mip"), dict(mode="surface", iso=0.0, shadows=True),
             dict(preset="ct-skin")]
    for k, (view, look) in enumerate(zip(VIEWS, looks)):
        mine = py.render(view, width=96, height=80, **look)
        assert mine.shape == (80, 96, 4) and mine.dtype == np.uint8
        assert np.array_equal(mine, cli.render(view, width=96, height=80, **look))
        # ... and RGB equals the PNG `cdvol render` writes.
        args = ["--view", f"{view[0]},{view[1]}", "--width", 96, "--height", 80]
        for key in ("mode", "preset", "iso"):
            if key in look:
                args += [f"--{key}", look[key]]
        if look.get("shadows"):
            args += ["--shadows"]
        out = tmp_path / f"cli{k}.png"
        run(cdvol_bin, "render", tmp_path / "cli.cdv", "-o", out, *args)
        assert np.array_equal(mine[..., :3], png(out)), (view, look)
        assert mine[..., 3].any() and (mine[..., 3] == 0).any(), "the object is in the frame"


def test_transparent_background_is_the_pngs_rgba(tmp_path, cdvol_bin, phantom):
    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "py.cdv", envelope=["ct"], spacing=spacing, positions=positions,
               progress=False)
    mine = cdvol.open(tmp_path / "py.cdv").render((40, 10), preset="ct-bone", width=64, height=64,
                                                  background="transparent")
    run(cdvol_bin, "render", tmp_path / "py.cdv", "-o", tmp_path / "t.png", "--view", "40,10",
        "--width", 64, "--height", 64, "--preset", "ct-bone", "--background", "transparent")
    assert np.array_equal(mine, png(tmp_path / "t.png"))
    white = cdvol.open(tmp_path / "py.cdv").render((40, 10), preset="ct-bone", width=64,
                                                   height=64, background="white")
    miss = mine[..., 3] == 0
    assert miss.any() and (white[miss][:, :3] == 255).all()


def test_float_render_rounds_to_the_8_bit_one(tmp_path, phantom):
    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "py.cdv", envelope=["ct"], spacing=spacing, positions=positions,
               progress=False)
    vol = cdvol.open(tmp_path / "py.cdv")
    f = vol.render((10, 10), preset="ct-bone", width=64, height=48, bit_depth=32)
    u = vol.render((10, 10), preset="ct-bone", width=64, height=48)
    assert f.dtype == np.float32 and f.shape == (48, 64, 4)
    assert 0.0 <= f.min() and f.max() <= 1.0
    assert np.abs(f * 255.0 - u).max() <= 1.0


def test_real_ct_from_an_array_renders_as_the_cli(tmp_path, cdvol_bin, real_ct):
    a, side, spacing = real_ct
    run(cdvol_bin, "prep", side, "--iso", 300, "-o", tmp_path / "cli.cdv")
    cdvol.prep(a, tmp_path / "py.cdv", iso=300, spacing=spacing, progress=False)
    # A path works where an array does.
    cdvol.prep(side, tmp_path / "path.cdv", iso=300, progress=False)
    for view in [(0, 0), (120, 15)]:
        mine = cdvol.open(tmp_path / "py.cdv").render(view, width=128, height=128)
        assert np.array_equal(mine, cdvol.open(tmp_path / "path.cdv").render(view, width=128,
                                                                              height=128))
        run(cdvol_bin, "render", tmp_path / "cli.cdv", "-o", tmp_path / "ct.png",
            "--view", f"{view[0]},{view[1]}", "--width", 128, "--height", 128)
        assert np.array_equal(mine[..., :3], png(tmp_path / "ct.png")), view
        assert (mine[..., 3] == 255).sum() > 128 * 128 // 10, "the skull fills the frame"


def test_float_render_is_the_cli_float_tiff(tmp_path, cdvol_bin, phantom):
    import tifffile

    a, spacing, positions = phantom
    cdvol.prep(a, tmp_path / "py.cdv", envelope=["ct"], spacing=spacing, positions=positions,
               progress=False)
    mine = cdvol.open(tmp_path / "py.cdv").render((10, 10), mode="composite", preset="ct-bone",
                                                  width=64, height=48, bit_depth=32)
    run(cdvol_bin, "render", tmp_path / "py.cdv", "-o", tmp_path / "f.tif", "--view", "10,10",
        "--width", 64, "--height", 48, "--mode", "composite", "--preset", "ct-bone",
        "--bit-depth", 32)
    tiff = tifffile.imread(tmp_path / "f.tif")
    assert tiff.dtype == np.float32 and tiff.shape == (48, 64, 3)
    assert np.array_equal(mine[..., :3], tiff)


def test_a_label_map_preps_and_renders_as_the_cli(tmp_path, cdvol_bin):
    """A label array (two balls and a nested core) prepared with
    ``labels=True`` holds every label exactly and draws the label surfaces
    ``cdvol render --labels`` draws."""
    z, y, x = np.mgrid[0:30, 0:34, 0:38].astype(np.float64)
    a = np.zeros((30, 34, 38), np.uint8)
    a[(x - 12) ** 2 + (y - 16) ** 2 + (z - 15) ** 2 <= 64] = 1
    a[(x - 12) ** 2 + (y - 16) ** 2 + (z - 15) ** 2 <= 9] = 4
    a[(x - 27) ** 2 + (y - 17) ** 2 + (z - 14) ** 2 <= 36] = 2
    side = write_sidecar(tmp_path, "seg", a, (1.0, 1.1, 1.3))
    run(cdvol_bin, "prep", "--labels", side, "-o", tmp_path / "cli.cdv")
    report = cdvol.prep(a, tmp_path / "py.cdv", labels=True, spacing=(1.0, 1.1, 1.3),
                        progress=False)
    assert report["one_cells"] > 0
    py, cli = cdvol.open(tmp_path / "py.cdv"), cdvol.open(tmp_path / "cli.cdv")
    # Every label back, exactly (codes stand for label 0).
    assert np.array_equal(py.export("values", progress=False).reshape(a.shape), a)
    assert [c[0] for c in py.info["labels"]["counts"]] == [1, 2, 4]
    for spec in ("all", "2", "1,4"):
        mine = py.render((30, 20), width=64, height=64, labels=spec)
        out = tmp_path / "l.png"
        run(cdvol_bin, "render", tmp_path / "cli.cdv", "--labels", spec, "--view", "30,20",
            "--width", 64, "--height", 64, "-o", out)
        assert np.array_equal(mine[..., :3], png(out)), spec
        assert np.array_equal(mine, cli.render((30, 20), width=64, height=64, labels=spec))
        assert mine[..., 3].any()
    with pytest.raises(cdvol.Error, match="label 3 does not occur"):
        py.render(labels="3")
    with pytest.raises(cdvol.Error, match="dtype"):
        cdvol.prep(a.astype(np.float32), tmp_path / "f.cdv", labels=True, progress=False)
    assert not (tmp_path / "f.cdv").exists()
