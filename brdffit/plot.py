"""Every figure brdffit makes (SPEC 9), as matplotlib ``Figure`` objects.

The figures are built without ``matplotlib.pyplot``: no global figure registry, and the caller's
backend is never changed (nothing here calls ``matplotlib.use``). A returned figure shows itself
in Jupyter (it has ``_repr_png_``) and is written with ``fig.savefig(path)``.

- :func:`table`: the 81x81 display of a UBO-81 measurement or of a fit evaluated on the grid.
- :func:`compare_table`: measured | fitted, and the signed log residual per channel (R, G, B).
- :func:`slices`: in-plane and cross-plane polar lobes per channel, measured dots, fitted curve.
- :func:`spheres`: tone-mapped sphere renders (one per light), one exposure for all.
- :func:`sphere_panel`: one light of a validation: reference | fit | signed error per channel.
- :func:`scatter`: fitted against measured values per channel (scattered, non-grid data).
- :func:`usage`: where a scene looks at a material (SPEC 12); :func:`scene_panel`: a scene rendered with the
  reference | with the fit | FLIP map.
- :func:`pareto`: error against run time of a :class:`~brdffit.fitting.compare.Report`.
- :func:`fit_figure`: the figure ``brdffit fit`` writes; :func:`fit_figure_data` makes its content
  (:class:`FigureData`: arrays and text) without matplotlib, to be drawn here or in another process.
- :func:`parameter_maps`: the maps ``fit_btf`` made; :func:`btf_panel`: BTF photographs against
  renders of the maps.

Conventions shared by the figures
---------------------------------
- 81x81 displays: rows are light directions, columns view directions, ordered by theta then phi
  (SPEC 1); ticks mark every theta ring (0, 15, ..., 75 degrees) at its centre, thin lines
  between rings, the same on every 81x81 display.
- Values are f_r in 1/sr (never f_r cos). Tables are shown on a log scale per channel whose range
  comes from the measured data (1st percentile of its positive values to its maximum); the colour
  bar gives that range.
- Samples a fit leaves out (weight 0, non-finite, below the horizon) are drawn in magenta, with a
  legend entry and their count.
- Errors are the log residual that ``log_rmse`` is the RMS of (SPEC 5):
  ln(1 + f_fit cos th_l) - ln(1 + f_meas cos th_l), per channel, on a diverging scale whose
  symmetric range comes from the data (99.5th percentile of its magnitude).
"""

from __future__ import annotations

import dataclasses
import io

import numpy as np

from .grid import UBO_PHI_STEP_DEG, UBO_THETA_DEG, ubo_directions, ubo_pairs

EXCLUDED_COLOUR = (1.0, 0.0, 1.0)  # magenta: not a colour of any map used here
CHANNEL_NAMES = {1: ("Y",), 3: ("R", "G", "B")}
CHANNEL_COLOURS = {"R": "tab:red", "G": "tab:green", "B": "tab:blue", "Y": "black"}

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


#: zlib level of the PNGs brdffit's figures write. PIL's default (6) took 120 ms to encode
#: ``brdffit fit``'s fit.png (1428 x 962), level 3 takes 52 ms for a 9 % larger file.
PNG_COMPRESS_LEVEL = 3


def __getattr__(name: str):
    # ``Figure`` (matplotlib's, which every figure here is) is imported with matplotlib when first
    # needed: the data a figure shows is made without matplotlib (``FigureData``).
    if name == "Figure":
        from ._mpl_figure import Figure

        return Figure
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def png_bytes(fig, dpi: float = 90) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _figure(figsize, **kwargs) -> Figure:
    from ._mpl_figure import Figure

    return Figure(figsize=figsize, **kwargs)


def _channel_names(c: int) -> tuple[str, ...]:
    return CHANNEL_NAMES.get(c, tuple(f"channel {k}" for k in range(c)))


def light_label(d: np.ndarray) -> str:
    """"light θ = 60°, φ = 90°" of a world direction towards the light."""
    theta = np.degrees(np.arccos(np.clip(d[2], -1, 1)))
    phi = np.degrees(np.arctan2(d[1], d[0])) % 360.0
    return f"light θ = {theta:.0f}°, φ = {phi:.0f}°" if theta > 0.5 else "light θ = 0° (from the camera)"


