"""Scene-aware fitting (docs/scene.md#scene-aware-fitting): :func:`usage` (where a scene looks at a material) and
:func:`scene_panel` (a scene rendered with the reference | with the fit | FLIP map)."""

from __future__ import annotations

import numpy as np

from ._common import new_figure


# -- scene-aware fitting (docs/scene.md#scene-aware-fitting) -----------------------------------------------------------------
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

    from ..grid import ubo_pairs

    if measurement is None:
        from ..measurement import Measurement

        wi, wo = ubo_pairs()
        measurement = Measurement(wi, wo, np.zeros((wi.shape[0], 1)), name="UBO-81", grid="ubo81")
    w = usage.weights(measurement, bandwidth_deg=bandwidth_deg, floor=floor)
    fig = new_figure((14.0, 4.4), layout="constrained")
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


def scene_panel(reference: np.ndarray, fit: np.ndarray, flip_map: np.ndarray, scale: float, metrics: dict):
    """Scene rendered with the reference | with the fit | FLIP error map, one exposure for both."""
    from ..render.metrics import tonemap

    h, w = reference.shape[:2]
    fig = new_figure((3 * 4.0 * w / max(h, w) + 1.0, 4.0 * h / max(h, w) + 0.9), layout="constrained")
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
                 f"{o['rel_rmse']:.3g}, PSNR {o['psnr']:.1f} dB, FLIP {o['flip']:.3f}", fontsize=10)
    return fig
