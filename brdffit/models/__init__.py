"""The model library: ``names()``, ``get(name)``; one file per model (docs/models.md#models).

A module in this package that defines ``MODEL`` is registered under ``MODEL.name`` (``_registry``:
adding a model is one file and its tests). Native models
(docs/materials.md#native-materials-and-exports) are named ``renderer:bsdf`` and live in ``renderer_bsdf.py`` (``mitsuba:roughplastic`` in
``mitsuba_roughplastic.py``).
``get`` also accepts sums ("lambert+ggx+ggx", see ``compose``: names are case-insensitive and
spaces are ignored) and multi-lobe Lafortune models (``get("lafortune", lobes=3)`` or
``get("lafortune3")``).
"""

from __future__ import annotations

import functools
import re

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from ._registry import discover as _discover
from ._registry import native_names
from .base import Model, Param


def names() -> list[str]:
    """Registered base model names (compose them with '+', e.g. 'lambert+ggx+ggx')."""
    return sorted(_discover())


def _one(key: str, original: str) -> Model:
    registry = _discover()
    if key in registry:
        return registry[key]
    lobes = re.fullmatch(r"lafortune(\d+)", key)
    if lobes:
        from .lafortune import lafortune

        return lafortune(int(lobes.group(1)))
    raise KeyError(f"unknown model {key!r} in {original!r}; known: {', '.join(names())}")


@functools.lru_cache(maxsize=None)
def _get(key: str) -> Model:
    # Cached on the normalised key: one Model object per model, so that jit caches keyed on the
    # (hashable, static) model are shared by every spelling of its name.
    from .compose import compose

    parts = key.split("+")
    if any(not p for p in parts):
        raise KeyError(f"malformed model name {key!r}: empty component")
    components = [_one(p, key) for p in parts]
    if len(components) > 1 and any(c.is_native for c in components):
        # a name the user typed: the registry's KeyError, which the CLI reports as bad usage
        raise KeyError(f"{key!r}: native models ({', '.join(c.name for c in components if c.is_native)}) "
                       "do not compose with '+'")
    return compose(components)


def get(name: str | Model, *, lobes: int | None = None) -> Model:
    """A model by name; '+' composes models. ``lobes`` selects a multi-lobe Lafortune model."""
    if isinstance(name, Model):
        return name
    key = "".join(str(name).split()).lower()
    if lobes is not None:
        if key != "lafortune":
            raise KeyError(f"lobes= applies to 'lafortune' only, not {name!r}")
        from .lafortune import lafortune

        return lafortune(int(lobes))
    return _get(key)


# Sums of Model objects: ``brdffit.models.compose.compose([m1, m2])`` (a function of the same name
# here would be shadowed by the submodule as soon as it is imported).
__all__ = ["Model", "Param", "get", "names", "native_names"]
