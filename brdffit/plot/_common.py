"""What the figures of :mod:`brdffit.plot` share: the values shown (a table from a measurement, a
fit or an array; log ranges; the log residual), the 81x81 display's ticks, legend and colour bar,
the diverging error scale, and :func:`new_figure`. Matplotlib is imported inside the functions that
draw, never here (``import brdffit.plot`` stays light)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..grid import UBO_PHI_STEP_DEG, UBO_THETA_DEG, ubo_directions, ubo_pairs
from .style import EXCLUDED_COLOUR

if TYPE_CHECKING:
    from ._figure import Figure


def new_figure(figsize, **kwargs) -> Figure:
    """A :class:`~brdffit.plot.Figure` (matplotlib is imported here, on the first figure drawn)."""
    from ._figure import Figure

    return Figure(figsize=figsize, **kwargs)


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
    from ..measurement import Measurement

    if isinstance(source, Measurement):
        if source.grid != "ubo81":
            from ..errors import UsageError

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
    """ln(1 + f cos th_l) - ln(1 + f_ref cos th_l): the residual of the ``log`` loss (docs/fitting.md#fitting)."""
    from ..fitting.losses import log_residual as _lr

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


def ring_starts() -> np.ndarray:
    """Index of the first direction of every theta ring of the UBO-81 ordering, and 81 at the end."""
    return np.cumsum([0, *(360 // s for s in UBO_PHI_STEP_DEG)])


def _ring_ticks(ax, light_axis: bool = True, view_axis: bool = True) -> None:
    """Ticks at the centre of every theta ring of the UBO-81 ordering, lines between rings.
    ``light_axis=False``: no light-ring ticks or label, for a panel right of one that has them
    (the rows are the same lights); ``view_axis=False``: none for the view rings, for a panel above
    one that has them (the same columns). Tick objects and their labels are most of the time a
    figure of 81x81 panels takes to build and draw."""
    counts = [360 // s for s in UBO_PHI_STEP_DEG]
    starts = ring_starts()
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


def _diverging():
    import matplotlib

    return matplotlib.colormaps["RdBu_r"].with_extremes(bad=EXCLUDED_COLOUR)
