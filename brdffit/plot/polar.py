"""Polar slices of f_r: :func:`slices` (in-plane and cross-plane lobes per channel).

A figure of slices is made of its geometry (:func:`slice_geometry`: the light used, the measured
samples lying in each plane, the view directions of the fitted curves), the fit evaluated along
those curves, and the panels drawn from both (:func:`draw_slice_panels`). The explorer's live view
(:mod:`brdffit.plot.explorer`) draws the same panels once per light and redraws only the curves.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from ._common import new_figure
from .style import CHANNEL_COLOURS, channel_names as _channel_names

if TYPE_CHECKING:
    from ._figure import Figure

PLANES = ("in-plane", "cross-plane")
#: Signed view angles of the fitted curves (radians): every half degree across the hemisphere.
CURVE_ANGLES = np.radians(np.linspace(-89.5, 89.5, 359))


def _plane_directions(theta_signed: np.ndarray, phi_plane: float) -> np.ndarray:
    """Unit directions at signed polar angle s in the vertical plane of azimuth phi_plane (s > 0
    towards phi_plane, s < 0 towards phi_plane + 180 degrees)."""
    s = np.asarray(theta_signed, np.float64)
    return np.stack([np.sin(s) * np.cos(phi_plane), np.sin(s) * np.sin(phi_plane), np.cos(s)], -1)


@dataclasses.dataclass(frozen=True)
class SliceGeometry:
    """Where the slices of one light lie (see :func:`slices` for the planes and signs)."""

    light: np.ndarray  # (3,) the light direction used: the measured one nearest to the one asked for
    phi_light: float  # radians: the azimuth the planes are taken from
    #: plane -> (S, 3) view directions of the fitted curve, at the signed angles CURVE_ANGLES
    views: dict
    #: plane -> (signed view angles (n,), measured f_r (n, C)) of the samples within the tolerance
    dots: dict

    @property
    def theta_light_deg(self) -> float:
        return float(np.degrees(np.arccos(np.clip(self.light[2], -1, 1))))

    def curve_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(wi, wo), (2 S, 3) each: the light against every curve direction, in-plane first."""
        wo = np.concatenate([self.views[p] for p in PLANES])
        return np.broadcast_to(self.light, wo.shape), wo

    def split(self, values: np.ndarray) -> dict:
        """f_r at :meth:`curve_pairs`, (2 S, C) -> plane -> (S, C)."""
        values = np.asarray(values, np.float64)
        n = len(CURVE_ANGLES)
        return {p: values[k * n:(k + 1) * n] for k, p in enumerate(PLANES)}


def slice_geometry(measurement, theta_light: float, phi_light: float = 0.0,
                   tolerance_deg: float = 1.0) -> SliceGeometry:
    """The geometry of :func:`slices` for one light (radians); ``measurement`` may be None (then
    the light is the one asked for and there are no dots)."""
    from ..errors import UsageError

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
    views = {"in-plane": _plane_directions(CURVE_ANGLES, phi_light + np.pi),
             "cross-plane": _plane_directions(CURVE_ANGLES, phi_light + np.pi / 2)}
    return SliceGeometry(light, float(phi_light), views, dots)


def panel_tops(geometry: SliceGeometry, curves: dict | None, channels: int) -> dict:
    """(plane, channel) -> the radial extent of that panel: the largest value shown (dots, curve),
    or 1 where there is none."""
    tops = {}
    for plane in PLANES:
        for c in range(channels):
            top = 0.0
            if curves is not None:
                top = max(top, float(np.nanmax(curves[plane][:, c])))
            if plane in geometry.dots and geometry.dots[plane][0].size:
                top = max(top, float(np.nanmax(geometry.dots[plane][1][:, c])))
            tops[plane, c] = top * 1.05 if top > 0 else 1.0
    return tops


@dataclasses.dataclass(frozen=True)
class SlicePanel:
    """The artists of one polar panel: its axes, the fitted curve, the measured dots and (in the
    in-plane row) the light's direction."""

    ax: Any
    curve: Any
    dots: Any
    light: Any | None


