"""PNG panels of a validation: per light (reference | fit | error) and the 81x81 table.

Colour images are tone-mapped with the reference's exposure (:func:`metrics.tonemap`). Error maps
show the signed luminance difference fit - reference on a diverging scale (red: fit too bright,
blue: fit too dark) with symmetric limits, and a colour bar in the units of the data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..grid import UBO_THETA_DEG, ubo_angles_deg
from .metrics import luminance, tonemap


def _figure(figsize):
    """A matplotlib Figure without pyplot: no global figure registry to clean up, and a lighter
    import than ``matplotlib.pyplot``; ``savefig`` renders it with Agg."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize)


def _limit(d: np.ndarray) -> float:
    a = np.abs(d[np.isfinite(d)])
    lim = float(np.percentile(a, 99.5)) if a.size else 0.0
    return lim if lim > 0 else 1e-12


def light_label(d: np.ndarray) -> str:
    """"theta = 60 deg, phi = 90 deg" of a world direction towards the light."""
    theta = np.degrees(np.arccos(np.clip(d[2], -1, 1)))
    phi = np.degrees(np.arctan2(d[1], d[0])) % 360.0
    return f"light θ = {theta:.0f}°, φ = {phi:.0f}°" if theta > 0.5 else "light θ = 0° (from the camera)"


