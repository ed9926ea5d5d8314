"""``.blend`` (docs/materials.md#native-materials-and-exports): a UV sphere carrying a ``blender:*`` fit (``blender:principled``) as Blender's
own Principled BSDF, written by Blender itself in the worker process (:mod:`brdffit.cycles`).

The file holds one smooth UV sphere (radius 1) with the material, a camera and a sun, and Cycles as
its render engine; the material's custom property ``brdffit`` holds ``extras`` as JSON text (the fit,
its metrics, the conversion error of a converted fit). Needs the Blender environment
(``.venv-blender``); without it, one UsageError line.
"""

from __future__ import annotations

from .._files import strict_json
from ..errors import UsageError
from ._record import fit_record, native_of
from .formats import Format


def check_native(native) -> dict:
    """``native`` if it is a Blender material dict (``blender:principled``'s ``native()``), else one line."""
    if not (isinstance(native, dict) and isinstance(native.get("inputs"), dict)
            and native.get("distribution") in ("GGX", "MULTI_GGX")):
        held = FORMAT.held()
        raise UsageError(f"a .blend file holds a {' or '.join(held)} material ({{'distribution': 'GGX', 'inputs': "
                         f"{{...}}}}); convert the fit with --to {held[0]}")
    return native


def blend_bytes(native: dict, name: str, extras: dict) -> bytes:
    """The contents of a .blend file with a sphere and the material ``name`` set from ``native``."""
    from .. import cycles

    return cycles.blend_file(check_native(native), str(name), strict_json(extras))


#: Every ``blender:*`` model: ``model.native`` is the Principled BSDF's settings.
FORMAT = Format("Blender", (".blend",), lambda fit, ext, bsdf_id: blend_bytes(native_of(fit), bsdf_id, fit_record(fit)),
                lambda fit, ext: "a UV sphere with the material (Blender)", target="blender", note="needs .venv-blender")
