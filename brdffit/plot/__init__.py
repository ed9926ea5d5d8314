"""Every figure brdffit makes (docs/validation.md#figures), as matplotlib ``Figure`` objects.

The figures are built without ``matplotlib.pyplot``: no global figure registry, and the caller's
backend is never changed (nothing here calls ``matplotlib.use``). A returned figure shows itself
in Jupyter (it has ``_repr_png_``) and is written with ``fig.savefig(path)``.

- :func:`table`: the 81x81 display of a UBO-81 measurement or of a fit evaluated on the grid.
- :func:`compare_table`: measured | fitted, and the signed log residual per channel (R, G, B).
- :func:`slices`: in-plane and cross-plane polar lobes per channel, measured dots, fitted curve.
- :func:`spheres`: tone-mapped sphere renders (one per light), one exposure for all.
- :func:`sphere_panel`: one light of a validation: reference | fit | signed error per channel.
- :func:`scatter`: fitted against measured values per channel (scattered, non-grid data).
- :func:`usage`: where a scene looks at a material (docs/scene.md#scene-aware-fitting); :func:`scene_panel`: a scene rendered with the
  reference | with the fit | FLIP map.
- :func:`pareto`: error against run time of a :class:`~brdffit.fitting.compare.Report`.
- :func:`fit_figure`: the figure ``brdffit fit`` writes; :func:`fit_figure_data` makes its content
  (:class:`FigureData`: arrays and text) without matplotlib, to be drawn here or in another process.
- :func:`parameter_maps`: the maps ``fit_btf`` made; :func:`btf_panel`: BTF photographs against
  renders of the maps.

Conventions shared by the figures
---------------------------------
- 81x81 displays: rows are light directions, columns view directions, ordered by theta then phi
  (docs/conventions.md#conventions); ticks mark every theta ring (0, 15, ..., 75 degrees) at its centre, thin lines
  between rings, the same on every 81x81 display.
- Values are f_r in 1/sr (never f_r cos). Tables are shown on a log scale per channel whose range
  comes from the measured data (1st percentile of its positive values to its maximum); the colour
  bar gives that range.
- Samples a fit leaves out (weight 0, non-finite, below the horizon) are drawn in magenta, with a
  legend entry and their count.
- Errors are the log residual that ``log_rmse`` is the RMS of (docs/fitting.md#fitting):
  ln(1 + f_fit cos th_l) - ln(1 + f_meas cos th_l), per channel, on a diverging scale whose
  symmetric range comes from the data (99.5th percentile of its magnitude).

The package, a module per figure family: :mod:`~brdffit.plot.tables` (table, compare_table,
scatter), :mod:`~brdffit.plot.fitfigure` (fit_figure, FigureData), :mod:`~brdffit.plot.polar`
(slices), :mod:`~brdffit.plot.renders` (spheres, sphere_panel), :mod:`~brdffit.plot.compare`
(pareto), :mod:`~brdffit.plot.scene` (usage, scene_panel), :mod:`~brdffit.plot.btf` (parameter
maps, BTF panels); what they share in ``_common``; colours and PNG settings in
:mod:`~brdffit.plot.style` (no matplotlib). None of them imports matplotlib at import time: it is
imported with the first figure drawn (``_figure``).
"""

from __future__ import annotations

from ._common import light_label, log_range, log_residual
from .btf import btf_panel, map_preview_png, parameter_maps
from .compare import pareto
from .fitfigure import FigureData, fit_figure, fit_figure_data
from .polar import slices
from .renders import sphere_panel, spheres
from .scene import scene_panel, usage
from .style import CHANNEL_COLOURS, CHANNEL_NAMES, EXCLUDED_COLOUR, PNG_COMPRESS_LEVEL, png_bytes
from .tables import compare_table, scatter, table

__all__ = [
    "Figure",
    "compare_table",
    "pareto",
    "scatter",
    "slices",
    "sphere_panel",
    "spheres",
    "table",
    "fit_figure",
    "fit_figure_data",
    "FigureData",
    "light_label",
    "parameter_maps",
    "map_preview_png",
    "btf_panel",
]


def __getattr__(name: str):
    # ``Figure`` (matplotlib's, which every figure here is) is imported with matplotlib when first
    # needed: the data a figure shows is made without matplotlib (``FigureData``).
    if name == "Figure":
        from ._figure import Figure

        return Figure
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
