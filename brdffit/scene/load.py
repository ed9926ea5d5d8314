"""A user's Mitsuba 3 scene and the material in it that brdffit looks at or replaces.

``scene`` is a path to a Mitsuba XML scene, a scene dictionary (``mi.load_dict`` form) or an
already loaded ``mi.Scene``. The material is the BSDF whose ``id`` is ``material``: in XML the
``id`` attribute of a ``<bsdf>`` (top level, referenced with ``<ref id=.../>``, or nested in a
shape); in a dictionary a top-level key (or an ``"id"`` entry). Every shape whose BSDF has that id
uses the material. Replacing it (:func:`replaced`) swaps the BSDF object of those shapes
(``Shape.set_bsdf``) and restores the original on the way out, so the same loaded scene can
render several sources and a caller's ``mi.Scene`` is left as it was.
"""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path

from .._mitsuba import mitsuba
from ..errors import InputError


@dataclasses.dataclass(frozen=True, eq=False)
class LoadedScene:
    """A loaded scene, the name it is reported under, and the shapes using ``material``."""

    scene: object  # mi.Scene
    name: str
    material: str
    shapes: tuple  # mi.Shape using the material
    original: object  # mi.BSDF: the material as the scene defines it

    @property
    def two_sided(self) -> bool:
        mi = mitsuba()
        return bool(self.original.flags() & mi.BSDFFlags.BackSide)


def scene_name(scene) -> str:
    if isinstance(scene, (str, Path)):
        return str(scene)
    return "<scene dict>" if isinstance(scene, dict) else "<mi.Scene>"


def load_scene(scene, material: str) -> LoadedScene:
    """Load ``scene`` and find ``material`` in it (InputError naming the scene when it is not there)."""
    from ..render.export import register_mitsuba

    mi = mitsuba()
    register_mitsuba()  # a scene may hold a fit exported as <bsdf type="brdffit"> (docs/materials.md#a-fit-in-any-mitsuba-scene)
    name = scene_name(scene)
    if isinstance(scene, (str, Path)):
        path = Path(scene)
        if not path.is_file():
            raise InputError(name, "no such scene file")
        try:
            loaded = mi.load_file(str(path))
        except Exception as exc:  # Mitsuba reports XML and plugin errors as RuntimeError
            raise InputError(name, f"not a loadable Mitsuba 3 scene: {_first_line(exc)}") from None
    elif isinstance(scene, dict):
        try:
            loaded = mi.load_dict(scene)
        except Exception as exc:
            raise InputError(name, f"not a loadable Mitsuba 3 scene dictionary: {_first_line(exc)}") from None
    elif isinstance(scene, mi.Scene):
        loaded = scene
    else:
        raise TypeError(f"scene must be an XML path, a scene dict or an mi.Scene, not {type(scene).__name__}")
    if not isinstance(loaded, mi.Scene):
        raise InputError(name, "does not describe a scene (its root is not a scene)")
    if not loaded.sensors():
        raise InputError(name, "the scene has no sensor")
    shapes = tuple(s for s in loaded.shapes() if s.bsdf() is not None and s.bsdf().id() == material)
    if not shapes:
        ids = sorted({s.bsdf().id() for s in loaded.shapes() if s.bsdf() is not None})
        raise InputError(name, f"no shape uses a BSDF with id {material!r} (BSDF ids in the scene: {', '.join(ids) or 'none'})")
    return LoadedScene(loaded, name, material, shapes, shapes[0].bsdf())


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[-1] if text else type(exc).__name__


@contextlib.contextmanager
def replaced(loaded: LoadedScene, bsdf):
    """``loaded``'s material replaced by ``bsdf`` for the duration of the block (wrapped in Mitsuba's
    ``twosided`` when the original material is two-sided, so back faces still reflect)."""
    mi = mitsuba()
    if loaded.two_sided and not (bsdf.flags() & mi.BSDFFlags.BackSide):
        bsdf = mi.load_dict({"type": "twosided", "material": bsdf})
    try:
        for s in loaded.shapes:
            s.set_bsdf(bsdf)
        yield loaded.scene
    finally:
        for s in loaded.shapes:
            s.set_bsdf(loaded.original)
        del bsdf
