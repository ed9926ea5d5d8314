"""The matplotlib ``Figure`` that every figure of :mod:`brdffit.plot` is, in a module of its own so
that ``brdffit.plot`` imports matplotlib only when a figure is drawn (``brdffit fit`` makes its
figure's data without matplotlib and draws it in another process: ``brdffit._figure_process``)."""

from __future__ import annotations

import os

import matplotlib
from matplotlib.figure import Figure as _MplFigure

from .style import PNG_COMPRESS_LEVEL, png_bytes


class Figure(_MplFigure):
    """A matplotlib Figure that also shows itself in Jupyter without pyplot (``_repr_png_``) and
    writes PNGs at ``brdffit.plot.PNG_COMPRESS_LEVEL``."""

    def _repr_png_(self) -> bytes:
        return png_bytes(self)

    def savefig(self, fname, *args, **kwargs):
        """``matplotlib.figure.Figure.savefig``; a PNG (by ``format=`` or the file's suffix) is
        compressed at ``PNG_COMPRESS_LEVEL`` unless ``pil_kwargs`` is given."""
        fmt = kwargs.get("format")
        if fmt is None and isinstance(fname, (str, os.PathLike)):
            fmt = os.path.splitext(os.fspath(fname))[1][1:] or None
        if str(fmt or matplotlib.rcParams["savefig.format"]).lower() == "png":
            kwargs.setdefault("pil_kwargs", {"compress_level": PNG_COMPRESS_LEVEL})
        return super().savefig(fname, *args, **kwargs)