# -- values of what is plotted ----------------------------------------------------------------------
def _is_fit(x) -> bool:
    return hasattr(x, "eval") and hasattr(x, "params") and hasattr(x, "model")


def _grid_table(source):
    """(81, 81, C) f_r, (81, 81) mask of the samples a fit uses, (81, 81) cos th_light, label."""
    from .measurement import Measurement

    if isinstance(source, Measurement):
        if source.grid != "ubo81":
            from .errors import UsageError

            raise UsageError(
                f"{source.name}: the 81x81 display needs a UBO-81 measurement (grid={source.grid!r}); "
                "resample it first: brdffit.resample(m)"
            )
        cos_l = np.asarray(source.wi)[:, 2].reshape(81, 81)
        return source.table().astype(np.float64), source.valid_mask().reshape(81, 81), cos_l, source.name
    if _is_fit(source):
        wi, wo = ubo_pairs()
        values = np.asarray(source.eval(wi, wo), np.float64).reshape(81, 81, -1)
        label = f"{source.model_name} fit of {source.data_name}" if source.data_name else source.model_name
        return values, np.ones((81, 81), bool), wi[:, 2].reshape(81, 81), label
    values = np.asarray(source, np.float64)
    if values.ndim == 2:
        values = values[..., None]
    if values.shape[:2] != (81, 81):
        raise ValueError(f"expected a UBO-81 Measurement, a FitResult or an (81, 81, C) table, got shape {values.shape}")
    valid = np.all(np.isfinite(values), axis=-1)
    return values, valid, ubo_directions()[:, 2][:, None].repeat(81, 1), "table"


def log_range(values: np.ndarray, valid: np.ndarray) -> tuple[float, float]:
    """(lo, hi) of the log display, from the data: 1st percentile of the positive valid values and
    the largest valid value."""
    v = np.asarray(values, np.float64)[np.broadcast_to(valid[..., None], values.shape)]
    pos = v[np.isfinite(v) & (v > 0)]
    if pos.size == 0:
        return 1e-3, 1.0
    lo, hi = float(np.percentile(pos, 1)), float(pos.max())
    return lo, max(hi, lo * 1.0001)


