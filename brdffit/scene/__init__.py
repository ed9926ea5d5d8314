"""Scene-aware fitting (docs/scene.md#scene-aware-fitting): where a user's Mitsuba 3 scene looks at a material, fit weights
from it, and the scene rendered with a fit beside it rendered with the reference."""

from __future__ import annotations

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from .render import SceneValidation, render_scene, validate_scene
from .usage import Usage, fit_data, rusinkiewicz, scene_usage

__all__ = ["SceneValidation", "Usage", "fit_data", "render_scene", "rusinkiewicz", "scene_usage", "validate_scene"]
