"""A native model's dictionary (``model.native(params)``) as a Mitsuba 3 scene-XML fragment.

Mitsuba's XML and ``mi.load_dict`` describe the same objects: a plugin ``type`` and named
properties. This writes the dictionary that ``mitsuba:*`` models return (the renderer's own
``roughconductor``, ``roughplastic`` or ``principled`` plugin, every setting written out) so that a
plain Mitsuba, in a process that never imports brdffit, loads it::

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


def _attr(value: str) -> str:
    return html.escape(str(value), quote=True)


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
        # XML comments may not hold "--"
        lines.append("<!-- " + comment.replace("--", "- -") + " -->")
    lines.append('<scene version="3.0.0">')
    lines += _plugin("bsdf", native, "    ", plugin_id=bsdf_id)
    lines += ["</scene>", ""]
    return "\n".join(lines)
