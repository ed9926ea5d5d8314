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


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _limit(d: np.ndarray) -> float:
    a = np.abs(d[np.isfinite(d)])
    lim = float(np.percentile(a, 99.5)) if a.size else 0.0
    return lim if lim > 0 else 1e-12


def light_label(d: np.ndarray) -> str:
    """"theta = 60 deg, phi = 90 deg" of a world direction towards the light."""
    theta = np.degrees(np.arccos(np.clip(d[2], -1, 1)))
    phi = np.degrees(np.arctan2(d[1], d[0])) % 360.0
    return f"light θ = {theta:.0f}°, φ = {phi:.0f}°" if theta > 0.5 else "light θ = 0° (from the camera)"


def sphere_panel(
    path: Path,
    reference: np.ndarray,
    fit: np.ndarray,
    scale: float,
    light: np.ndarray,
    metrics: dict,
    ref_label: str,
    fit_label: str,
) -> None:
    """One light: reference | fit | signed luminance error with a colour bar."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(11.0, 4.0), gridspec_kw={"width_ratios": [1, 1, 1.22]})
    for ax, img, title in ((axes[0], reference, f"reference\n{ref_label}"), (axes[1], fit, f"fit\n{fit_label}")):
        ax.imshow(tonemap(img, scale), interpolation="nearest")
        ax.set_title(title, fontsize=10)
    d = luminance(fit) - luminance(reference)
    lim = _limit(d)
    im = axes[2].imshow(d, cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
    axes[2].set_title("error: fit − reference\n(luminance)", fontsize=10)
    cb = fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    cb.set_label("radiance difference (per unit irradiance)", fontsize=8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(
        f"{light_label(light)}    RMSE {metrics['rmse']:.3g}   rel. RMSE {metrics['relative_rmse']:.3g}   "
        f"PSNR {metrics['psnr']:.1f} dB   FLIP {metrics['flip']:.3f}",
        fontsize=11,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _ring_ticks(ax) -> None:
    """Ticks at the first direction of each theta ring of the UBO-81 ordering."""
    angles = ubo_angles_deg()
    starts = [int(np.argmax(angles[:, 0] == t)) for t in UBO_THETA_DEG]
    labels = [f"{t}°" for t in UBO_THETA_DEG]
    ax.set_xticks(starts, labels, fontsize=7)
    ax.set_yticks(starts, labels, fontsize=7)
    for s in starts[1:]:
        ax.axhline(s - 0.5, color="white", lw=0.3, alpha=0.5)
        ax.axvline(s - 0.5, color="white", lw=0.3, alpha=0.5)


def table_panel(path: Path, reference: np.ndarray, fit: np.ndarray, ref_label: str, fit_label: str, metrics: dict) -> None:
    """The 81x81 tables (rows: light, columns: view, ordered by theta then phi) as the UTIA
    database shows them: f_r * cos(theta_light) tone-mapped | fitted | signed error."""
    plt = _plt()
    from ..grid import ubo_directions

    cos_l = np.maximum(ubo_directions()[:, 2], 0.0)[:, None, None]
    ref = np.nan_to_num(np.asarray(reference, np.float64)) * cos_l
    fit = np.nan_to_num(np.asarray(fit, np.float64)) * cos_l
    from .metrics import exposure

    scale = exposure(ref)
    fig, axes = plt.subplots(1, 3, figsize=(12.0, 4.4), gridspec_kw={"width_ratios": [1, 1, 1.22]})
    for ax, img, title in ((axes[0], ref, f"measured\n{ref_label}"), (axes[1], fit, f"fitted\n{fit_label}")):
        ax.imshow(tonemap(img, scale), interpolation="nearest")
        ax.set_title(title, fontsize=10)
    d = luminance(fit) - luminance(ref)
    lim = _limit(d)
    im = axes[2].imshow(d, cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
    axes[2].set_title("error: fitted − measured\n(luminance of f_r cos θ_light)", fontsize=10)
    cb = fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04)
    cb.set_label("f_r cos θ_light difference (1/sr)", fontsize=8)
    for ax in axes:
        _ring_ticks(ax)
        ax.set_xlabel("view direction (θ rings, φ within)", fontsize=8)
        ax.set_ylabel("light direction", fontsize=8)
    fig.suptitle(
        f"UBO-81 table (81 light × 81 view directions)    RMSE {metrics['rmse']:.3g} 1/sr   "
        f"rel. RMSE {metrics['relative_rmse']:.3g}   log-RMSE {metrics['log_rmse']:.3g}",
        fontsize=11,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