def _log_rgb(values: np.ndarray, valid: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(81, 81, 3) display colours: log(f) per channel from [lo, hi] to [0, 1], excluded magenta."""
    v = np.asarray(values, np.float64)
    if v.shape[-1] == 1:
        v = np.repeat(v, 3, axis=-1)
    v = v[..., :3]
    img = (np.log(np.clip(np.nan_to_num(v, nan=lo), lo, hi)) - np.log(lo)) / max(np.log(hi) - np.log(lo), 1e-12)
    img = np.clip(img, 0.0, 1.0)
    img[~valid] = EXCLUDED_COLOUR
    return img


def log_residual(fitted, measured, cos_light):
    """ln(1 + f cos th_l) - ln(1 + f_ref cos th_l): the residual of the ``log`` loss (SPEC 5)."""
    from .fitting.losses import log_residual as _lr

    return np.asarray(_lr(np.asarray(fitted, np.float64), np.asarray(measured, np.float64), cos_light))


def _sym_limit(d: np.ndarray) -> float:
    a = np.abs(d[np.isfinite(d)])
    lim = float(np.percentile(a, 99.5)) if a.size else 0.0
    return lim if lim > 0 else 1e-12


def _sym_norm(d: np.ndarray):
    """A symmetric colour scale that shows the whole error range: linear up to the largest |error|
    when that is within 4x of the 99.5th percentile, otherwise linear up to the percentile and
    logarithmic beyond it (SymLogNorm), so that a few large errors neither vanish off the scale
    nor wash out the rest."""
    import matplotlib.colors

    typical = _sym_limit(d)
    a = np.abs(d[np.isfinite(d)])
    top = max(float(a.max()) if a.size else 0.0, typical)
    if top <= 4.0 * typical:
        return matplotlib.colors.Normalize(vmin=-top, vmax=top)
    return matplotlib.colors.SymLogNorm(linthresh=typical, linscale=1.0, vmin=-top, vmax=top, base=10)


def _ring_ticks(ax, light_axis: bool = True, view_axis: bool = True) -> None:
    """Ticks at the centre of every theta ring of the UBO-81 ordering, lines between rings.
    ``light_axis=False``: no light-ring ticks or label, for a panel right of one that has them
    (the rows are the same lights); ``view_axis=False``: none for the view rings, for a panel above
    one that has them (the same columns). Tick objects and their labels are most of the time a
    figure of 81x81 panels takes to build and draw."""
    counts = [360 // s for s in UBO_PHI_STEP_DEG]
    starts = np.cumsum([0, *counts])
    centres = starts[:-1] + (np.asarray(counts) - 1) / 2
    labels = [f"{t}°" for t in UBO_THETA_DEG]
    if view_axis:
        ax.set_xticks(centres, labels, fontsize=7)
        # The 0 and 15 degree rings' centres are 3.5 samples apart: centred labels run into each other
        first, second = ax.get_xticklabels()[:2]
        first.set_horizontalalignment("right")
        second.set_horizontalalignment("left")
        ax.set_xlabel("view θ ring (φ increases within a ring)", fontsize=8)
    else:
        ax.set_xticks([])
    if light_axis:
        ax.set_yticks(centres, labels, fontsize=7)
        ax.set_ylabel("light θ ring", fontsize=8)
    else:
        ax.set_yticks([])
    # Two line collections per panel, not a line artist per ring boundary (50 in the fit figure);
    # the limits stay the image's.
    edges = starts[1:-1] - 0.5
    end = starts[-1] - 0.5
    ax.hlines(edges, -0.5, end, color="white", lw=0.4, alpha=0.6)
    ax.vlines(edges, -0.5, end, color="white", lw=0.4, alpha=0.6)
    ax.set_xlim(-0.5, end)
    ax.set_ylim(end, -0.5)


def _excluded_legend(ax, n: int, below_view_axis: bool = True) -> None:
    """The count of excluded samples, under the panel (and under its view-ring labels if it has them)."""
    from matplotlib.patches import Patch

    if n:
        ax.legend(handles=[Patch(color=EXCLUDED_COLOUR, label=f"excluded samples ({n})")], loc="upper center",
                  bbox_to_anchor=(0.5, -0.16 if below_view_axis else -0.01), fontsize=7, frameon=False)


def _log_colourbar(fig, lo: float, hi: float, label: str, **where):
    """The grey log-scale bar of the 81x81 displays; ``where``: ``ax=`` (room taken from those
    axes) or ``cax=`` (an axes of its own)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import StrMethodFormatter

    if "ax" in where:
        where.update(fraction=0.046, pad=0.03)
    cb = fig.colorbar(ScalarMappable(LogNorm(lo, hi), cmap="gray"), **where)
    # Decades as plain numbers (0.01, 0.1, 1): the default 10^k labels go through mathtext, whose
    # parser costs ~40 ms to build in every process that draws them.
    cb.ax.yaxis.set_major_formatter(StrMethodFormatter("{x:g}"))
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)
    return cb


# -- 81x81 displays ----------------------------------------------------------------------------------
def table(measurement_or_fit, *, title: str | None = None) -> Figure:
    """The 81x81 display of a UBO-81 measurement, a FitResult (evaluated on the grid) or an
    (81, 81, C) array: f_r per channel on a log scale (range from the data), excluded samples
    in magenta."""
    values, valid, _, label = _grid_table(measurement_or_fit)
    lo, hi = log_range(values, valid)
    fig = _figure((6.6, 6.0), layout="constrained")
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
    return FigureData("compare_table", _compare_table_content(measurement, fit, title)).draw()


def _compare_table_content(measurement, fit, title: str | None) -> dict:
    """What :func:`compare_table` shows, as arrays and text (the fit evaluated, the residual)."""
    ref, valid, cos_l, ref_label = _grid_table(measurement)
    summary = None
    if _is_fit(fit):
        from .measurement import Measurement

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
    fig = _figure((bars_x + _BAR_W + _BAR_LABEL, _X_AXIS + row + under_top + row + _SUPTITLE))
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
    from .fitting.losses import masked_log_residual
    from .fitting.program import compiled

    args = tuple(np.asarray(a, np.float64) for a in (fitted, ref, cos_l, used))
    program, _ = compiled(("masked_log_residual",), lambda: masked_log_residual, *args)
    residual, lrmse = program(*args)
    return np.array(residual), float(lrmse)


def _diverging():
    import matplotlib

    return matplotlib.colormaps["RdBu_r"].with_extremes(bad=EXCLUDED_COLOUR)


