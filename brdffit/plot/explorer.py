"""The explorer's view (:func:`brdffit.explore`): what it shows, as arrays and text
(:class:`ExplorerView`); its images for the widget (:class:`LiveImages`, made fast enough to follow
a slider); and the same view as one static figure (:func:`explorer`).

The live images are the static figure's parts without matplotlib's layout on every change: the
81x81 tables and the log residual are coloured arrays (the colours of :func:`compare_table`,
enlarged with the theta rings drawn in), the spheres are tone-mapped renders, and the polar slices
are drawn by matplotlib once per light (axes, measured dots) with only the fitted curves redrawn
on a parameter change (blitting). Each is written as a PNG at :data:`LIVE_PNG_LEVEL`.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import time
from typing import TYPE_CHECKING

import numpy as np

from ._common import _diverging, _log_rgb, _ring_ticks, _sym_norm, log_range, new_figure, ring_starts
from .polar import SliceGeometry, draw_slice_panels, panel_tops, set_slice_geometry, slices_title
from .style import channel_names
from .tables import _residual_and_log_rmse

if TYPE_CHECKING:
    from ._figure import Figure

#: zlib level of the live images: 1 writes the 576 x 264 slices image in about 3 ms on this machine
#: (level 3, the figures' level, in about 5 ms; the images are shown, not kept).
LIVE_PNG_LEVEL = 1
#: Pixels per table entry in the live 81x81 images (the browser shows them at this size).
TABLE_ZOOM = 3
RESIDUAL_ZOOM = 2
#: Headroom of the live slices' radial axes over the measured dots: a fitted curve above it is cut
#: at the rim until the light changes (the axes are drawn once per light).
LIVE_HEADROOM = 1.25


@dataclasses.dataclass(frozen=True, eq=False)
class ExplorerView:
    """What the explorer shows for one model, parameter set, light and exposure."""

    measured: np.ndarray  # (81, 81, C) measured f_r (1/sr)
    valid: np.ndarray  # (81, 81) the samples a fit uses
    cos_light: np.ndarray  # (81, 81) cos theta of each sample's light
    fitted: np.ndarray  # (81, 81, C) the model at ``params``
    light_row: int  # the table row of the light the slices use (the measured light nearest to ``light``)
    light: tuple[float, float]  # (theta, phi) in degrees, as asked for
    geometry: SliceGeometry  # the slices at that light
    curves: dict  # plane -> (S, C) the model along the slices
    sphere_measured: np.ndarray  # (H, W, 3) linear radiance of the measured sphere
    sphere_fit: np.ndarray  # (H, W, 3) of the model's sphere
    sphere_kind: str  # "preview" (from the model and the table) or "Mitsuba" (rendered)
    scale: float  # the exposure both spheres are shown at
    data_name: str
    model_name: str
    params: dict  # name -> (size,) values
    loss_name: str
    metrics: dict  # the loss under its name, "rmse", "log_rmse", "rel_rmse"
    status: str  # where the parameters come from: a fit's status, or "set by hand"
    warnings: tuple[str, ...] = ()

    @functools.cached_property
    def residual(self) -> np.ndarray:
        """(81, 81, C) the log residual of :func:`compare_table` (fitted against measured), NaN where
        a sample is not used or the model is not finite."""
        valid = self.valid & np.all(np.isfinite(self.fitted), axis=-1)
        residual, _ = _residual_and_log_rmse(self.fitted, self.measured, self.cos_light[..., None], valid[..., None])
        residual[~valid] = np.nan
        return residual


# -- images as arrays ---------------------------------------------------------------------------------
def _enlarged(rgb: np.ndarray, zoom: int) -> np.ndarray:
    """(81, 81, 3) colours in [0, 1] -> (81 zoom, 81 zoom, 3) uint8 with the theta rings' borders
    drawn in a light line, as on the figures' 81x81 displays."""
    img = np.repeat(np.repeat(np.asarray(rgb, np.float64), zoom, 0), zoom, 1)
    for edge in ring_starts()[1:-1] * zoom:
        img[edge, :] = 0.4 * img[edge, :] + 0.6
        img[:, edge] = 0.4 * img[:, edge] + 0.6
    return np.round(np.clip(img, 0.0, 1.0) * 255).astype(np.uint8)