class SpherePanels:
    """Writes the per-light panels: reference | fit | signed luminance error with a colour bar.

    One figure is laid out once and its images, limits and titles are updated for each light:
    building a figure (axes, colour bar, layout) costs more than drawing it.
    """

    def __init__(self, size: int, ref_label: str, fit_label: str, irradiance: float = 1.0):
        fig = _figure((11.0, 4.1))
        # fixed layout (no tight_layout: it draws the figure once more)
        left, width, gap, top, height = 0.015, 0.27, 0.02, 0.83, 0.76
        axes = [fig.add_axes((left + k * (width + gap), top - height, width, height)) for k in range(3)]
        cax = fig.add_axes((left + 3 * width + 2 * gap + 0.01, top - height, 0.012, height))
        blank = np.zeros((size, size, 3))
        self.im_ref = axes[0].imshow(blank, interpolation="nearest")
        self.im_fit = axes[1].imshow(blank, interpolation="nearest")
        self.im_err = axes[2].imshow(blank[..., 0], cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        axes[0].set_title(f"reference: {ref_label}", fontsize=10)
        axes[1].set_title(f"fit: {fit_label}", fontsize=10)
        axes[2].set_title("error: fit − reference (luminance)\nred: fit too bright, blue: too dark", fontsize=9)
        # the sphere's outline on the error map, where the background is white like zero error
        t = np.linspace(0, 2 * np.pi, 256)
        c = (size - 1) / 2
        axes[2].plot(c + size / 2 * np.cos(t), c + size / 2 * np.sin(t), color="0.6", lw=0.6)
        # where the light direction projects onto the image (the normal facing the light)
        (self.light_dot,) = axes[2].plot([], [], "o", ms=7, mfc="gold", mec="black", mew=0.8)
        axes[2].legend([self.light_dot], ["light direction, projected"], loc="lower right", fontsize=7,
                       frameon=False, handletextpad=0.2, borderaxespad=0.1)
        axes[2].set_xlim(-0.5, size - 0.5)
        axes[2].set_ylim(size - 0.5, -0.5)
        self.size = size
        for ax in axes:
            ax.set_xticks([])
            ax.set_yticks([])
        cb = fig.colorbar(self.im_err, cax=cax)
        cb.set_label(f"radiance difference (irradiance {irradiance:g})", fontsize=8)
        cb.ax.tick_params(labelsize=8)
        self.title = fig.suptitle("", fontsize=11, y=0.975)
        self.fig = fig

    def write(self, path: Path, reference: np.ndarray, fit: np.ndarray, scale: float, light: np.ndarray, metrics: dict):
        self.im_ref.set_data(tonemap(reference, scale))
        self.im_fit.set_data(tonemap(fit, scale))
        d = luminance(fit) - luminance(reference)
        lim = _limit(d)
        self.im_err.set_data(d)
        self.im_err.set_clim(-lim, lim)
        # pixel coordinates of world (x, y) = the light direction's projection (SPEC 6 framing)
        n = self.size
        self.light_dot.set_data([(light[0] + 1) * n / 2 - 0.5], [(1 - light[1]) * n / 2 - 0.5])
        self.title.set_text(
            f"{light_label(light)}    RMSE {metrics['rmse']:.3g}   rel. RMSE {metrics['relative_rmse']:.3g}   "
            f"PSNR {metrics['psnr']:.1f} dB   FLIP {metrics['flip']:.3f}"
        )
        self.fig.savefig(path, dpi=90, pil_kwargs={"compress_level": 1})

    def close(self):
        self.fig.clear()


def _ring_ticks(ax) -> None:
    """Ticks at the first direction of each theta ring of the UBO-81 ordering."""
    angles = ubo_angles_deg()
    starts = [int(np.argmax(angles[:, 0] == t)) for t in UBO_THETA_DEG]
    ends = starts[1:] + [len(angles)]
    # label each ring (from 15 degrees: the pole is a single row) at its middle, lines between rings
    centres = [(a + b - 1) / 2 for a, b in zip(starts[1:], ends[1:])]
    labels = [f"{t}°" for t in UBO_THETA_DEG[1:]]
    ax.set_xticks(centres, labels, fontsize=7)
    ax.set_yticks(centres, labels, fontsize=7)
    for s in starts[1:]:
        ax.axhline(s - 0.5, color="white", lw=0.3, alpha=0.5)
        ax.axvline(s - 0.5, color="white", lw=0.3, alpha=0.5)


def table_panel(path: Path, reference: np.ndarray, fit: np.ndarray, ref_label: str, fit_label: str, metrics: dict) -> None:
    """The 81x81 tables (rows: light, columns: view, ordered by theta then phi) as the UTIA
    database shows them: f_r * cos(theta_light) tone-mapped | fitted | signed error."""
    from ..grid import ubo_directions

    cos_l = np.maximum(ubo_directions()[:, 2], 0.0)[:, None, None]
    # invalid measured entries are NaN: black in the table, blank (no error shown) in the error map
    ref_raw = np.asarray(reference, np.float64) * cos_l
    ref = np.nan_to_num(ref_raw)
    fit = np.nan_to_num(np.asarray(fit, np.float64)) * cos_l
    from .metrics import exposure

    scale = exposure(ref)
    fig = _figure((12.0, 4.4))
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 1, 1.22]})
    for ax, img, title in ((axes[0], ref, f"measured\n{ref_label}"), (axes[1], fit, f"fitted\n{fit_label}")):
        ax.imshow(tonemap(img, scale), interpolation="nearest")
        ax.set_title(title, fontsize=10)
    d = luminance(fit) - luminance(ref_raw)
    lim = _limit(d)
    im = axes[2].imshow(d, cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
    axes[2].set_title("error: fitted − measured\n(luminance of f_r cos θ_light)", fontsize=10)
    cb = fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    cb.set_label("f_r cos θ_light difference (1/sr)", fontsize=8)
    cb.ax.tick_params(labelsize=8)
    for ax in axes:
        _ring_ticks(ax)
        ax.set_xlabel("view θ ring (φ increasing within)", fontsize=8)
        ax.set_ylabel("light θ ring", fontsize=8)
    fig.suptitle(
        f"UBO-81 table (81 light × 81 view directions)    RMSE {metrics['rmse']:.3g} 1/sr   "
        f"rel. RMSE {metrics['relative_rmse']:.3g}   log-RMSE {metrics['log_rmse']:.3g}",
        fontsize=11,
    )
    fig.subplots_adjust(left=0.05, right=0.92, bottom=0.12, top=0.8, wspace=0.25)
    fig.savefig(path, dpi=90, pil_kwargs={"compress_level": 1})