def scatter(measurement, fit, *, title: str | None = None) -> Figure:
    """Fitted against measured f_r per channel (R, G, B), log axes: for scattered samples."""
    return FigureData("scatter", _scatter_content(measurement, fit, title)).draw()


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
    fig = _figure((6.5, 6.0), layout="constrained")
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


# -- polar slices ------------------------------------------------------------------------------------
def _plane_directions(theta_signed: np.ndarray, phi_plane: float) -> np.ndarray:
    """Unit directions at signed polar angle s in the vertical plane of azimuth phi_plane (s > 0
    towards phi_plane, s < 0 towards phi_plane + 180 degrees)."""
    s = np.asarray(theta_signed, np.float64)
    return np.stack([np.sin(s) * np.cos(phi_plane), np.sin(s) * np.sin(phi_plane), np.cos(s)], -1)


def slices(measurement=None, fit=None, *, theta_light: float = np.radians(45.0), phi_light: float = 0.0,
           tolerance_deg: float = 1.0) -> Figure:
    """In-plane and cross-plane polar lobes of f_r (1/sr) per channel for one light direction.

    ``theta_light``, ``phi_light``: radians (SPEC 1). The light is the measured incident direction
    nearest to the one asked for. Row 1, the plane of incidence: the signed view angle is positive
    on the mirror side. Row 2, the plane through the normal perpendicular to it: positive towards
    phi_light + 90 degrees. Measured samples within ``tolerance_deg`` of a plane are dots; the fit is
    the curve. Either of ``measurement`` and ``fit`` may be None.
    """
    from matplotlib.ticker import MaxNLocator

    from .errors import UsageError

    if measurement is None and fit is None:
        raise UsageError("slices needs a measurement, a fit, or both")
    if not (0.0 <= float(theta_light) < np.pi / 2):
        raise UsageError(f"theta_light must be in radians in [0, pi/2), got {theta_light!r}"
                         + (" (degrees? use np.radians)" if float(theta_light) >= np.pi / 2 else ""))
    asked = np.array([np.sin(theta_light) * np.cos(phi_light), np.sin(theta_light) * np.sin(phi_light),
                      np.cos(theta_light)])
    light = asked
    dots = {}
    if measurement is not None:
        wi = np.asarray(measurement.wi, np.float64)
        wo = np.asarray(measurement.wo, np.float64)
        values = np.asarray(measurement.values, np.float64)
        ok = measurement.valid_mask()
        ang = np.arccos(np.clip(wi @ asked, -1, 1))
        ang[~ok] = np.inf
        best = float(ang.min())
        near = ok & (ang <= best + np.radians(0.5))
        light = wi[near].mean(axis=0)
        light /= np.linalg.norm(light)
        theta_v = np.arccos(np.clip(wo[near, 2], -1, 1))
        dphi = np.arctan2(wo[near, 1], wo[near, 0]) - phi_light
        tol = np.sin(np.radians(tolerance_deg))
        pole = theta_v < np.radians(tolerance_deg)
        in_plane = pole | (np.abs(np.sin(dphi)) < tol)
        cross = pole | (np.abs(np.cos(dphi)) < tol)
        dots["in-plane"] = (np.where(np.cos(dphi[in_plane]) < 0, 1, -1) * theta_v[in_plane], values[near][in_plane])
        dots["cross-plane"] = (np.where(np.sin(dphi[cross]) >= 0, 1, -1) * theta_v[cross], values[near][cross])
    channels = measurement.n_channels if measurement is not None else fit.channels
    names = _channel_names(channels)
    s = np.radians(np.linspace(-89.5, 89.5, 359))
    curves = {}
    if fit is not None:
        for plane, phi_p in (("in-plane", phi_light + np.pi), ("cross-plane", phi_light + np.pi / 2)):
            wo = _plane_directions(s, phi_p)
            curves[plane] = np.asarray(fit.eval(np.repeat(light[None], len(s), 0), wo), np.float64)
    theta_l_deg = np.degrees(np.arccos(np.clip(light[2], -1, 1)))
    fig = _figure((3.4 * len(names) + 0.6, 6.4), layout="constrained")
    for row, plane in enumerate(("in-plane", "cross-plane")):
        for c, name in enumerate(names):
            ax = fig.add_subplot(2, len(names), row * len(names) + c + 1, projection="polar")
            ax.set_theta_zero_location("N")
            ax.set_theta_direction(-1)
            ax.set_thetamin(-90)
            ax.set_thetamax(90)
            colour = CHANNEL_COLOURS.get(name, "black")
            top = 0.0
            if plane in curves:
                ax.plot(s, curves[plane][:, c], color=colour, lw=1.4, label="fit")
                top = max(top, float(np.nanmax(curves[plane][:, c])))
            if plane in dots and dots[plane][0].size:
                ax.plot(dots[plane][0], dots[plane][1][:, c], "o", ms=3.5, mfc="white", mec=colour, label="measured")
                top = max(top, float(np.nanmax(dots[plane][1][:, c])))
            if row == 0:
                ax.plot([-np.radians(theta_l_deg)] * 2, [0, top * 1.05 or 1], color="goldenrod", lw=1, ls=":",
                        label="light")
            ax.set_ylim(0, top * 1.05 if top > 0 else 1)
            ax.yaxis.set_major_locator(MaxNLocator(4))
            ax.tick_params(labelsize=7)
            ax.set_title(f"{name}, {plane}", fontsize=9)
            if row == 0 and c == len(names) - 1:
                ax.legend(fontsize=7, loc="upper right", bbox_to_anchor=(1.25, 1.1))
    what = " vs ".join(x for x in (getattr(measurement, "name", None), getattr(fit, "model_name", None)) if x)
    fig.suptitle(f"{what}: f_r (1/sr) against view θ, light θ = {theta_l_deg:.1f}°, φ = {np.degrees(phi_light):.0f}° "
                 "(in-plane: + on the mirror side)", fontsize=9)
    return fig