def table_rgb(values: np.ndarray, valid: np.ndarray, lo: float, hi: float, zoom: int = TABLE_ZOOM) -> np.ndarray:
    """An 81x81 table in the colours of :func:`table` (log scale [lo, hi], excluded magenta)."""
    return _enlarged(_log_rgb(values, valid, lo, hi), zoom)


def residual_rgb(residual: np.ndarray, zoom: int = RESIDUAL_ZOOM, gap: int = 6) -> np.ndarray:
    """The log residual per channel, side by side, in the colours of :func:`compare_table`
    (symmetric scale from the data, excluded samples magenta)."""
    norm = _sym_norm(residual)
    cmap = _diverging()
    panels = [_enlarged(cmap(norm(residual[..., c]))[..., :3], zoom) for c in range(residual.shape[-1])]
    space = np.full((panels[0].shape[0], gap, 3), 255, np.uint8)
    return np.concatenate([p for panel in panels for p in (panel, space)][:-1], axis=1)


def sphere_rgb(radiance: np.ndarray, scale: float) -> np.ndarray:
    """A sphere render tone-mapped as the validation panels are (``brdffit.render.metrics.tonemap``)."""
    from ..render.metrics import tonemap

    return np.round(tonemap(radiance, scale) * 255).astype(np.uint8)


def rgb_png(rgb: np.ndarray, level: int = LIVE_PNG_LEVEL) -> bytes:
    """(H, W, 3) uint8 -> PNG bytes."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(buf, format="PNG", compress_level=level)
    return buf.getvalue()


# -- the live images ----------------------------------------------------------------------------------
class _LiveSlices:
    """The slices on a figure kept between changes: axes, grid and measured dots are drawn once per
    light (the background), the fitted curves over a copy of it on each change of parameters."""

    def __init__(self, geometry: SliceGeometry, curves: dict, channels: int):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        self.channels = channels
        names = channel_names(channels)
        # fixed margins (a constrained layout took a third of a change of light), axes made once
        self.figure = new_figure((2.5 * len(names) + 0.4, 3.0), dpi=80)
        self.figure.subplots_adjust(left=0.04, right=0.98, bottom=0.02, top=0.9, wspace=0.2, hspace=0.3)
        self.canvas = FigureCanvasAgg(self.figure)
        self.panels = draw_slice_panels(self.figure, geometry, None, names, self._tops(geometry, curves),
                                        animated=True, legend=False, fontsize=8, radial_ticks=2)
        self._background(geometry)

    def _tops(self, geometry: SliceGeometry, curves: dict) -> dict:
        tops = panel_tops(geometry, None if geometry.dots else curves, self.channels)
        return {k: v * LIVE_HEADROOM for k, v in tops.items()}

    def _background(self, geometry: SliceGeometry) -> None:
        self.geometry = geometry
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def rgb(self, geometry: SliceGeometry, curves: dict) -> np.ndarray:
        if geometry is not self.geometry:
            set_slice_geometry(self.panels, geometry, self._tops(geometry, curves))
            self._background(geometry)
        self.canvas.restore_region(self.background)
        for (plane, c), panel in self.panels.items():
            panel.curve.set_ydata(curves[plane][:, c])
            panel.ax.draw_artist(panel.curve)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


class LiveImages:
    """The explorer's images of one measurement, as PNG bytes by name: "measured", "fitted",
    "log_ratio", "slices", "sphere_measured", "sphere_fit". What depends only on the measurement,
    the light or the exposure is made once and kept."""

    def __init__(self, measured: np.ndarray, valid: np.ndarray):
        self.lo, self.hi = log_range(measured, valid)
        self.measured_png = rgb_png(table_rgb(measured, valid, self.lo, self.hi))
        self._slices: _LiveSlices | None = None
        self._sphere: tuple | None = None  # (radiance, scale, PNG) of the measured sphere
        self.seconds: dict[str, float] = {}

    def images(self, view: ExplorerView) -> dict[str, bytes]:
        """The images of ``view``; :attr:`seconds` then holds what each took (made and encoded)."""
        if self._slices is None:
            self._slices = _LiveSlices(view.geometry, view.curves, view.measured.shape[-1])
        if self._sphere is None or self._sphere[0] is not view.sphere_measured or self._sphere[1] != view.scale:
            self._sphere = (view.sphere_measured, view.scale, rgb_png(sphere_rgb(view.sphere_measured, view.scale)))
        makers = {
            "measured": lambda: self.measured_png,
            "fitted": lambda: rgb_png(table_rgb(view.fitted, view.valid, self.lo, self.hi)),
            "log_ratio": lambda: rgb_png(residual_rgb(view.residual)),
            "slices": lambda: rgb_png(self._slices.rgb(view.geometry, view.curves)),
            "sphere_measured": lambda: self._sphere[2],
            "sphere_fit": lambda: rgb_png(sphere_rgb(view.sphere_fit, view.scale)),
        }
        out, self.seconds = {}, {}
        for name, make in makers.items():
            t = time.perf_counter()
            out[name] = make()
            self.seconds[name] = time.perf_counter() - t
        return out


# -- the static figure ------------------------------------------------------------------------------
def view_summary(view: ExplorerView) -> str:
    """The view's numbers as text: model, loss, rel_rmse, the parameters, the warnings."""
    lines = [f"{view.model_name} on {view.data_name}: {view.status}",
             f"{view.loss_name} loss {view.metrics[view.loss_name]:.4g}   rel_rmse {view.metrics['rel_rmse']:.4g}   "
             f"log_rmse {view.metrics['log_rmse']:.4g}"]
    width = max(len(k) for k in view.params)
    for name, value in view.params.items():
        lines.append(f"{name:<{width}}  " + " ".join(f"{x:.4g}" for x in np.asarray(value, np.float64).reshape(-1)))
    lines += [f"warning: {w}" for w in view.warnings]
    return "\n".join(lines)


