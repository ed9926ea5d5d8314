"""The explorer's view of one parameter set: the model evaluated once for the 81x81 table, the
slices and the sphere, and the numbers of the fit's loss on the table.

The model runs through the one evaluator (``brdffit.fitting.model_eval.eval_model``: a program
compiled once per model and length, kept on disk), in one call for the table's 6,561 pairs, the
slices' 718 and the preview sphere's lit pixels together. The loss, ``rel_rmse`` and ``log_rmse``
are the fit's own definitions (``brdffit.fitting.losses.values_metrics`` on the fit's prepared
data, in the table's unit), compiled once per loss: the loss shown for a fit's parameters is that
fit's ``loss_value``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..fitting.cache import compiled
from ..fitting.model_eval import eval_model
from ..fitting.losses import values_metrics
from ..fitting.problem import Prepared, prepare
from ..measurement import Measurement
from ..models.base import Model
from ..plot.explorer import ExplorerView
from ..render.tabulated import UboInterpolator
from .lighting import Lighting

#: The numbers the explorer shows besides the loss (``FitResult.metrics`` names).
SHOWN_METRICS = ("rel_rmse", "log_rmse", "rmse")


@dataclasses.dataclass(frozen=True, eq=False)
class Table:
    """A UBO-81 measurement as the explorer uses it."""

    measurement: Measurement
    measured: np.ndarray  # (81, 81, C)
    valid: np.ndarray  # (81, 81) the samples a fit uses
    cos_light: np.ndarray  # (81, 81)
    wi: np.ndarray  # (6561, 3)
    wo: np.ndarray  # (6561, 3)
    prepared: Prepared  # the fit's arrays (``brdffit.fitting.problem.prepare``)
    interpolator: UboInterpolator  # the table between its directions (the measured sphere)

    @classmethod
    def of(cls, m: Measurement) -> "Table":
        wi = np.asarray(m.wi, np.float64)
        return cls(m, m.table().astype(np.float64), m.valid_mask().reshape(81, 81), wi[:, 2].reshape(81, 81), wi,
                   np.asarray(m.wo, np.float64), prepare(m), UboInterpolator.from_measurement(m))


def metrics(table: Table, loss: str, f: np.ndarray) -> dict[str, float]:
    """The fit's ``loss`` and :data:`SHOWN_METRICS` of model values ``f`` (6561, C) on the table."""
    # Samples a fit leaves out have weight 0 in ``data``: they enter no sum (f is finite at every
    # table direction, all above the horizon: the models' contract, brdffit.models.base.Model).
    data = table.prepared.data
    program, _ = compiled(("explorer_metrics", loss), lambda: lambda f, d: values_metrics(f, d, (loss,)), f, data)
    return {k: float(v) for k, v in program(f, data).items() if k == loss or k in SHOWN_METRICS}


def view(table: Table, model: Model, params: dict, lit: Lighting, *, loss: str, status: str,
         warnings: tuple[str, ...] = (), spheres: tuple[np.ndarray, np.ndarray] | None = None, scale: float = 1.0,
         timings: dict | None = None) -> ExplorerView:
    """The :class:`~brdffit.plot.explorer.ExplorerView` of ``model`` at ``params`` under ``lit``.
    ``spheres``: (measured, model) renders to show instead of the preview. ``timings``, when given,
    gets the seconds of the evaluation and of the metrics."""
    t0 = time.perf_counter()
    curve_wi, curve_wo = lit.geometry.curve_pairs()
    sphere = lit.sphere
    n_table, n_curves = len(table.wi), len(curve_wi)
    f = eval_model(model, params, np.concatenate([table.wi, curve_wi, sphere.wi]),
                   np.concatenate([table.wo, curve_wo, sphere.wo]))
    t1 = time.perf_counter()
    numbers = metrics(table, loss, f[:n_table])
    t2 = time.perf_counter()
    if timings is not None:
        timings.update(evaluate=t1 - t0, metrics=t2 - t1)
    fitted = f[:n_table].reshape(table.measured.shape)
    measured_sphere, model_sphere = spheres if spheres is not None else (lit.sphere_measured,
                                                                        sphere.image(f[n_table + n_curves:]))
    return ExplorerView(
        measured=table.measured, valid=table.valid, cos_light=table.cos_light, fitted=fitted, light_row=lit.row,
        light=lit.light, geometry=lit.geometry, curves=lit.geometry.split(f[n_table:n_table + n_curves]),
        sphere_measured=measured_sphere, sphere_fit=model_sphere, sphere_kind="Mitsuba" if spheres is not None else "preview",
        scale=scale, data_name=table.measurement.name, model_name=model.name,
        params={k: np.asarray(v, np.float64) for k, v in params.items()}, loss_name=loss, metrics=numbers,
        status=status, warnings=tuple(warnings))
