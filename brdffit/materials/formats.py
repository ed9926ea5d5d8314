"""The material formats, one module each (docs/materials.md#native-materials-and-exports): what a file holds and how it is written.

A module of this package that declares ``FORMAT`` (a :class:`Format`: one fit as a material file)
or ``MAPS_FORMAT`` (a :class:`MapsFormat`: a BTF's parameter maps as a textured material) is a
format; the registry finds it by that name, as :mod:`brdffit.models` finds its models, the first
time a format is asked for. Each declares its extensions, the models it holds and its writer; the
CLI's help and every message that names formats, or the models a format holds, are read from here.
Adding a format is one module (and its tests); a native model that a format holds by its renderer
(``target``) is held as soon as its model file exists.

A format module imports at its top only what declaring itself needs; its writer's libraries
(pygltflib, MaterialX, Blender's worker, OpenEXR) load when it writes.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import pkgutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import UsageError


class _Holds:
    """Which models a format holds: every native model of one renderer or format (``target``, the
    part of a native model's name before ':'), the models named (``models``, in the order a message
    proposes them), or, with neither, any model."""

    target: str | None
    models: tuple[str, ...]

    def holds(self, model_name: str) -> bool:
        if self.models:
            return model_name in self.models
        if self.target is not None:
            renderer, colon, _ = model_name.partition(":")
            return bool(colon) and renderer == self.target
        return True

    def held(self) -> tuple[str, ...]:
        """The native models it holds, by name (empty for a format that holds any model)."""
        if self.models or self.target is None:
            return self.models
        from ..models import native_names

        return tuple(n for n in native_names() if self.holds(n))


@dataclasses.dataclass(frozen=True)
class Format(_Holds):
    """One fit as a material file: what a format module declares as ``FORMAT``.

    ``write(fit, ext, bsdf_id)`` returns the file's bytes for a fit whose model the format holds
    (checked first: :func:`brdffit.materials.check_format`); ``describe(fit, ext)`` says what the
    file holds, for the line after an export; ``note`` follows the name in the help."""

    name: str
    extensions: tuple[str, ...]
    write: Callable[[Any, str, str], bytes]
    describe: Callable[[Any, str], str]
    target: str | None = None
    models: tuple[str, ...] = ()
    note: str = ""


@dataclasses.dataclass(frozen=True)
class MapsJob:
    """One textured export, checked: the native model, its maps ``{parameter: (H, W, size)}``, the
    file, the material's id, what the file records (``extras``) and the format's ``plan``."""

    model: Any
    arrays: dict
    path: Path
    bsdf_id: str
    extras: dict
    plan: Any = None


@dataclasses.dataclass(frozen=True)
class MapsFormat(_Holds):
    """Parameter maps as a textured material file: what a format module declares as ``MAPS_FORMAT``.

    ``plan(model, arrays, path, source)``, before any work, refuses (one line) what the renderer
    cannot take and returns what the writer needs (default: nothing); ``write(job)`` returns the
    file's bytes; ``textures(job, folder)``, where given, writes texture files into the folder
    ``<stem>_textures`` beside the file, which the export writes first (:mod:`.textured`)."""

    name: str
    extensions: tuple[str, ...]
    write: Callable[[MapsJob], bytes]
    target: str | None = None
    models: tuple[str, ...] = ()
    plan: Callable[..., Any] | None = None
    textures: Callable[[MapsJob, Path], None] | None = None
    note: str = ""


_FOUND: list[dict] = []


def _declared(maps: bool) -> dict:
    """Extension -> format, for fits or for maps."""
    if not _FOUND:
        fits: dict[str, Format] = {}
        textured: dict[str, MapsFormat] = {}
        package = __name__.rpartition(".")[0]
        for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
            if info.name.startswith("_") or info.name == "formats":
                continue
            module = importlib.import_module(f"{package}.{info.name}")
            for table, attr in ((fits, "FORMAT"), (textured, "MAPS_FORMAT")):
                declared = getattr(module, attr, None)
                for ext in declared.extensions if declared is not None else ():
                    if ext in table:
                        raise RuntimeError(f"materials/{info.name}.py: {ext} is declared by another format too")
                    table[ext] = declared
        _FOUND.extend([fits, textured])
    return _FOUND[1 if maps else 0]


def formats(*, maps: bool = False) -> tuple:
    """Every format of fits (of parameter maps, with ``maps``), in the order of their modules."""
    return tuple(dict.fromkeys(_declared(maps).values()))


def extensions(*, maps: bool = False) -> list[str]:
    return sorted(_declared(maps))


def for_path(path: str | os.PathLike, *, maps: bool = False):
    """The format of ``path`` by its extension, or one ``UsageError`` line naming those there are."""
    ext = Path(path).suffix.lower()
    if ext not in _declared(maps):
        usable = ", ".join(extensions(maps=maps))
        what, hint = ("textured material format", f"parameter maps export as {usable}") if maps else \
            ("material format", f"use one of {usable}")
        raise UsageError(f"{path}: unknown {what} {ext or '(no extension)'!r}; {hint}")
    return _declared(maps)[ext]


def of_extension(ext: str, *, maps: bool = False):
    """The format of an extension already checked (``.xml``)."""
    return _declared(maps)[ext.lower()]


def help_text(*, maps: bool = False) -> str:
    """The formats as the help names them: ``.blend (Blender; needs .venv-blender), .glb or .gltf (glTF 2.0), ...``."""
    return ", ".join(f"{' or '.join(f.extensions)} ({f.name}{'; ' + f.note if f.note else ''})"
                     for f in formats(maps=maps))


def maps_help_text() -> str:
    """:func:`help_text` of the formats of parameter maps."""
    return help_text(maps=True)
