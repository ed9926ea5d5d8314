"""``brdffit.render_scene`` and ``brdffit.validate_scene``: a user's scene with its material replaced (docs/scene.md#scene-aware-fitting).

The scene renders with its own sensor, integrator and lights; only the BSDF with id ``material``
is replaced, by the same BSDF builders as the sphere validation (:mod:`brdffit.render.bsdf`): a
fit or a UBO-81 table through brdffit's callback BSDF (the JAX model / the table interpolator),
an RGL ``.bsdf`` through Mitsuba's ``measured`` plugin.

``validate_scene`` writes (in ``out``, atomically: the folder appears complete or not at all):
``reference.exr`` and ``fit.exr`` (linear radiance, 32-bit float RGB), ``panel.png`` (reference |
fit | FLIP error map) and ``metrics.json`` (rmse, rel_rmse, psnr, flip over the whole image,
with the tone mapping of :mod:`brdffit.render.metrics`; the settings; the time per stage).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
from pathlib import Path

import numpy as np

from .._mitsuba import mitsuba
from ..errors import UsageError
from ._drjit import python_bsdf_render
from .load import LoadedScene, load_scene, replaced, scene_name

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


#: Samples per pixel of a scene render.
DEFAULT_SPP = 64


def _source(obj):
    """A render Source from a FitResult, a fit.json path, a (model, params) pair, a Measurement or a file."""
    from ..render.validate import as_fit

    return as_fit(obj)


def source_bsdf(obj):
    """A *new* Mitsuba BSDF for ``obj`` (never the one a ``Source`` caches: a Python BSDF that
    outlives the render would break the caller's later symbolic renders, see ``_drjit``)."""
    from ..render.bsdf import callback_bsdf, measured_bsdf

    src = _source(obj)
    return measured_bsdf(src.path) if src.kind == "rgl" else callback_bsdf(src.brdf, src.label)


def _render_loaded(loaded: LoadedScene, obj, spp: int, seed: int) -> np.ndarray:
    mi = mitsuba()
    bsdf = source_bsdf(obj)
    with python_bsdf_render():
        with replaced(loaded, bsdf) as sc:
            img = np.array(mi.render(sc, spp=int(spp), seed=int(seed)), np.float32)
        del bsdf
    return img[..., :3]


def render_scene(scene, material: str, source, *, spp: int = DEFAULT_SPP, seed: int = 0) -> Float[np.ndarray, "H W 3"]:
    """Linear radiance (H, W, 3) of ``scene`` with the BSDF ``material`` replaced by ``source``.

    ``scene``: a Mitsuba 3 XML path, a scene dict or an ``mi.Scene`` (left unchanged).
    ``source``: a FitResult, a path to a fit.json, a ``(model_name, params)`` pair, a UBO-81
    Measurement, or a path to an RGL ``.bsdf`` (or another measurement file).
    """
    if int(spp) < 1:
        raise UsageError(f"spp must be >= 1, got {spp}")
    return _render_loaded(load_scene(scene, material), source, spp, seed)


@dataclasses.dataclass(frozen=True, eq=False)
class SceneValidation:
    """The result of :func:`validate_scene`."""

    reference: np.ndarray  # (H, W, 3) linear radiance
    fit: np.ndarray  # (H, W, 3)
    flip_map: np.ndarray  # (H, W) per-pixel FLIP
    metrics: dict
    files: tuple[Path, ...]
    seconds: dict[str, float]

    def __repr__(self) -> str:
        o = self.metrics["image"]
        return (f"SceneValidation({self.metrics['material']!r} in {self.metrics['scene']}: rmse {o['rmse']:.4g}, "
                f"psnr {o['psnr']:.1f} dB, flip {o['flip']:.3f}; {len(self.files)} files)")


def validate_scene(
    scene,
    material: str,
    fit,
    reference,
    *,
    spp: int = DEFAULT_SPP,
    seed: int = 0,
    out: str | Path | None = None,
    force: bool = False,
) -> SceneValidation:
    """Render ``scene`` with ``material`` as ``fit`` and as ``reference``, compare, write (module docstring).

    ``fit`` and ``reference`` take what :func:`render_scene` takes. Both renders use the same
    seed, so their noise is alike and the difference is the material's.
    """
    from ..render.bsdf import import_native
    from ..render.metrics import exposure, image_metrics
    from ..render.outputs import ValidationRun

    if int(spp) < 1:
        raise UsageError(f"spp must be >= 1, got {spp}")
    run = ValidationRun(out, force)  # checks the output folder before the work
    import_native()
    loaded = load_scene(scene, material)
    ref_label, fit_label = _source(reference).label, _source(fit).label
    run.lap("load")
    ref_img = _render_loaded(loaded, reference, spp, seed)
    run.lap("render reference")
    fit_img = _render_loaded(loaded, fit, spp, seed)
    run.lap("render fit")
    del loaded
    mask = np.ones(ref_img.shape[:2], bool)
    scale = exposure(ref_img, mask)
    m = image_metrics(ref_img, fit_img, mask, scale)
    flip_map = m.pop("_flip_map")
    m.pop("_mse_tonemapped")
    metrics = {
        "scene": scene_name(scene),
        "material": material,
        "reference": ref_label,
        "fit": fit_label,
        "size": [int(ref_img.shape[1]), int(ref_img.shape[0])],
        "spp": int(spp),
        "seed": int(seed),
        "image": m,
    }
    run.lap("metrics")
    with run.folder():
        if run.writing:
            from ..plot import scene_panel

            run.exr("reference.exr", ref_img)
            run.exr("fit.exr", fit_img)
            run.png("panel.png", scene_panel(ref_img, fit_img, flip_map, scale, metrics))
            run.lap("write")
            metrics["seconds"] = run.rounded_seconds()
            run.metrics_json(metrics)
    metrics["seconds"] = run.rounded_seconds()
    return SceneValidation(ref_img, fit_img, np.asarray(flip_map), metrics, tuple(run.files), dict(run.seconds))
