"""Parameter maps of a ``mitsuba:*`` model as Mitsuba 3's own plugin with ``bitmap`` textures.

Which properties a plugin takes as a texture (Mitsuba 3.9.1, ``src/bsdfs/*.cpp``: those read with
``props.get_texture`` or ``get_unbounded_texture``; every other property is one number):

- ``roughconductor``: alpha (and alpha_u, alpha_v), eta, k, specular_reflectance: every fitted
  parameter, so every ``mitsuba:roughconductor`` map exports.
- ``roughplastic``: diffuse_reflectance and specular_reflectance. **alpha and int_ior are numbers**:
  the plugin precomputes its rough-interface transmittance table for one alpha and one eta.
- ``principled``: base_color, roughness, metallic, anisotropic, sheen, clearcoat, clearcoat_gloss
  (and spec_tint, sheen_tint, spec_trans, flatness). **specular (and eta) is a number**.

Where a map cannot be a texture: a map whose texels all hold one value (within float32 precision)
is written as that number; a map that varies is refused, one line naming the parameter (no other
Mitsuba plugin evaluates the same BRDF with that parameter varying, so there is nothing exact to
map it to; hold it in the fit instead: ``fit_btf(..., fixed={"alpha": value})``). Uniform maps of
the other parameters are written as numbers too; the settings that are no parameters
(``distribution`` ggx, ``ext_ior``, ``nonlinear``, the tints) are what ``model.native`` writes.

Textures: one 32-bit float OpenEXR per varying map, ``<parameter>.exr`` in the textures folder
(``R,G,B`` for three-channel parameters, ``Y`` for the others), referenced by relative path from
the XML. Each is a ``bitmap`` with ``filter_type`` nearest and the default ``wrap_mode`` repeat;
``raw`` true for the data maps (alpha, eta, k and principled's scalars: no colour transform, no
warning for values above 1), false for the reflectances (linear already; a spectral variant
upsamples them as any reflectance texture). The texel layout is the one of
:mod:`brdffit.materials.textured`: maps row 0 is the textures' top row, at v = 0 in Mitsuba.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

#: Mitsuba 3.9.1: the properties of each plugin that are textures (see the module docstring).
TEXTURED = {
    "roughconductor": ("alpha", "alpha_u", "alpha_v", "eta", "k", "specular_reflectance"),
    "roughplastic": ("diffuse_reflectance", "specular_reflectance"),
    "principled": ("base_color", "roughness", "metallic", "anisotropic", "sheen", "clearcoat", "clearcoat_gloss",
                   "spec_tint", "sheen_tint", "spec_trans", "flatness"),
}
#: Textures holding reflectances (colour data); the others are raw data.
COLOURS = ("diffuse_reflectance", "specular_reflectance", "base_color")


def plan(model, arrays: dict[str, np.ndarray], folder: str, source=None) -> dict:
    """The plugin's ``mi.load_dict`` dictionary for the maps: ``model.native`` of the maps' means,
    each varying map replaced by its ``bitmap`` texture (file ``folder/<name>.exr``); one
    ``InputError`` naming ``source`` and the parameter where the plugin takes a varying map as one
    number."""
    from .textures import uniform_value

    values, varying = {}, []
    for p in model.params:
        one = uniform_value(arrays[p.name])
        if one is None:
            varying.append(p.name)
            one = arrays[p.name].mean(axis=(0, 1))
        values[p.name] = np.clip(one, p.lower, p.upper)  # a float32 texel at a bound, read in float64
    native = model.native(values)
    for name in varying:
        if name not in TEXTURED[native["type"]]:
            a = arrays[name]
            raise InputError(source, f"cannot export {model.name} maps to Mitsuba: {name} varies over the texels "
                                     f"({a.min():.4g} to {a.max():.4g}) and Mitsuba 3's {native['type']} plugin takes "
                                     f"{name} as one number, not a texture (hold it in the fit: "
                                     f"fit_btf(..., fixed={{{name!r}: value}}))")
        native[name] = {"type": "bitmap", "filename": f"{folder}/{name}.exr", "filter_type": "nearest",
                        "raw": name not in COLOURS}
    return native


def write_textures(native: dict, arrays: dict[str, np.ndarray], folder: Path) -> None:
    """The OpenEXR file of every ``bitmap`` texture of ``native`` (:func:`plan`), written into ``folder``."""
    from .textures import write_exr

    for name, value in native.items():
        if isinstance(value, dict) and value.get("type") == "bitmap":
            write_exr(folder / Path(value["filename"]).name, arrays[name])


def xml_text(native: dict, bsdf_id: str, model, extras: dict) -> str:
    """The scene-XML fragment: one ``<bsdf>`` of Mitsuba's own plugin with its ``<texture>``s."""
    from .mitsuba_xml import native_xml

    about = extras["brdffit"]
    h, w = about["texels"]
    source = f" from {about['source']}" if about["source"] else ""
    comment = (f"brdffit per-texel fit: {model.name} maps, {h} x {w} texels ({about['loss']} loss, "
               f"{100 * about['converged_share']:.1f} % converged){source}. "
               f"{model.citation}. Mitsuba 3's own {native['type']} plugin with bitmap textures: loads in any "
               "Mitsuba 3 (no brdffit needed); the texture files are named relative to this file's folder. Texel "
               "(row r, column c) covers u in [c/W, (c+1)/W), v in [r/H, (r+1)/H). Include it with "
               f'<include filename="THIS FILE"/> and refer to it with <ref id="{bsdf_id}"/>.')
    return native_xml(native, bsdf_id, comment)
