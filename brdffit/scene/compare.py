"""Scene-weighted against plain fits, judged in the scene and on the sphere validation (docs/scene.md#scene-aware-fitting's
"must show"; used by benchmarks/bench_scene.py and tests/test_scene_rgl.py)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


@dataclasses.dataclass(frozen=True)
class SceneGain:
    material: str
    scene_flip_plain: float  # the scene rendered with the plain UBO-81 fit against the reference
    scene_flip_scene: float  # ... with the scene-aware fit
    sphere_flip_plain: float  # brdffit.validate (spheres, light sweep) of the plain fit
    sphere_flip_scene: float  # ... of the scene-aware fit

    @property
    def gain(self) -> float:
        """How much lower the scene's FLIP is with the scene-aware fit."""
        return self.scene_flip_plain - self.scene_flip_scene

    @property
    def cost(self) -> float:
        """How much higher the sphere validation's FLIP is with the scene-aware fit."""
        return self.sphere_flip_scene - self.sphere_flip_plain


def scene_gain(reference: str | Path, scene, material: str, *, model: str = "ggx", usage_spp: int = 16,
               render_spp: int = 64, sphere_size: int = 64) -> SceneGain:
    """Fit ``model`` to ``reference`` (an RGL file) twice: plainly on the UBO-81 pairs, and for the
    scene (``fit_data`` + ``scene=usage``, usage recorded with the reference as the material);
    render the scene with both fits and the reference, and validate both fits on spheres."""
    import brdffit

    from ..render.metrics import image_metrics
    from .render import render_scene
    from .usage import fit_data, scene_usage

    plain = brdffit.fit(brdffit.load(reference), model)
    usage = scene_usage(scene, material, spp=usage_spp, source=reference)
    aware = brdffit.fit(fit_data(reference, usage), model, scene=usage)
    ref = render_scene(scene, material, reference, spp=render_spp)
    mask = np.ones(ref.shape[:2], bool)
    flips = [image_metrics(ref, render_scene(scene, material, f, spp=render_spp), mask)["flip"] for f in (plain, aware)]
    spheres = [brdffit.validate(reference, f, size=sphere_size).metrics["overall"]["flip"] for f in (plain, aware)]
    return SceneGain(Path(reference).stem, flips[0], flips[1], spheres[0], spheres[1])
