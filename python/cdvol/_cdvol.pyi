# The extension module (python/src/lib.rs). Its callers are in
# cdvol/__init__.py, which holds the documented, keyword-argument API.
import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

__version__: str

_Progress = Optional[Callable[[str, str, int], None]]

# The keywords of cdvol.prep, as a dict: iso, preset, envelope, modality,
# brick, zstd_level, aniso, allow_empty, labels.
PrepKw = Dict[str, Any]
# An array's grid: spacing, origin, positions, rescale.
GridKw = Dict[str, Any]
# The keywords of Renderer.render, as a dict: view, mode, preset, iso,
# width, height, background, shadows, shade, step, perspective, frame, float,
# crop, clip, cap, labels.
RenderKw = Dict[str, Any]

def prep_path(
    source: os.PathLike[str], out: os.PathLike[str], kw: PrepKw, progress: _Progress
) -> dict: ...
def prep_array(
    array: np.ndarray,
    out: os.PathLike[str],
    grid: GridKw,
    kw: PrepKw,
    files: Sequence[os.PathLike[str]],
    progress: _Progress,
) -> dict: ...
def prep_slices(
    slices: Sequence[np.ndarray],
    out: os.PathLike[str],
    grid: GridKw,
    kw: PrepKw,
    progress: _Progress,
) -> dict: ...

class RRenderer:
    def render(self, kw: RenderKw) -> Tuple[np.ndarray, Optional[np.ndarray], str]: ...

class RVolume:
    def __init__(self, path: os.PathLike[str]) -> None: ...
    def info_json(self) -> str: ...
    def histogram(self) -> Optional[Tuple[list[int], float, float]]: ...
    def presets(self) -> list[Tuple[str, str, str]]: ...
    def layout(self) -> Tuple[str, List[int], List[int]]: ...
    def export(self, what: str, progress: _Progress) -> np.ndarray: ...
    def renderer(self, cache_mb: int) -> RRenderer: ...