# -- sphere renders ----------------------------------------------------------------------------------
def spheres(images, lights=None, *, titles=None, exposure: float | None = None) -> Figure:
    """Tone-mapped renders side by side, (L, H, W, 3) linear radiance, or a Validation (reference
    and fit rows). One exposure for all (from the first row): brightness compares across lights."""
    from .render.metrics import exposure as _exposure
    from .render.metrics import tonemap

    rows: list[tuple[str, np.ndarray]]
    if hasattr(images, "reference") and hasattr(images, "fit") and hasattr(images, "lights"):
        lights = images.lights if lights is None else lights
        rows = [("reference", np.asarray(images.reference)), ("fit", np.asarray(images.fit))]
    else:
        imgs = np.asarray(images, np.float64)
        if imgs.ndim == 3:
            imgs = imgs[None]
        rows = [("", imgs)]
    n = rows[0][1].shape[0]
    scale = exposure if exposure is not None else _exposure(rows[0][1])
    fig = _figure((2.6 * n + 0.4, 2.8 * len(rows) + 0.3), layout="constrained")
    axes = fig.subplots(len(rows), n, squeeze=False)
    from .render.scene import light_directions

    dirs = light_directions(lights) if lights is not None else None
    for r, (name, imgs) in enumerate(rows):
        for k in range(n):
            ax = axes[r, k]
            ax.imshow(tonemap(imgs[k], scale), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            label = titles[k] if titles is not None else (light_label(dirs[k]) if dirs is not None else f"image {k}")
            if r == 0:
                ax.set_title(label, fontsize=8)
            if k == 0 and name:
                ax.set_ylabel(name, fontsize=9)
    return fig


def sphere_panel(reference, fit, light, *, metrics: dict | None = None, scale: float | None = None,
                 ref_label: str = "reference", fit_label: str = "fit", irradiance: float = 1.0) -> Figure:
    """One light of a validation: reference | fit (one exposure, from the reference) and the
    signed radiance difference fit − reference per channel (R, G, B: a colour error is seen, not
    only a luminance error), symmetric range from the data, one colour bar."""
    from .render.metrics import exposure, tonemap

    ref = np.asarray(reference, np.float64)
    tst = np.asarray(fit, np.float64)
    scale = exposure(ref) if scale is None else scale
    size = ref.shape[0]
    d = tst - ref
    norm = _sym_norm(d)
    fig = _figure((15.5, 3.6), layout="constrained")
    axes = fig.subplots(1, 5)
    axes[0].imshow(tonemap(ref, scale), interpolation="nearest")
    axes[0].set_title(f"reference: {ref_label}", fontsize=9)
    axes[1].imshow(tonemap(tst, scale), interpolation="nearest")
    axes[1].set_title(f"fit: {fit_label}", fontsize=9)
    t = np.linspace(0, 2 * np.pi, 256)
    c0 = (size - 1) / 2
    light = np.asarray(light, np.float64)
    for c, name in enumerate(("R", "G", "B")):
        ax = axes[2 + c]
        im = ax.imshow(d[..., c], cmap="RdBu_r", norm=norm, interpolation="nearest")
        ax.set_title(f"{name}: fit − reference", fontsize=9)
        ax.plot(c0 + size / 2 * np.cos(t), c0 + size / 2 * np.sin(t), color="0.6", lw=0.6)
        # where the light direction projects onto the image (the normal facing the light)
        ax.plot([(light[0] + 1) * size / 2 - 0.5], [(1 - light[1]) * size / 2 - 0.5], "o", ms=6, mfc="gold",
                mec="black", mew=0.8)
        ax.set_xlim(-0.5, size - 0.5)
        ax.set_ylim(size - 0.5, -0.5)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    cb = fig.colorbar(im, ax=list(axes[2:]), fraction=0.03, pad=0.02)
    cb.set_label(f"radiance difference (irradiance {irradiance:g})\nred: fit too bright", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    text = light_label(light) + "   (gold dot: light direction, projected)"
    if metrics:
        text += (f"   RMSE {metrics['rmse']:.3g}   rel. RMSE {metrics['relative_rmse']:.3g}   "
                 f"PSNR {metrics['psnr']:.1f} dB   FLIP {metrics['flip']:.3f}")
    fig.suptitle(text, fontsize=10)
    return fig


# -- error against run time --------------------------------------------------------------------------
def pareto(report, metric: str = "loss_log") -> Figure:
    """Error (``metric``) against run time, log axes: colour = model, marker = solver; the rows of
    ``report.pareto(metric)`` are labelled and joined (ties keep the fastest, SPEC 5)."""
    import matplotlib
    from matplotlib.lines import Line2D

    rows = [r for r in report.rows if r[metric] > 0 and r["run_s"] > 0]
    front = [r for r in report.pareto(metric) if r in rows]
    fig = _figure((9, 6.5), layout="constrained")
    ax = fig.add_subplot()
    solvers = sorted({r["solver"] for r in rows})
    markers = dict(zip(solvers, "osD^v<>p*hX"))
    models = sorted({r["model"] for r in rows})
    cmap = matplotlib.colormaps["tab20" if len(models) > 10 else "tab10"]
    colours = {m: cmap(i % cmap.N) for i, m in enumerate(models)}
    for r in rows:
        ax.scatter(r["run_s"], r[metric], marker=markers[r["solver"]], color=colours[r["model"]], s=46,
                   edgecolors="black" if r["converged"] else "red", linewidths=0.6 if r["converged"] else 1.6,
                   zorder=3)
    several_losses = len({x["loss"] for x in rows}) > 1
    for i, r in enumerate(front):
        label = f"{r['model']} / {r['solver']}" + (f" / {r['loss']}" if several_losses else "")
        ax.annotate(label, (r["run_s"], r[metric]), fontsize=7.5, xytext=(6, 6 if i % 2 else -10),
                    textcoords="offset points", bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
    if len(front) > 1:
        ax.plot([r["run_s"] for r in front], [r[metric] for r in front], "k--", lw=0.8, zorder=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("run time (s, after compilation)")
    ax.set_ylabel(f"{metric.replace('loss_', '')} loss on the measurement")
    ax.set_title(f"error against run time: {report.data_name}")
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], marker=markers[s], ls="", color="grey", label=f"solver {s}") for s in solvers]
    handles += [Line2D([], [], marker="s", ls="", color=colours[m], label=m) for m in models]
    handles.append(Line2D([], [], marker="o", ls="", mfc="white", mec="red", mew=1.6, label="not converged"))
    handles.append(Line2D([], [], ls="--", color="k", label="Pareto front (labelled)"))
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return fig


# -- scene-aware fitting (SPEC 12) -----------------------------------------------------------------
def _usage_density(fig, ax, x, y, weight, labels: tuple[str, str], title: str) -> None:
    """A weighted 2-D histogram of two angles in degrees (0..90, 2-degree bins), relative to its
    maximum, on a log colour scale from 1e-3."""
    from matplotlib.colors import LogNorm

    bins = np.linspace(0, 90, 46)
    h, _, _ = np.histogram2d(x, y, bins=(bins, bins), weights=weight)
    h = h / h.max() if h.max() > 0 else h
    im = ax.imshow(h.T, origin="lower", extent=(0, 90, 0, 90), norm=LogNorm(1e-3, 1.0), cmap="viridis",
                   interpolation="nearest")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, fraction=0.046, label="relative contribution")


