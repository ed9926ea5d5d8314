"""Rendered spheres: :func:`spheres` (tone-mapped renders side by side) and :func:`sphere_panel`
(one light of a validation: reference | fit | signed error per channel)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._common import _sym_norm, light_label, new_figure

if TYPE_CHECKING:
    from ._figure import Figure


# -- sphere renders ----------------------------------------------------------------------------------
def spheres(images, lights=None, *, titles=None, exposure: float | None = None) -> Figure:
    """Tone-mapped renders side by side, (L, H, W, 3) linear radiance, or a Validation (reference
    and fit rows). One exposure for all (from the first row): brightness compares across lights."""
    from ..render.metrics import exposure as _exposure
    from ..render.metrics import tonemap

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
    fig = new_figure((2.6 * n + 0.4, 2.8 * len(rows) + 0.3), layout="constrained")
    axes = fig.subplots(len(rows), n, squeeze=False)
    from ..render.scene import light_directions

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
    from ..render.metrics import exposure, tonemap

    ref = np.asarray(reference, np.float64)
    tst = np.asarray(fit, np.float64)
    scale = exposure(ref) if scale is None else scale
    size = ref.shape[0]
    d = tst - ref
    norm = _sym_norm(d)
    fig = new_figure((15.5, 3.6), layout="constrained")
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
        text += (f"   RMSE {metrics['rmse']:.3g}   rel. RMSE {metrics['rel_rmse']:.3g}   "
                 f"PSNR {metrics['psnr']:.1f} dB   FLIP {metrics['flip']:.3f}")
    fig.suptitle(text, fontsize=10)
    return fig