def explorer(view: ExplorerView) -> Figure:
    """The explorer's view as one figure: measured | fitted table (one log scale, from the measured
    data), the spheres (measured | model, one exposure), the log residual per channel, the numbers,
    and the polar slices at the light (``Explorer.figure()``, and its ``_repr_png_`` where no
    widget front end runs)."""
    import textwrap

    channels = view.measured.shape[-1]
    names = channel_names(channels)
    fig = new_figure((2.6 * max(channels, 2) + 4.4, 10.6), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=(1.3, 1.0))
    axes = top.subplots(2, 4)
    marker = dict(marker=">", ms=7, mfc="gold", mec="black", clip_on=False)
    for ax, values, label in ((axes[0, 0], view.measured, f"measured: {view.data_name}"),
                              (axes[0, 1], view.fitted, f"model: {view.model_name}")):
        lo, hi = log_range(view.measured, view.valid)
        ax.imshow(_log_rgb(values, view.valid, lo, hi), interpolation="nearest")
        _ring_ticks(ax, light_axis=ax is axes[0, 0])
        ax.plot([-0.5], [view.light_row], **marker)
        ax.set_title(label, fontsize=9)
    theta, phi = view.light
    for ax, img, label in ((axes[0, 2], view.sphere_measured, "measured"), (axes[0, 3], view.sphere_fit, "model")):
        ax.imshow(sphere_rgb(img, view.scale), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{label} sphere ({view.sphere_kind})\nlight θ = {theta:.0f}°, φ = {phi:.0f}°", fontsize=9)
    norm = _sym_norm(view.residual)
    for c, name in enumerate(names[:3]):
        ax = axes[1, c]
        im = ax.imshow(view.residual[..., c], cmap=_diverging(), norm=norm, interpolation="nearest")
        _ring_ticks(ax, light_axis=c == 0)
        ax.set_title(f"{name}: log residual (red: model too bright)", fontsize=9)
    for c in range(len(names[:3]), 3):
        axes[1, c].set_axis_off()
    top.colorbar(im, ax=list(axes[1, :3]), fraction=0.02, pad=0.01).ax.tick_params(labelsize=7)
    text = axes[1, 3]
    text.set_axis_off()
    summary = "\n".join(textwrap.fill(line, 44, subsequent_indent="  ") for line in view_summary(view).splitlines())
    text.text(0.0, 1.0, summary, fontsize=7.5, family="monospace", va="top", ha="left", transform=text.transAxes)
    tops = panel_tops(view.geometry, view.curves, channels)
    draw_slice_panels(bottom, view.geometry, view.curves, names, tops, fontsize=8, radial_ticks=3)
    bottom.suptitle(slices_title(view.geometry, f"{view.data_name} vs {view.model_name}"), fontsize=9)
    return fig


__all__ = ["ExplorerView", "LiveImages", "explorer", "rgb_png", "view_summary"]