def usage(usage, measurement=None, *, bandwidth_deg: float = 5.0, floor: float = 1e-2):
    """Where a scene looks at its material (``usage`` from ``brdffit.scene_usage``).

    Left: the weights ``usage.weights`` gives the UBO-81 table (``measurement`` when given,
    else the UBO-81 pairs), light rows by view columns like the 81x81 display, log scale.
    Middle: the recorded contribution as a density over (theta_h, theta_d). Right: over
    (theta_light, theta_view).
    """
    from matplotlib.colors import LogNorm

    from .grid import ubo_pairs

    if measurement is None:
        from .measurement import Measurement

        wi, wo = ubo_pairs()
        measurement = Measurement(wi, wo, np.zeros((wi.shape[0], 1)), name="UBO-81", grid="ubo81")
    w = usage.weights(measurement, bandwidth_deg=bandwidth_deg, floor=floor)
    fig = _figure((14.0, 4.4), layout="constrained")
    axes = fig.subplots(1, 3)
    if measurement.grid == "ubo81":
        im = axes[0].imshow(w.reshape(81, 81), norm=LogNorm(max(floor, 1e-4), 1.0), cmap="magma", interpolation="nearest")
        axes[0].set_xlabel("view index")
        axes[0].set_ylabel("light index")
        axes[0].set_title(f"fit weights on {measurement.name} (floor {floor:g})", fontsize=10)
    else:
        deg = np.degrees(np.arccos(np.clip([np.asarray(measurement.wi)[:, 2], np.asarray(measurement.wo)[:, 2]], -1, 1)))
        im = axes[0].scatter(deg[0], deg[1], c=w, s=6, cmap="magma", norm=LogNorm(max(floor, 1e-4), 1.0))
        axes[0].set_xlabel("θ light [°]")
        axes[0].set_ylabel("θ view [°]")
        axes[0].set_title(f"fit weights on {measurement.name}", fontsize=10)
    fig.colorbar(im, ax=axes[0], fraction=0.046, label="weight")

    c = np.degrees(usage.coordinates())
    _usage_density(fig, axes[1], c[:, 0], c[:, 1], usage.weight, ("θ_h [°]", "θ_d [°]"),
                   "contribution to the image over (θ_h, θ_d)")
    ti = np.degrees(np.arccos(np.clip(usage.wi[:, 2], -1, 1)))
    to = np.degrees(np.arccos(np.clip(usage.wo[:, 2], -1, 1)))
    _usage_density(fig, axes[2], ti, to, usage.weight, ("θ light [°]", "θ view [°]"), "… over (θ light, θ view)")
    fig.suptitle(f"where {usage.material!r} is seen in {usage.scene}: {len(usage)} pairs, "
                 f"{usage.pixels[0]}x{usage.pixels[1]} px, {usage.spp} spp", fontsize=11)
    return fig


