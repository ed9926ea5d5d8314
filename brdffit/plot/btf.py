"""BTF figures: :func:`parameter_maps` (the maps ``fit_btf`` made), :func:`map_preview_png` (one map
as a PNG of its own pixels) and :func:`btf_panel` (photographs against renders of the maps)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ._common import new_figure

if TYPE_CHECKING:
    from ._figure import Figure


# -- BTF -----------------------------------------------------------------------------------------------
def _p99(a) -> float:
    v = float(np.percentile(np.asarray(a, np.float64), 99))
    return v if v > 0 else 1.0


def _range(a) -> tuple[float, float]:
    lo, hi = (float(x) for x in np.percentile(np.asarray(a, np.float64), [1, 99]))
    return (lo, hi if hi > lo else lo + 1e-12)


def _rgb_preview(a) -> np.ndarray:
    from ..io.images import linear_to_srgb

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
    fig = new_figure((3.2 * cols, 3.0 * rows), dpi=90)
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
    from ..render.metrics import exposure, tonemap

    n = len(names)
    fig = new_figure((9.5, 3.0 * n), dpi=90)
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
