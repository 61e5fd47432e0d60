"""cdvol: prepare CT and MR volumes larger than memory, and ray-cast them.

numpy in, numpy out::

    import numpy as np
    import cdvol

    ct = np.load("head.npy")                      # int16, indexed [z, y, x]
    cdvol.prep(ct, "head.cdv", spacing=(0.49, 0.49, 1.25))
    vol = cdvol.open("head.cdv")
    counts, edges = vol.histogram()
    front = vol.render(view=(0, 10), preset="ct-bone")      # (512, 512, 4) uint8
    depth = vol.depth(view=(30, 10), iso=300.0)             # (512, 512) float32, mm

A path works wherever an array does: a DICOM directory, NIfTI, NRRD or a
raw-stack sidecar. Images are those ``cdvol render`` writes for the same
options, byte for byte. Renders and preps release the GIL and run on
cdvol's own threads; a :class:`Renderer` keeps its brick cache between
calls, so a loop over views is warm. Errors are :class:`cdvol.Error` and
its subclasses (:mod:`cdvol.errors`), carrying the library's message.
"""

from __future__ import annotations

import json
import os
import pathlib
import sys
from typing import Any, Callable, Optional, Sequence, Tuple, Union

import numpy as np

from . import _cdvol, errors
from .errors import (
    DtypeError,
    Error,
    FileNotFound,
    FormatError,
    InputError,
    LookError,
    PrepError,
    RenderError,
    ShapeError,
    ViewError,
)

__version__ = _cdvol.__version__

__all__ = ["prep", "open", "Volume", "Renderer", *errors.__all__]

PathLike = Union[str, "os.PathLike[str]"]
ViewSpec = Union[None, str, Tuple[float, float]]


def _progress(enabled: bool) -> Optional[Callable[[str, str, int], None]]:
    """A callback that draws cdvol's progress as tqdm bars: in a terminal
    (stderr is one) or a Jupyter notebook, and only when ``enabled``."""
    if not enabled:
        return None
    in_notebook = "ipykernel" in sys.modules
    if not (in_notebook or (hasattr(sys.stderr, "isatty") and sys.stderr.isatty())):
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # tqdm is a dependency; a broken install draws nothing
        return None
    bar: list = [None]

    def callback(event: str, stage: str, n: int) -> None:
        if event == "begin":
            if bar[0] is not None:
                bar[0].close()
            bar[0] = tqdm(total=n or None, desc=stage, unit="", leave=False)
        elif event == "advance" and bar[0] is not None:
            bar[0].update(n)
        elif event == "end" and bar[0] is not None:
            bar[0].close()
            bar[0] = None
        elif event == "print":
            tqdm.write(stage)

    return callback


def _readable(a: np.ndarray, what: str) -> np.ndarray:
    """``a`` with a dtype cdvol reads, in native byte order, with no
    negative stride; copied only when one of these must change."""
    if isinstance(a, np.ma.MaskedArray):
        raise DtypeError(f"{what}: a masked array; fill it first (a.filled(value))")
    if a.dtype.kind not in "biuf":
        raise DtypeError(f"{what} dtype {a.dtype}: expected an integer, float or bool dtype")
    if a.dtype == np.float16:
        a = a.astype(np.float32)
    if not a.dtype.isnative:
        a = a.astype(a.dtype.newbyteorder("="))
    # Negative strides, strides that are no whole number of elements (a
    # field of a structured array) and unaligned data: a C-order copy.
    if (any(s < 0 or s % a.itemsize for s in a.strides) or not a.flags.aligned):
        a = np.ascontiguousarray(a)
    return a


def _volume_array(a: np.ndarray) -> np.ndarray:
    """``a`` as cdvol reads it: 3-D, see :func:`_readable`."""
    if a.ndim != 3:
        hint = (
            " (a 2-D array is one slice: pass a 3-D array or a sequence of 2-D "
            "slices in z order)"
            if a.ndim == 2
            else ""
        )
        raise ShapeError(f"array of shape {a.shape}: expected 3 axes indexed [z, y, x]{hint}")
    return _readable(a, "array")


