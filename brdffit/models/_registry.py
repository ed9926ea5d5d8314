"""The model files of this package, found by what they declare: a module that defines ``MODEL`` is
registered under ``MODEL.name`` (docs/models.md#models). Adding a model, native ones included, is one file.

Kept apart from the package's ``get``/``names`` (``brdffit.models``) so that :mod:`.base` can name
the native models in a message without importing the package that imports it: this module imports
no model module by name (it finds them), and none of its own imports is brdffit's.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

#: Modules of the package that hold no model (helpers start with '_').
NOT_MODELS = ("base", "compose", "albedo")
_REGISTRY: dict = {}


def discover() -> dict:
    """name -> Model of every model file (imported on the first call)."""
    if not _REGISTRY:
        package = __name__.rpartition(".")[0]
        for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
            if info.name.startswith("_") or info.name in NOT_MODELS:
                continue
            model = getattr(importlib.import_module(f"{package}.{info.name}"), "MODEL", None)
            if model is not None:
                _REGISTRY[model.name] = model
    return _REGISTRY


def native_names() -> list[str]:
    """The native models (a renderer's or format's own BSDF, named ``renderer:bsdf``; docs/materials.md#native-materials-and-exports), sorted."""
    return sorted(name for name, model in discover().items() if model.is_native)
