"""Polar slices of f_r: :func:`slices` (in-plane and cross-plane lobes per channel)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._common import new_figure
from .style import CHANNEL_COLOURS, channel_names as _channel_names

if TYPE_CHECKING:
    from ._figure import Figure


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

    from ..errors import UsageError

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
    fig = new_figure((3.4 * len(names) + 0.6, 6.4), layout="constrained")
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
