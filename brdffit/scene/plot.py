"""Figures of scene-aware fitting (to move into ``brdffit.plot``): where a scene looks, and a
scene validation panel. matplotlib ``Figure`` objects built without pyplot (the caller's backend
is never changed; ``savefig`` draws with Agg; Jupyter shows a returned Figure)."""

from __future__ import annotations

import numpy as np


def _figure(figsize):
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained")


def usage(usage, measurement=None, *, bandwidth_deg: float = 5.0, floor: float = 1e-2):
    """Where a scene looks at its material (``usage`` from ``brdffit.scene_usage``).

    Left: the weights ``usage.weights`` gives the UBO-81 table (``measurement`` when given,
    else the UBO-81 pairs), light rows by view columns like the 81x81 display, log scale.
    Middle: the recorded contribution as a density over (theta_h, theta_d). Right: over
    (theta_light, theta_view).
    """
    from matplotlib.colors import LogNorm

    from ..grid import ubo_pairs

    if measurement is None:
        from ..measurement import Measurement

        wi, wo = ubo_pairs()
        measurement = Measurement(wi, wo, np.zeros((wi.shape[0], 1)), name="UBO-81", grid="ubo81")
    w = usage.weights(measurement, bandwidth_deg=bandwidth_deg, floor=floor)
    fig = _figure((14.0, 4.4))
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
    bins = np.linspace(0, 90, 46)
    h, _, _ = np.histogram2d(c[:, 0], c[:, 1], bins=(bins, bins), weights=usage.weight)
    h = h / h.max() if h.max() > 0 else h
    im = axes[1].imshow(h.T, origin="lower", extent=(0, 90, 0, 90), norm=LogNorm(1e-3, 1.0), cmap="viridis",
                        interpolation="nearest")
    axes[1].set_xlabel("θ_h [°]")
    axes[1].set_ylabel("θ_d [°]")
    axes[1].set_title("contribution to the image over (θ_h, θ_d)", fontsize=10)
    fig.colorbar(im, ax=axes[1], fraction=0.046, label="relative contribution")

    ti = np.degrees(np.arccos(np.clip(usage.wi[:, 2], -1, 1)))
    to = np.degrees(np.arccos(np.clip(usage.wo[:, 2], -1, 1)))
    h, _, _ = np.histogram2d(ti, to, bins=(bins, bins), weights=usage.weight)
    h = h / h.max() if h.max() > 0 else h
    im = axes[2].imshow(h.T, origin="lower", extent=(0, 90, 0, 90), norm=LogNorm(1e-3, 1.0), cmap="viridis",
                        interpolation="nearest")
    axes[2].set_xlabel("θ light [°]")
    axes[2].set_ylabel("θ view [°]")
    axes[2].set_title("… over (θ light, θ view)", fontsize=10)
    fig.colorbar(im, ax=axes[2], fraction=0.046, label="relative contribution")
    fig.suptitle(f"where {usage.material!r} is seen in {usage.scene}: {len(usage)} pairs, "
                 f"{usage.pixels[0]}x{usage.pixels[1]} px, {usage.spp} spp", fontsize=11)
    return fig


def validation_panel(reference: np.ndarray, fit: np.ndarray, flip_map: np.ndarray, scale: float, metrics: dict):
    """Scene rendered with the reference | with the fit | FLIP error map, one exposure for both."""
    from ..render.metrics import tonemap

    h, w = reference.shape[:2]
    fig = _figure((3 * 4.0 * w / max(h, w) + 1.0, 4.0 * h / max(h, w) + 0.9))
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