def draw_slice_panels(fig, geometry: SliceGeometry, curves: dict | None, names, tops: dict, *,
                      animated: bool = False, legend: bool = True, fontsize: float = 9, radial_ticks: int = 4) -> dict:
    """The 2 x C polar panels of :func:`slices` on ``fig`` (a Figure or a SubFigure): measured
    dots, the fitted curve (``curves``: plane -> (S, C); None: no curve), the light's direction in
    the in-plane row, radial extent ``tops`` (see :func:`panel_tops`). ``animated=True`` leaves the
    curves out of a full draw, to be drawn by blitting. Returns (plane, channel) -> SlicePanel;
    :func:`set_slice_geometry` moves them to another light."""
    from matplotlib.ticker import MaxNLocator

    out = {}
    for row, plane in enumerate(PLANES):
        for c, name in enumerate(names):
            ax = fig.add_subplot(2, len(names), row * len(names) + c + 1, projection="polar")
            ax.set_theta_zero_location("N")
            ax.set_theta_direction(-1)
            ax.set_thetamin(-90)
            ax.set_thetamax(90)
            colour = CHANNEL_COLOURS.get(name, "black")
            values = curves[plane][:, c] if curves is not None else np.full(len(CURVE_ANGLES), np.nan)
            (curve,) = ax.plot(CURVE_ANGLES, values, color=colour, lw=1.4, animated=animated,
                               label="fit" if curves is not None or animated else "_no fit")
            (dots,) = ax.plot([], [], "o", ms=3.5, mfc="white", mec=colour, label="measured")
            light = ax.plot([], [], color="goldenrod", lw=1, ls=":", label="light")[0] if row == 0 else None
            ax.yaxis.set_major_locator(MaxNLocator(radial_ticks))
            ax.tick_params(labelsize=fontsize - 2)
            ax.set_title(f"{name}, {plane}", fontsize=fontsize)
            out[plane, c] = SlicePanel(ax, curve, dots, light)
    set_slice_geometry(out, geometry, tops)
    if legend:
        out[PLANES[0], len(names) - 1].ax.legend(fontsize=fontsize - 2, loc="upper right", bbox_to_anchor=(1.25, 1.1))
    return out


def set_slice_geometry(panels: dict, geometry: SliceGeometry, tops: dict) -> None:
    """The panels of :func:`draw_slice_panels` at another light: its measured dots, its direction,
    radial extents ``tops``."""
    theta_l = np.radians(geometry.theta_light_deg)
    for (plane, c), panel in panels.items():
        angles, values = geometry.dots.get(plane, (np.zeros(0), np.zeros((0, c + 1))))
        panel.dots.set_data(angles, values[:, c])
        # no dots: no legend entry for them either
        panel.dots.set_label("measured" if angles.size else "_no dots")
        if panel.light is not None:
            panel.light.set_data([-theta_l] * 2, [0, tops[plane, c]])
        panel.ax.set_ylim(0, tops[plane, c])


def slices_title(geometry: SliceGeometry, what: str) -> str:
    return (f"{what}: f_r (1/sr) against view θ, light θ = {geometry.theta_light_deg:.1f}°, "
            f"φ = {np.degrees(geometry.phi_light):.0f}° (in-plane: + on the mirror side)")


def slices(measurement=None, fit=None, *, theta_light: float = np.radians(45.0), phi_light: float = 0.0,
           tolerance_deg: float = 1.0) -> Figure:
    """In-plane and cross-plane polar lobes of f_r (1/sr) per channel for one light direction.

    ``theta_light``, ``phi_light``: radians (docs/conventions.md#conventions). The light is the measured incident direction
    nearest to the one asked for. Row 1, the plane of incidence: the signed view angle is positive
    on the mirror side. Row 2, the plane through the normal perpendicular to it: positive towards
    phi_light + 90 degrees. Measured samples within ``tolerance_deg`` of a plane are dots; the fit is
    the curve. Either of ``measurement`` and ``fit`` may be None.
    """
    from ..errors import UsageError

    if measurement is None and fit is None:
        raise UsageError("slices needs a measurement, a fit, or both")
    geometry = slice_geometry(measurement, theta_light, phi_light, tolerance_deg)
    curves = geometry.split(fit.eval(*geometry.curve_pairs())) if fit is not None else None
    channels = measurement.n_channels if measurement is not None else fit.channels
    names = _channel_names(channels)
    fig = new_figure((3.4 * len(names) + 0.6, 6.4), layout="constrained")
    draw_slice_panels(fig, geometry, curves, names, panel_tops(geometry, curves, channels))
    what = " vs ".join(x for x in (getattr(measurement, "name", None), getattr(fit, "model_name", None)) if x)
    fig.suptitle(slices_title(geometry, what), fontsize=9)
    return fig