# -- BTF -----------------------------------------------------------------------------------------------
def _p99(a) -> float:
    v = float(np.percentile(np.asarray(a, np.float64), 99))
    return v if v > 0 else 1.0


def _range(a) -> tuple[float, float]:
    lo, hi = (float(x) for x in np.percentile(np.asarray(a, np.float64), [1, 99]))
    return (lo, hi if hi > lo else lo + 1e-12)


def _rgb_preview(a) -> np.ndarray:
    from .io.images import linear_to_srgb

    return linear_to_srgb(np.asarray(a, np.float64) / _p99(a))


def map_preview_png(a: np.ndarray, path) -> None:
    """One parameter map (H, W, 1 or 3) as a PNG of its own pixels, scaled as in
    :func:`parameter_maps` (``ParameterMaps.save`` writes these previews)."""
    import matplotlib.image

    if a.shape[-1] == 3:
        matplotlib.image.imsave(path, _rgb_preview(a), format="png")
    else:
        lo, hi = _range(a[..., 0])
        matplotlib.image.imsave(path, a[..., 0], cmap="viridis", vmin=lo, vmax=hi, format="png")


def parameter_maps(maps) -> Figure:
    """The maps of a ``ParameterMaps`` (``fit_btf``): RGB parameters as sRGB previews scaled by
    their 99th percentile, scalar ones on viridis between their 1st and 99th percentiles (the
    scaling of the preview PNGs ``ParameterMaps.save`` writes: :func:`map_preview_png`)."""
    arrays = maps.maps()
    cols = min(len(arrays), 4)
    rows = -(-len(arrays) // cols)
    fig = _figure((3.2 * cols, 3.0 * rows), dpi=90)
    for i, (name, a) in enumerate(arrays.items()):
        ax = fig.add_subplot(rows, cols, i + 1)
        if a.shape[-1] == 3:
            ax.imshow(_rgb_preview(a), interpolation="nearest")
            ax.set_title(f"{name} (RGB, /{_p99(a):.3g})", fontsize=9)
        else:
            lo, hi = _range(a[..., 0])
            im = ax.imshow(a[..., 0], cmap="viridis", vmin=lo, vmax=hi, interpolation="nearest")
            fig.colorbar(im, ax=ax, fraction=0.046)
            ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{maps.model}: {maps.shape[0]} x {maps.shape[1]} texels, "
                 f"{int(maps.converged.sum())} converged", fontsize=10)
    return fig


