"""The 81x81 displays and the fitted-against-measured figures: :func:`table`, :func:`compare_table`,
:func:`scatter`. Each of the last two is made of its content (arrays and text, no matplotlib:
``_*_content``) and its drawing (``_draw_*``), so that ``brdffit fit`` can draw fit.png in
another process (:mod:`brdffit.plot.fitfigure`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._common import (
    _diverging,
    _excluded_legend,
    _grid_table,
    _is_fit,
    _log_colourbar,
    _log_rgb,
    _ring_ticks,
    _sym_norm,
    log_range,
    new_figure,
)
from .style import CHANNEL_COLOURS, channel_names as _channel_names

if TYPE_CHECKING:
    from ._figure import Figure


# -- 81x81 displays ----------------------------------------------------------------------------------
def table(measurement_or_fit, *, title: str | None = None) -> Figure:
    """The 81x81 display of a UBO-81 measurement, a FitResult (evaluated on the grid) or an
    (81, 81, C) array: f_r per channel on a log scale (range from the data), excluded samples
    in magenta."""
    values, valid, _, label = _grid_table(measurement_or_fit)
    lo, hi = log_range(values, valid)
    fig = new_figure((6.6, 6.0), layout="constrained")
    ax = fig.add_subplot()
    ax.imshow(_log_rgb(values, valid, lo, hi), interpolation="nearest")
    _ring_ticks(ax)
    _log_colourbar(fig, lo, hi, "f_r per channel (1/sr), log scale", ax=ax)
    _excluded_legend(ax, int(np.count_nonzero(~valid)))
    ax.set_title(title or f"{label}: f_r on the UBO-81 grid (81 lights × 81 views)", fontsize=9)
    return fig


# Fixed geometry of compare_table, in inches: no layout engine (constrained layout measured every
# text of the figure several times: about two thirds of the time ``brdffit fit`` spent on fit.png).
_PANEL = 3.1  # side of each square 81x81 panel
_GAP = 0.85  # between panels: the next panel's tick labels and axis label
_LEFT = 0.75  # tick labels and axis label of the first column
_BAR_PAD, _BAR_W, _BAR_LABEL = 0.15, 0.14, 0.95  # colour bars: gap, width, room for ticks and label
_TITLE = 0.3  # a panel's title
_SUPTITLE = 0.5
_X_AXIS = 0.6  # tick labels and axis label under a panel
_LEGEND = 0.25  # the excluded-samples legend under the measured panel
_ROW_GAP = 0.15  # between the legend and the residual panels' titles


def _inch_axes(fig, left: float, bottom: float, width: float, height: float):
    w, h = fig.get_size_inches()
    return fig.add_axes((left / w, bottom / h, width / w, height / h))


def compare_table(measurement, fit, *, title: str | None = None) -> Figure:
    """Measured | fitted 81x81 displays (one log scale, from the measured data) and the signed log
    residual per channel (R, G, B), with the RMSE (1/sr) and log-RMSE of the valid samples.

    ``measurement``: a UBO-81 Measurement or an (81, 81, C) table (NaN = excluded); ``fit``: a
    FitResult (evaluated at the measurement's own directions) or an (81, 81, C) table."""
    return _draw_compare_table(**_compare_table_content(measurement, fit, title))


def _compare_table_content(measurement, fit, title: str | None) -> dict:
    """What :func:`compare_table` shows, as arrays and text (the fit evaluated, the residual)."""
    ref, valid, cos_l, ref_label = _grid_table(measurement)
    summary = None
    if _is_fit(fit):
        from ..measurement import Measurement

        if isinstance(measurement, Measurement):
            fitted = np.asarray(fit.eval(np.asarray(measurement.wi), np.asarray(measurement.wo)), np.float64)
            fitted = fitted.reshape(81, 81, -1)
        else:
            fitted = _grid_table(fit)[0]
        fit_label = f"{fit.model_name} ({fit.solver}, {fit.loss} loss)"
        summary = _fit_summary(fit)
    else:
        fitted, _, _, fit_label = _grid_table(fit)
    valid = valid & np.all(np.isfinite(fitted), axis=-1)
    residual, lrmse = _residual_and_log_rmse(fitted, ref, cos_l[..., None], valid[..., None])
    residual[~valid] = np.nan
    v3 = np.broadcast_to(valid[..., None], ref.shape)
    d = (fitted - ref)[v3]
    rmse = float(np.sqrt(np.mean(d * d))) if d.size else float("nan")
    return {"ref": ref, "fitted": fitted, "valid": valid, "residual": residual, "rmse": rmse, "log_rmse": lrmse,
            "ref_label": ref_label, "fit_label": fit_label, "summary": summary, "title": title}


def _draw_compare_table(ref, fitted, valid, residual, rmse: float, log_rmse: float, ref_label: str, fit_label: str,
                        summary: str | None, title: str | None) -> Figure:
    lo, hi = log_range(ref, valid)
    names = _channel_names(ref.shape[-1])
    cols = max(len(names), 2)
    row = _PANEL + _TITLE
    bars_x = _LEFT + cols * _PANEL + (cols - 1) * _GAP + _BAR_PAD
    # A top panel with a residual panel below it (same column, same view rings) leaves the view
    # rings to that one; the fitted panel of a one-channel table has none below and keeps them.
    fitted_view_axis = len(names) < 2
    under_top = (_X_AXIS if fitted_view_axis else 0.0) + _LEGEND + _ROW_GAP
    fig = new_figure((bars_x + _BAR_W + _BAR_LABEL, _X_AXIS + row + under_top + row + _SUPTITLE))
    top_y = _X_AXIS + row + under_top
    ax_m = _inch_axes(fig, _LEFT, top_y, _PANEL, _PANEL)
    ax_f = _inch_axes(fig, _LEFT + _PANEL + _GAP, top_y, _PANEL, _PANEL)
    for ax, img, name in ((ax_m, ref, f"measured: {ref_label}"), (ax_f, fitted, f"fitted: {fit_label}")):
        ax.imshow(_log_rgb(img, valid, lo, hi), interpolation="nearest")
        ax.set_title(name, fontsize=9)
        _ring_ticks(ax, light_axis=ax is ax_m, view_axis=ax is ax_f and fitted_view_axis)
    _log_colourbar(fig, lo, hi, "f_r per channel (1/sr), log scale",
                   cax=_inch_axes(fig, _LEFT + 2 * _PANEL + _GAP + _BAR_PAD, top_y, _BAR_W, _PANEL))
    _excluded_legend(ax_m, int(np.count_nonzero(~valid)), below_view_axis=False)
    if summary is not None and cols >= 3:  # the free slot of the top row: what the fit found
        text_x = _LEFT + 2 * _PANEL + _GAP + _BAR_PAD + _BAR_W + _BAR_LABEL
        fig.text(text_x / fig.get_size_inches()[0], (top_y + _PANEL) / fig.get_size_inches()[1],
                 summary, fontsize=8, va="top", ha="left", family="monospace")
    norm = _sym_norm(residual)
    cmap = _diverging()
    for c, name in enumerate(names):
        ax = _inch_axes(fig, _LEFT + c * (_PANEL + _GAP), _X_AXIS, _PANEL, _PANEL)
        im = ax.imshow(residual[..., c], cmap=cmap, norm=norm, interpolation="nearest")
        ax.set_title(f"{name}: fitted − measured (log residual)", fontsize=9)
        _ring_ticks(ax, light_axis=c == 0)
    cb = fig.colorbar(im, cax=_inch_axes(fig, _LEFT + len(names) * (_PANEL + _GAP) - _GAP + _BAR_PAD, _X_AXIS,
                                         _BAR_W, _PANEL))
    cb.set_label("ln(1 + f_fit cos θ_l) − ln(1 + f_meas cos θ_l)\nred: fit too bright, blue: too dark", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    fig.suptitle(title or f"UBO-81 table: RMSE {rmse:.3g} 1/sr   log-RMSE {log_rmse:.3g} (RMS of the residual shown)",
                 fontsize=10, y=1.0 - 0.12 / fig.get_size_inches()[1], va="top")
    return fig


def _fit_summary(fit) -> str:
    """Parameter values of a fit, one line each (``fit.json`` has them in full)."""
    lines = [f"{fit.model_name} fit, {fit.steps} steps, {fit.loss} loss {fit.loss_value:.4g}"]
    width = max(len(k) for k in fit.params)
    for name, value in fit.params.items():
        values = " ".join(f"{x:.4g}" for x in np.asarray(value, np.float64).reshape(-1))
        lines.append(f"{name:<{width}}  {values}")
    return "\n".join(lines)


def _residual_and_log_rmse(fitted, ref, cos_l, used) -> tuple[np.ndarray, float]:
    """(the signed log residual, log_rmse over ``used``): ``losses.masked_log_residual`` as one
    compiled program, kept on disk like the fit programs (op by op it was ~15 small programs
    compiled per process; jitted, its tracing and lowering cost ~0.1 s of every ``brdffit fit``)."""
    from ..fitting.losses import masked_log_residual
    from ..fitting.cache import compiled

    args = tuple(np.asarray(a, np.float64) for a in (fitted, ref, cos_l, used))
    program, _ = compiled(("masked_log_residual",), lambda: masked_log_residual, *args)
    residual, lrmse = program(*args)
    return np.array(residual), float(lrmse)


def scatter(measurement, fit, *, title: str | None = None) -> Figure:
    """Fitted against measured f_r per channel (R, G, B), log axes: for scattered samples."""
    return _draw_scatter(**_scatter_content(measurement, fit, title))


def _scatter_content(measurement, fit, title: str | None) -> dict:
    return {"ref": np.asarray(measurement.values, np.float64),
            "fitted": np.asarray(fit.eval(np.asarray(measurement.wi), np.asarray(measurement.wo)), np.float64),
            "mask": np.asarray(measurement.valid_mask()),
            "title": title or f"{fit.model_name} on {measurement.name}: {fit.status}"}


def _draw_scatter(ref, fitted, mask, title: str) -> Figure:
    names = _channel_names(ref.shape[1])
    pos = ref[mask][ref[mask] > 0]
    lo = max(float(pos.min()) if pos.size else 1e-3, 1e-6)
    hi = float(max(ref[mask].max(initial=lo), fitted[mask].max(initial=lo)))
    fig = new_figure((6.5, 6.0), layout="constrained")
    ax = fig.add_subplot()
    for c, name in enumerate(names):
        ax.scatter(np.maximum(ref[mask, c], lo), np.maximum(fitted[mask, c], lo), s=4, alpha=0.5,
                   color=CHANNEL_COLOURS.get(name, None), label=name)
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8, label="fitted = measured")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("measured f_r (1/sr)")
    ax.set_ylabel("fitted f_r (1/sr)")
    ax.legend(fontsize=8, title=f"{int(np.count_nonzero(~mask))} samples excluded", title_fontsize=7)
    ax.set_title(title, fontsize=9)
    return fig
