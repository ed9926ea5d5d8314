"""The figure ``brdffit fit`` writes (fit.png), as :class:`FigureData` (arrays and text) that this
process or another one draws (``brdffit._figure_process``)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from .tables import _compare_table_content, _draw_compare_table, _draw_scatter, _scatter_content

if TYPE_CHECKING:
    from ._figure import Figure


def fit_figure(measurement, fit) -> Figure:
    """The figure ``brdffit fit`` writes: :func:`compare_table` on UBO-81 data, else :func:`scatter`."""
    return fit_figure_data(measurement, fit).draw()


def fit_figure_data(measurement, fit) -> FigureData:
    """What :func:`fit_figure` shows, evaluated (the fit on the measurement's directions, the
    residual), ready to be drawn here or in a process without JAX."""
    if measurement.grid == "ubo81":
        title = (f"{fit.model_name} ({fit.solver}, {fit.loss} loss) on {measurement.name}: {fit.status}; "
                 f"log-RMSE {fit.metrics.get('log_rmse', float('nan')):.3g}")
        return FigureData("compare_table", _compare_table_content(measurement, fit, title))
    return FigureData("scatter", _scatter_content(measurement, fit, None))


@dataclasses.dataclass(frozen=True)
class FigureData:
    """A figure's content as NumPy arrays and text: made where the measurement and the fit are
    (:func:`fit_figure_data`), drawn by :meth:`draw` (matplotlib) in this process or in another,
    which then needs neither JAX nor the fit (``brdffit fit`` draws fit.png in a process of its
    own while it fits: ``brdffit._figure_process``). Picklable."""

    kind: str  # the figure: "compare_table" or "scatter"
    content: dict

    def draw(self) -> Figure:
        return _DRAW[self.kind](**self.content)


_DRAW = {"compare_table": _draw_compare_table, "scatter": _draw_scatter}