def btf_panel(photos, renders, names, metrics) -> Figure:
    """One row per (light, view) pair of a BTF validation: the photograph, the render of the
    parameter maps (one exposure, the photograph's) and |error| relative to the exposure level,
    with the pair's PSNR and FLIP."""
    from .render.metrics import exposure, tonemap

    n = len(names)
    fig = _figure((9.5, 3.0 * n), dpi=90)
    for k in range(n):
        scale = exposure(photos[k])
        err = np.abs(np.asarray(renders[k], np.float64) - photos[k]).mean(axis=-1)
        ref_level = 1.0 / scale
        for j, (img, title) in enumerate(((tonemap(photos[k], scale), "BTF photograph"),
                                          (tonemap(renders[k], scale), "render of the maps"))):
            ax = fig.add_subplot(n, 3, 3 * k + j + 1)
            ax.imshow(img, interpolation="nearest")
            ax.set_title(f"{title}\n{names[k]}", fontsize=8)
            ax.axis("off")
        ax = fig.add_subplot(n, 3, 3 * k + 3)
        im = ax.imshow(err / ref_level, cmap="magma", vmin=0, vmax=max(float(np.percentile(err / ref_level, 99)), 1e-6),
                       interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.046)
        m = metrics[k]
        ax.set_title(f"|error| / exposure level\npsnr {m['psnr']:.1f} dB, flip {m['flip']:.3f}", fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    return fig


def scene_panel(reference: np.ndarray, fit: np.ndarray, flip_map: np.ndarray, scale: float, metrics: dict):
    """Scene rendered with the reference | with the fit | FLIP error map, one exposure for both."""
    from .render.metrics import tonemap

    h, w = reference.shape[:2]
    fig = _figure((3 * 4.0 * w / max(h, w) + 1.0, 4.0 * h / max(h, w) + 0.9), layout="constrained")
    axes = fig.subplots(1, 3)
    axes[0].imshow(tonemap(reference, scale), interpolation="nearest")
    axes[0].set_title(f"reference: {metrics['reference']}", fontsize=9)
    axes[1].imshow(tonemap(fit, scale), interpolation="nearest")
    axes[1].set_title(f"fit: {metrics['fit']}", fontsize=9)
    im = axes[2].imshow(flip_map, cmap="magma", vmin=0, vmax=1, interpolation="nearest")
    axes[2].set_title("FLIP error", fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[2], fraction=0.046)
    o = metrics["image"]
    fig.suptitle(f"{metrics['material']!r} in {metrics['scene']}: RMSE {o['rmse']:.3g}, rel. RMSE "
                 f"{o['relative_rmse']:.3g}, PSNR {o['psnr']:.1f} dB, FLIP {o['flip']:.3f}", fontsize=10)
    return fig
