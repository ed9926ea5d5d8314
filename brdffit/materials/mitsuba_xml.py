"""``.xml`` (docs/materials.md#a-fit-in-any-mitsuba-scene and docs/materials.md#native-materials-and-exports): a fit as a Mitsuba 3 scene-XML fragment, a plugin dictionary written as XML.

Mitsuba's XML and ``mi.load_dict`` describe the same objects: a plugin ``type`` and named
properties. This writes the dictionary that ``mitsuba:*`` models return (the renderer's own
``roughconductor``, ``roughplastic`` or ``principled`` plugin, every setting written out) so that a
plain Mitsuba, in a process that never imports brdffit, loads it, and for any other fit the
``brdffit`` plugin's properties (:func:`plugin_dict`, the layout ``brdffit.render.export``
documents and its plugin reads)::

    <scene version="3.0.0">
        <bsdf type="roughplastic" id="paint">
            <string name="distribution" value="ggx"/>
            <rgb name="diffuse_reflectance" value="0.31, 0.24, 0.2"/>
            <float name="alpha" value="0.12"/>
            ...
        </bsdf>
    </scene>
"""

from __future__ import annotations

import html
from collections.abc import Mapping

import numpy as np

from .._files import plain_text
from ._names import xml_comment
from ._record import about, native_of
from .formats import Format


def _attr(value: str) -> str:
    return html.escape(plain_text(value), quote=True)


def _number(x) -> str:
    return repr(float(x))


def _property(name: str, value, indent: str) -> list[str]:
    """The XML element(s) of one ``mi.load_dict`` property."""
    if isinstance(value, bool):  # before int: bool is an int in Python
        return [f'{indent}<boolean name="{_attr(name)}" value="{"true" if value else "false"}"/>']
    if isinstance(value, int):
        return [f'{indent}<integer name="{_attr(name)}" value="{value}"/>']
    if isinstance(value, float):
        return [f'{indent}<float name="{_attr(name)}" value="{_number(value)}"/>']
    if isinstance(value, str):
        return [f'{indent}<string name="{_attr(name)}" value="{_attr(value)}"/>']
    if isinstance(value, Mapping) and value.get("type") == "rgb":
        rgb = ", ".join(_number(v) for v in value["value"])
        return [f'{indent}<rgb name="{_attr(name)}" value="{rgb}"/>']
    if isinstance(value, Mapping) and value.get("type") == "spectrum":
        v = value["value"]  # one value, or (wavelength, value) pairs: "400:0.1, 500:0.2"
        text = ", ".join(f"{_number(w)}:{_number(x)}" for w, x in v) if isinstance(v, (list, tuple)) else _number(v)
        return [f'{indent}<spectrum name="{_attr(name)}" value="{text}"/>']
    if isinstance(value, Mapping) and "type" in value:  # a nested plugin (a texture)
        return _plugin("texture", value, indent, name=name)
    raise TypeError(f"property {name!r}: no Mitsuba XML form for {type(value).__name__} {value!r}")


def _plugin(tag: str, d: Mapping, indent: str, name: str | None = None, plugin_id: str | None = None) -> list[str]:
    head = f'{indent}<{tag} type="{_attr(d["type"])}"'
    if name is not None:
        head += f' name="{_attr(name)}"'
    if plugin_id is not None:
        head += f' id="{_attr(plugin_id)}"'
    lines = [head + ">"]
    for key, value in d.items():
        if key in ("type", "id"):
            continue
        lines += _property(key, value, indent + "    ")
    return lines + [f"{indent}</{tag}>"]


def native_xml(native: Mapping, bsdf_id: str, comment: str = "") -> str:
    """A ``<scene>`` holding one ``<bsdf>`` written from a native ``mi.load_dict`` dictionary,
    for ``<include filename="..."/>`` in a user's scene; ``comment`` goes at the top."""
    lines = ['<?xml version="1.0" encoding="utf-8"?>']
    if comment:
        lines.append(xml_comment(comment))
    lines.append('<scene version="3.0.0">')
    lines += _plugin("bsdf", native, "    ", plugin_id=bsdf_id)
    lines += ["</scene>", ""]
    return "\n".join(lines)


def plugin_dict(fit) -> dict:
    """The ``brdffit`` plugin's dictionary of a (non-native) fit, as ``brdffit.mitsuba_bsdf`` makes it
    but without importing Mitsuba: ``model``, ``channels`` when not 3, and each parameter under its
    name with '.' written '_' (an ``rgb`` for 3 values, a ``float`` for 1)."""
    from ..render.export import PLUGIN, _key

    out: dict = {"type": PLUGIN, "model": fit.model.name}
    if fit.model.channels != 3:
        out["channels"] = int(fit.model.channels)
    for name, v in fit.model.check_params(fit.params).items():
        v = np.asarray(v, np.float64).reshape(-1)
        if v.size not in (1, 3):  # pragma: no cover - parameters are 1 or 3 values (docs/models.md#models)
            raise ValueError(f"{name}: {v.size} values")
        out[_key(name)] = float(v[0]) if v.size == 1 else {"type": "rgb", "value": [float(x) for x in v]}
    return out


def xml_bytes(fit, ext: str, bsdf_id: str) -> bytes:
    """The file of a fit: Mitsuba's own plugin for a ``mitsuba:*`` fit (plain Mitsuba loads it), the
    ``brdffit`` plugin's properties for any other, with a comment that says how to use it."""
    if fit.model.target == "mitsuba":
        native = native_of(fit)
        how = (f"Mitsuba 3's own {native['type']} plugin: loads in any Mitsuba 3 (no brdffit needed); include"
               f' it with <include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>.')
    else:
        native = plugin_dict(fit)
        how = ("Load it with `import brdffit; brdffit.register_mitsuba()` (after mi.set_variant), include it"
               f' with <include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>;'
               " render it like any scene.")
    return native_xml(native, bsdf_id, f"{about(fit)}. {fit.model.citation}. {how}").encode()


def _describe(fit, ext: str) -> str:
    if fit.model.target == "mitsuba":
        return f"Mitsuba's own {fit.model.native(fit.params)['type']} plugin"
    return '<bsdf type="brdffit">'


#: Any model: a ``mitsuba:*`` fit as Mitsuba's own plugin, any other as the ``brdffit`` plugin.
FORMAT = Format("Mitsuba 3", (".xml",), xml_bytes, _describe)
