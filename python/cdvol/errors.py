"""The exceptions cdvol raises.

Every one is a :class:`cdvol.Error`; its message is the library's own and
names the file, the field and what was expected. Where a standard
exception fits as well, the class derives from it too, so
``except ValueError`` or ``except FileNotFoundError`` catch what they
should.
"""


class Error(Exception):
    """Any error of cdvol."""


class InputError(Error, ValueError):
    """The input volume cannot be read: a file, a sidecar field, an array's
    shape, strides or values."""


class DtypeError(InputError, TypeError):
    """An array of a type cdvol does not read (complex, object, strings)."""


class ShapeError(InputError):
    """An array of the wrong rank, an empty axis, or a negative stride."""


class PrepError(Error, ValueError):
    """Prep refused its options or its input (a classification that selects
    no cell, an output that is an input, a memory limit)."""


class FormatError(Error):
    """A packed file cannot be opened or read."""


class LookError(Error, ValueError):
    """A look the file cannot give: an unknown preset, an iso value outside
    what the file was prepared for, a bad mode or background."""


class ViewError(Error, ValueError):
    """A view that cannot be placed: an unknown name, a named view of a file
    without orientation, a bad size."""


class RenderError(Error):
    """A render that failed (memory, a brick that does not decode)."""


class FileNotFound(Error, FileNotFoundError):
    """A file that does not exist."""


__all__ = [
    "Error",
    "InputError",
    "DtypeError",
    "ShapeError",
    "PrepError",
    "FormatError",
    "LookError",
    "ViewError",
    "RenderError",
    "FileNotFound",
]