def _slices(seq: Sequence[np.ndarray]) -> list:
    """A sequence of 2-D slices as cdvol reads them: one shape, one dtype,
    one layout (C order for all when theirs differ)."""
    out = []
    for z, s in enumerate(seq):
        s = np.asarray(s)
        if s.ndim != 2:
            raise ShapeError(f"slice {z} of shape {s.shape}: expected 2 axes indexed [y, x]")
        s = _readable(s, f"slice {z}")
        if out and (s.shape, s.dtype) != (out[0].shape, out[0].dtype):
            cls = ShapeError if s.shape != out[0].shape else DtypeError
            raise cls(
                f"slice {z}: {s.shape} {s.dtype}, expected slice 0's "
                f"{out[0].shape} {out[0].dtype}"
            )
        out.append(s)
    if len({s.strides for s in out}) > 1:
        out = [np.ascontiguousarray(s) for s in out]
    return out


def _in_range(name: str, value: Any, lo: int, hi: int, cls: type) -> int:
    """``value`` as an int in ``lo..=hi``, else ``cls`` naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise cls(f"{name} {value!r}: expected an integer from {lo} to {hi}")
    return int(value)


def _mapped_file(a: np.ndarray) -> list:
    """The file a numpy.memmap maps: prep refuses to write over it."""
    name = getattr(a, "filename", None)
    return [pathlib.Path(name)] if isinstance(a, np.memmap) and name else []


def prep(
    source: Union[PathLike, np.ndarray, Sequence[np.ndarray]],
    out: PathLike,
    *,
    iso: Optional[float] = None,
    preset: Optional[str] = None,
    envelope: Optional[Sequence[Union[str, float]]] = None,
    spacing: Optional[Sequence[float]] = None,
    positions: Optional[Sequence[float]] = None,
    origin: Optional[Sequence[float]] = None,
    rescale: Optional[Tuple[float, float]] = None,
    modality: Optional[str] = None,
    brick: int = 32,
    zstd_level: int = 3,
    aniso: bool = False,
    allow_empty: bool = False,
    labels: bool = False,
    progress: bool = True,
) -> dict:
    """Prepares a volume into the packed file ``out`` (``cdvol prep``).

    ``source`` is a path (a DICOM directory, NIfTI, NRRD or a raw-stack
    sidecar), a numpy array indexed ``[z, y, x]`` of any integer, bool or
    float dtype, in C or Fortran order, or a sequence of 2-D arrays
    ``[y, x]``, one a slice in z order (slices read one by one, never
    stacked). Arrays are read where they lie, without a copy (but for a
    non-native byte order, float16, negative or partial strides and
    unaligned data, which are copied first); a C-order
    ``numpy.memmap`` opened ``"r"`` or ``"r+"`` is read
    slice by slice with each slice's pages given back, so a volume larger
    than memory preps in a few hundred MiB. 64-bit integers are stored in
    the smallest integer type that holds their range.

    Classification, one of (as ``cdvol prep``):

    - ``iso``: a cell is an object when a vertex value is >= ``iso``;
    - ``preset``: the cells a preset's transfer function makes visible,
      and the preset becomes the file's look;
    - ``envelope``: iso values, presets, ``"ct"`` or ``"mr"``: one file for
      all of them (``cdvol prep --envelope``).

    - ``labels``: the source is a label map (integers 0..65535, 0 = none,
      no rescale): classified by the union of its labels, every label kept
      exactly (``cdvol prep --labels``); render it with ``labels=``.

    With none, ``envelope=["auto"]``: every preset of the input's modality.

    For an array: ``spacing=(sx, sy, sz)`` in mm, x first (default 1 mm);
    ``positions``, one z position per slice in mm, for slices of varying
    thickness (then ``sz`` is unused); ``origin=(x0, y0, z0)`` in mm;
    ``rescale=(slope, intercept)`` turns stored values into units (HU);
    ``modality`` ``"CT"`` or ``"MR"`` when the guess from the values is
    wrong.

    A classification that selects no cell is refused (the file would
    render empty) unless ``allow_empty``. ``brick`` (cells per brick edge)
    and ``zstd_level`` tune the file; ``aniso`` adds the octant codes that
    make renders 10-15 % faster (``cdvol prep --aniso``).

    ``out`` is written through a temporary file renamed when complete.
    Returns what prep did: ``seconds``, ``cells``, ``one_cells``, ``bytes``,
    ``classification`` and a ``warning`` (or None) when the classification
    selects nearly all cells.
    """
    if isinstance(envelope, (str, int, float)):
        envelope = [envelope]
    if envelope is not None and len(envelope) == 0:
        raise PrepError("envelope []: expected iso values, presets, \"ct\", \"mr\" or \"auto\"")
    _in_range("brick", brick, 4, 1024, PrepError)
    _in_range("zstd_level", zstd_level, -7, 22, PrepError)
    kw = dict(
        iso=None if iso is None else float(iso),
        preset=preset,
        envelope=None if envelope is None else [str(e) for e in envelope],
        modality=modality,
        brick=int(brick),
        zstd_level=int(zstd_level),
        aniso=bool(aniso),
        allow_empty=bool(allow_empty),
        labels=bool(labels),
    )
    cb = _progress(progress)
    out = pathlib.Path(os.fspath(out))
    stack = isinstance(source, (list, tuple))
    if stack and not all(isinstance(s, np.ndarray) for s in source):
        raise InputError("a list of slices: expected 2-D numpy arrays only")
    if stack and len(source) < 2:
        raise ShapeError(f"{len(source)} slices: expected at least 2")
    if not (stack or isinstance(source, (np.ndarray, str, os.PathLike))):
        raise InputError(
            f"source of type {type(source).__name__}: expected a path, a numpy array "
            "or a list of 2-D numpy arrays"
        )
    if isinstance(source, np.ndarray) or stack:
        sp = (1.0, 1.0, 1.0) if spacing is None else tuple(float(s) for s in spacing)
        if len(sp) != 3:
            raise InputError(f"spacing {spacing!r}: expected (sx, sy, sz) in mm, x first")
        org = (0.0, 0.0, 0.0) if origin is None else tuple(float(o) for o in origin)
        if len(org) != 3:
            raise InputError(f"origin {origin!r}: expected (x0, y0, z0) in mm")
        pos = None if positions is None else [float(p) for p in positions]
        rs = None if rescale is None else (float(rescale[0]), float(rescale[1]))
        grid = dict(spacing=sp, origin=org, positions=pos, rescale=rs)
        if stack:
            return _cdvol.prep_slices(_slices(source), out, grid, kw, cb)
        a = _volume_array(source)
        return _cdvol.prep_array(a, out, grid, kw, _mapped_file(source), cb)
    for name, given in (("spacing", spacing), ("positions", positions),
                        ("origin", origin), ("rescale", rescale)):
        if given is not None:
            raise InputError(
                f"{name}: a file states its own grid and rescale; give {name} "
                "only with an array"
            )
    return _cdvol.prep_path(pathlib.Path(os.fspath(source)), out, kw, cb)


class Renderer:
    """Renders views of one packed file through a brick cache it keeps:
    the bricks one render decodes are there for the next. Safe to share
    between threads; renders release the GIL."""

    def __init__(self, volume: "Volume", cache_mb: int = 512):
        self._r = volume._v.renderer(_in_range("cache_mb", cache_mb, 1, 1 << 30, RenderError))

    def _render(self, view, mode, preset, iso, width, height, background,
                shadows, shade, step, perspective, frame, bit_depth,
                crop=None, clip=(), cap=True, labels=None, integrate=None):
        if bit_depth not in (8, 32):
            raise LookError(f"bit_depth {bit_depth}: expected 8 (uint8) or 32 (float32)")
        width = _in_range("width", width, 1, (1 << 32) - 1, ViewError)
        height = _in_range("height", height, 1, (1 << 32) - 1, ViewError)
        if background is None:
            background = "black"
        if isinstance(view, list):
            view = tuple(view)
        return self._r.render(dict(
            view=view,
            mode=mode,
            preset=preset,
            iso=None if iso is None else float(iso),
            width=int(width),
            height=int(height),
            background=str(background),
            shadows=bool(shadows),
            shade=bool(shade),
            step=None if step is None else float(step),
            perspective=None if perspective is None else float(perspective),
            frame=None if frame is None else float(frame),
            float=bit_depth == 32,
            crop=None if crop is None else [[float(a), float(b)] for a, b in crop],
            clip=[[float(x) for x in p] for p in clip],
            cap=bool(cap),
            labels=None if labels is None else str(labels),
            integrate=None if integrate is None else str(integrate),
        ))

    def render(
        self,
        view: ViewSpec = None,
        *,
        mode: Optional[str] = None,
        preset: Optional[str] = None,
        iso: Optional[float] = None,
        width: int = 512,
        height: int = 512,
        background: str = "black",
        shadows: bool = False,
        shade: bool = False,
        step: Optional[float] = None,
        perspective: Optional[float] = None,
        frame: Optional[float] = None,
        bit_depth: int = 8,
        crop: Optional[Sequence[Tuple[float, float]]] = None,
        clip: Sequence[Tuple[float, float, float, float]] = (),
        cap: bool = True,
        labels: Optional[str] = None,
        integrate: Optional[str] = None,
        return_stats: bool = False,
    ) -> Any:
        """Renders one view as an ``(height, width, 4)`` array, row 0 at the
        top: uint8, or float32 in [0, 1] with ``bit_depth=32``.

        RGB is what ``cdvol render`` writes for the same options: the colour
        over ``background`` (``"black"``, ``"white"``, ``"R,G,B"``,
        ``"#rrggbb"``); channel 3 is the coverage. With
        ``background="transparent"`` the four channels are the PNG's
        straight RGBA.

        - ``view``: ``"anterior"``, ``"posterior"``, ``"left"``, ``"right"``,
          ``"superior"``, ``"inferior"`` or ``(azimuth, elevation)`` in
          degrees; default ``(0, 0)``, anterior for oriented files.
        - ``mode``: ``"surface"``, ``"composite"``, ``"mip"``, ``"depth"``
          or ``"cost"``; default the file's look, else a surface.
        - ``preset``: a name of :attr:`Volume.presets`; ``iso``: the surface's
          value (it must be one the file was prepared for).
        - ``shadows``, ``shade``: shadow rays for surfaces; shading for
          composites. ``integrate``: ``"segment"`` (the default: each
          cell's stretch of ray integrated exactly; the MIP's exact
          maximum), ``"step"`` (samples ``step`` mm apart, 0.5; the MIP at
          cell faces) or ``"reference"`` (slow f64, for measuring);
          ``step`` alone implies ``"step"``.
        - ``perspective``: field of view in degrees (default orthographic);
          ``frame``: the orthographic frame's height in mm (default: the
          object fits).
        - ``crop``: keep only ``((x0, x1), (y0, y1), (z0, z1))`` in mm, the
          file's coordinates; ``clip``: up to six planes ``(nx, ny, nz, d)``,
          each keeping ``nx*x + ny*y + nz*z >= d``; ``cap``: surfaces cut by
          them show their cut faces (else they are left open).
        - ``labels``: a label file's labels to draw, ``"all"``, ``"1,5-9"``
          or names from its colour table (default: all of them).

        With ``return_stats=True`` returns ``(image, stats)``, ``stats`` the
        dict ``cdvol render --stats-json`` prints.
        """
        rgba, _, stats = self._render(view, mode, preset, iso, width, height,
                                      background, shadows, shade, step,
                                      perspective, frame, bit_depth, crop, clip, cap,
                                      labels, integrate)
        image = rgba.reshape(int(height), int(width), 4)
        return (image, json.loads(stats)) if return_stats else image

    def depth(
        self,
        view: ViewSpec = None,
        *,
        iso: Optional[float] = None,
        preset: Optional[str] = None,
        width: int = 512,
        height: int = 512,
        perspective: Optional[float] = None,
        frame: Optional[float] = None,
        crop: Optional[Sequence[Tuple[float, float]]] = None,
        clip: Sequence[Tuple[float, float, float, float]] = (),
        cap: bool = True,
    ) -> np.ndarray:
        """The distance in mm from the eye (orthographic: from the image
        plane) to the surface at ``iso`` along each pixel's ray, as an
        ``(height, width)`` float32 array, NaN where the ray misses; with
        ``crop`` and ``clip`` as in :meth:`render`, a cut face is a hit."""
        _, depth, _ = self._render(view, "depth", preset, iso, width, height,
                                   "black", False, False, None, perspective,
                                   frame, 8, crop, clip, cap)
        return depth.reshape(int(height), int(width))


class Volume:
    """A packed file, open (:func:`cdvol.open`)."""

    def __init__(self, path: PathLike):
        self.path = pathlib.Path(os.fspath(path))
        self._v = _cdvol.RVolume(self.path)
        self._renderer: Optional[Renderer] = None
        self._info: Optional[dict] = None

    def __repr__(self) -> str:
        nx, ny, nz = self._v.layout()[1]
        return f"cdvol.Volume({str(self.path)!r}, shape=({nz}, {ny}, {nx}))"

    @property
    def info(self) -> dict:
        """What ``cdvol info --json`` prints: grid, axes, classification,
        modality, bricks, codes."""
        if self._info is None:
            self._info = json.loads(self._v.info_json())
        return self._info

    @property
    def shape(self) -> Tuple[int, int, int]:
        """Samples ``(nz, ny, nx)``, as the array :meth:`export` returns."""
        nx, ny, nz = self._v.layout()[1]
        return (nz, ny, nx)

    @property
    def presets(self) -> list:
        """The names of the presets this file offers (its modality's; MR
        presets placed on its values)."""
        return [name for name, _, _ in self._v.presets()]

    def preset_descriptions(self) -> dict:
        """``{name: description}`` of :attr:`presets`."""
        return {name: desc for name, _, desc in self._v.presets()}

    def histogram(self) -> Tuple[np.ndarray, np.ndarray]:
        """The histogram of the volume's values (in units: HU for CT) that
        prep recorded: ``(counts, edges)``, as :func:`numpy.histogram`
        returns them (``len(edges) == len(counts) + 1``)."""
        h = self._v.histogram()
        if h is None:
            raise FormatError(f"{self.path}: the file records no value histogram")
        counts, lo, width = h
        counts = np.asarray(counts, dtype=np.int64)
        edges = lo + width * np.arange(len(counts) + 1, dtype=np.float64)
        return counts, edges

    def renderer(self, cache_mb: int = 512) -> Renderer:
        """A new :class:`Renderer` with a cache of ``cache_mb`` MiB."""
        return Renderer(self, cache_mb)

    def _default(self) -> Renderer:
        if self._renderer is None:
            self._renderer = Renderer(self)
        return self._renderer

    def render(self, view: ViewSpec = None, **kwargs: Any) -> Any:
        """:meth:`Renderer.render` through this volume's own renderer (warm
        from one call to the next)."""
        return self._default().render(view, **kwargs)

    def depth(self, view: ViewSpec = None, **kwargs: Any) -> np.ndarray:
        """:meth:`Renderer.depth` through this volume's own renderer."""
        return self._default().depth(view, **kwargs)

    def export(self, what: str = "values", *, progress: bool = True) -> np.ndarray:
        """The whole volume as an array indexed ``[z, y, x]`` (``cdvol
        export``): ``"values"``, the samples in the file's stored type
        (stored words replaced by codes read as the input's smallest value,
        NaN for floats);
        ``"codes"``, one uint8 per cell, the distance code of each empty
        cell and 255 for object cells; ``"classes"``, 1 for object cells
        and 0 for the rest. Cells are one fewer than samples on each
        axis."""
        dtype_name, (nx, ny, nz), (cx, cy, cz) = self._v.layout()
        raw = self._v.export(what, _progress(progress))
        if what == "values":
            return raw.view(_STORED[dtype_name]).reshape(nz, ny, nx)
        return raw.reshape(cz, cy, cx)


# The file's stored types as numpy reads the export's little-endian bytes.
_STORED = {
    "u8": np.dtype("u1"), "i8": np.dtype("i1"), "u16": np.dtype("<u2"),
    "i16": np.dtype("<i2"), "u32": np.dtype("<u4"), "i32": np.dtype("<i4"),
    "i64": np.dtype("<i8"), "f32": np.dtype("<f4"), "f64": np.dtype("<f8"),
}


def open(path: PathLike) -> Volume:  # noqa: A001 - cdvol.open reads as io.open does
    """Opens the packed file ``path`` (the output of :func:`prep`)."""
    return Volume(path)
