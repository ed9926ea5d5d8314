"""``.blend`` export (SPEC 13): a UV sphere carrying a ``blender:principled`` fit as Blender's own
Principled BSDF, written by Blender itself in the worker process (:mod:`brdffit.cycles`).

The file holds one smooth UV sphere (radius 1) with the material, a camera and a sun, and Cycles as
its render engine; the material's custom property ``brdffit`` holds ``extras`` as JSON text (the fit,
its metrics, the conversion error of a converted fit). Needs the Blender environment
(``.venv-blender``); without it, one UsageError line.
"""

from __future__ import annotations

from .._files import strict_json
from ..errors import UsageError


def check_native(native) -> dict:
    """``native`` if it is a Blender material dict (``blender:principled``'s ``native()``), else one line."""
    if not (isinstance(native, dict) and isinstance(native.get("inputs"), dict)
            and native.get("distribution") in ("GGX", "MULTI_GGX")):
        raise UsageError("a .blend file holds a blender:principled material ({'distribution': 'GGX', 'inputs': "
                         "{...}}); convert the fit with --to blender:principled")
    return native


def blend_bytes(native: dict, name: str, extras: dict) -> bytes:
    """The contents of a .blend file with a sphere and the material ``name`` set from ``native``."""
    from .. import cycles

    return cycles.blend_file(check_native(native), str(name), strict_json(extras))
