"""The model library: ``names()``, ``get(name)``; one file per model (SPEC 4).

A module in this package that defines ``MODEL`` is registered under ``MODEL.name``.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import Model, Param

_REGISTRY: dict[str, Model] = {}


def _discover() -> dict[str, Model]:
    if not _REGISTRY:
        for info in pkgutil.iter_modules(__path__):
            if info.name.startswith("_") or info.name in ("base",):
                continue
            module = importlib.import_module(f"{__name__}.{info.name}")
            model = getattr(module, "MODEL", None)
            if isinstance(model, Model):
                _REGISTRY[model.name] = model
    return _REGISTRY


def names() -> list[str]:
    """Registered base model names (compose them with '+', e.g. 'lambert+ggx+ggx')."""
    return sorted(_discover())


def get(name: str | Model) -> Model:
    """A model by name; '+' composes models."""
    if isinstance(name, Model):
        return name
    registry = _discover()
    key = name.strip().lower()
    if key in registry:
        return registry[key]
    raise KeyError(f"unknown model {name!r}; known: {', '.join(names())}")


__all__ = ["Model", "Param", "get", "names"]
