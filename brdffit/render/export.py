"""A fit in any Mitsuba 3 scene (docs/materials.md#a-fit-in-any-mitsuba-scene): the ``brdffit`` BSDF plugin and its dict (its XML file is
written by :mod:`brdffit.materials.mitsuba_xml`, with every material format).

The plugin is the symbolic BSDF of :mod:`brdffit.render.symbolic_bsdf`: ``eval`` is the JAX
``model.eval`` the fit was made with, translated for Dr.Jit and for Python floats (one definition of
the formula, two tracers), ``sample``/``pdf`` the lobe mixture of :mod:`brdffit.render.sampling`; it
renders in every variant (RGB, spectral, mono, polarized; scalar and JIT) and mode. A ``mitsuba:*``
model is Mitsuba's own plugin (docs/materials.md#native-materials-and-exports), also when named in a ``brdffit`` plugin. Its properties are the model name and the parameters, each under
its parameter name (docs/models.md#models) with ``.`` written ``_`` (Mitsuba reserves the dot: ``ggx1.ks`` -> ``ggx1_ks``), each
a number, an RGB triple, a spectrum or a nested texture, as Mitsuba's own plugins take them::

    <bsdf type="brdffit" id="paint">
        <string name="model" value="ggx"/>
        <rgb name="kd" value="0.31, 0.24, 0.2"/>
        <rgb name="ks" value="0.5, 0.5, 0.5"/>
        <float name="alpha" value="0.12"/>
        <float name="f0" value="0.04"/>
    </bsdf>

Using it (the plugin must be registered for the Mitsuba variant in use)::

    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    import brdffit                      # registers "brdffit" when a variant is already set
    brdffit.register_mitsuba()          # otherwise (after choosing the variant): does the same
    scene = mi.load_file("scene.xml")   # holds <include filename="bsdf.xml"/> and <ref id="..."/>
    image = mi.render(scene, spp=64)

or, from Python, ``mi.load_dict({..., "bsdf": fit.to_mitsuba()})``.
"""

from __future__ import annotations

import re

import numpy as np

#: The plugin name scenes use: ``<bsdf type="brdffit">``, ``{"type": "brdffit"}``.
PLUGIN = "brdffit"
_REGISTERED: set[str] = set()


def _key(name: str) -> str:
    return name.replace(".", "_")


def _model_and_params(model_or_fit, params):
    from .. import models

    if hasattr(model_or_fit, "model") and hasattr(model_or_fit, "params"):  # a FitResult
        if params is not None:
            raise TypeError("give params only with a model name, not with a fit")
        model, params = models.get(model_or_fit.model), model_or_fit.params
    else:
        if params is None:
            raise TypeError("mitsuba_bsdf(model, params=...) needs the parameters")
        model = models.get(model_or_fit)
    checked = model.check_params(params)
    return model, {k: np.asarray(v, np.float64).reshape(-1) for k, v in checked.items()}


def _plugin(props):
    """Constructor of the ``brdffit`` plugin: the model in ``props`` (each parameter a number, an RGB
    triple, a spectrum or a nested texture) as :func:`model_bsdf` makes it."""
    from .. import models
    from .._mitsuba import user_mitsuba
    from .symbolic_bsdf import Texture

    mi = user_mitsuba()
    names = [str(k) for k in props.keys()]
    if "model" not in names:
        raise ValueError("brdffit BSDF: needs a string property 'model' (e.g. <string name=\"model\" value=\"ggx\"/>)")
    model = models.get(str(props["model"]))
    channels = int(props["channels"]) if "channels" in names else 3
    if channels != model.channels:
        model = model.with_channels(channels)
    by_key = {_key(n): n for n in model.param_names}
    unknown = sorted(set(names) - set(by_key) - {"model", "channels", "id"})
    if unknown:
        raise ValueError(f"brdffit BSDF ({model.name}): unknown properties {unknown}; parameters are {sorted(by_key)}")
    missing = sorted(k for k in by_key if k not in names)
    if missing:
        raise ValueError(f"brdffit BSDF ({model.name}): missing parameters {missing}")
    params = {}
    for key, name in by_key.items():
        value = props[key]
        if isinstance(value, mi.Texture):
            params[name] = Texture(value)
        elif props.type(key) == mi.Properties.Type.Spectrum:  # a spectrum, read as Mitsuba's own plugins read one
            params[name] = Texture(props.get_texture(key))
        else:
            params[name] = np.asarray(value, np.float64).reshape(-1)
    return model_bsdf(model, params, props)


def model_bsdf(model, params, props=None):
    """The one Mitsuba BSDF of an analytic model, for validation and for users alike: Mitsuba's own
    plugin for a ``mitsuba:*`` model (docs/materials.md#native-materials-and-exports), otherwise the symbolic BSDF of
    :mod:`brdffit.render.symbolic_bsdf` -- the model's formula translated, in any variant and mode.
    ``params`` maps each parameter to its values or a ``symbolic_bsdf.Texture``; the sampling
    mixture follows the textures' mean values."""
    from .._mitsuba import user_mitsuba
    from .sampling import Mixture
    from .symbolic_bsdf import Texture, symbolic_bsdf

    mi = user_mitsuba()
    textures = {k: v for k, v in params.items() if isinstance(v, Texture)}
    means = {k: np.full(model.size(model.param(k)), float(np.mean(v.texture.mean())) * v.scale) for k, v in textures.items()}
    checked = {k: np.asarray(v, np.float64) for k, v in model.check_params({**params, **means}).items()}
    if model.target == "mitsuba":
        native = model.native(checked)
        for name, tex in textures.items():
            if name not in native or tex.scale != 1.0:
                raise ValueError(f"{model.name}: Mitsuba's {native['type']} plugin takes no texture for {name!r}")
            native[name] = tex.texture
        try:
            return mi.load_dict(native)
        except RuntimeError as exc:  # a property the plugin reads as one number (roughplastic's alpha)
            found = re.search(r'The property "(\w+)" has the wrong type', str(exc))
            if found is None:
                raise
            raise ValueError(f"{model.name}: Mitsuba's {native['type']} plugin takes one number for "
                             f"{found.group(1)!r}, not a map (hold it fixed in the fit)") from None
    values = {k: textures.get(k, checked[k]) for k in params}
    return symbolic_bsdf(model, values, Mixture.for_model(model, checked), f"brdffit:{model.name}", props=props)


def register_mitsuba() -> str:
    """Register the ``brdffit`` BSDF plugin for the current Mitsuba variant (brdffit's when none is
    set); returns the variant. Idempotent."""
    from .._mitsuba import user_mitsuba

    mi = user_mitsuba()
    variant = mi.variant()
    if variant not in _REGISTERED:
        mi.register_bsdf(PLUGIN, _plugin)
        _REGISTERED.add(variant)
    return variant


def register_if_loaded() -> None:
    """Register the plugin when Mitsuba is already imported with a variant set (``import brdffit``)."""
    import sys

    mi = sys.modules.get("mitsuba")
    try:
        if mi is not None and mi.variant() is not None:
            register_mitsuba()
    except Exception:  # noqa: BLE001 - never let a user's half-configured Mitsuba break `import brdffit`
        pass


def _is_map(params) -> bool:
    return params is not None and any(np.ndim(v) >= 2 for v in params.values())


def map_bsdf(model, params):
    """The BSDF of parameter *maps*: each parameter a value, or an (H, W) / (H, W, size) array over the
    surface's uv, as a Mitsuba ``bitmap`` texture (nearest lookup, no filtering; 3-channel maps are
    upsampled like any colour texture, 1-channel ones read raw; a map of one value is that number). Texel (row i, column j) covers u in
    [j/W, (j+1)/W) and v in [i/H, (i+1)/H): the layout of Mitsuba's own ``bitmap`` texture. The
    formula is the model's translated one (:func:`model_bsdf`); sampling follows the mixture of the
    map's mean parameters (a valid density everywhere; best where texels are alike)."""
    from .. import models
    from .._mitsuba import user_mitsuba
    from .symbolic_bsdf import Texture

    mi = user_mitsuba()
    model = models.get(model)
    shapes = {np.shape(v)[:2] for v in params.values() if np.ndim(v) >= 2}
    if len(shapes) != 1:
        raise ValueError(f"parameter maps must share one (H, W) shape, got {sorted(shapes)}")
    (height, width), = shapes
    values = {}
    for p in model.params:
        if p.name not in params:
            raise ValueError(f"model {model.name!r}: missing parameter {p.name!r}")
        v = np.asarray(params[p.name], np.float64)
        if v.ndim < 2:
            values[p.name] = v.reshape(-1)
            continue
        size = model.size(p)
        data = np.broadcast_to(v.reshape(height, width, -1), (height, width, size))
        if np.all(data.astype(np.float32) == data.astype(np.float32)[:1, :1]):  # one value: a number
            values[p.name] = data[0, 0]
            continue
        # Mitsuba upsamples reflectances: a map above 1 is stored divided by its largest value
        scale = max(1.0, float(data.max())) if size == 3 else 1.0
        texture = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(data / scale, np.float32)),
                                "raw": size == 1, "filter_type": "nearest", "wrap_mode": "clamp"})
        values[p.name] = Texture(texture, scale)
    return model_bsdf(model, values)


def mitsuba_bsdf(model_or_fit, params=None):
    """A BSDF for ``mi.load_dict`` rendering ``model_or_fit`` (a FitResult, or a model name /
    Model with ``params``) in any Mitsuba 3 scene: the ``brdffit`` plugin's dict (registered here
    for the current variant). With parameter *maps* (any value an (H, W) or (H, W, size) array,
    e.g. a per-texel BTF fit) it is a BSDF object instead, the maps as textures (see :func:`map_bsdf`);
    it goes into a scene dict the same way and renders in any variant and mode like the plugin."""
    if not hasattr(model_or_fit, "params") and _is_map(params):
        return map_bsdf(model_or_fit, params)
    model, values = _model_and_params(model_or_fit, params)
    if model.target == "mitsuba":  # a native fit is Mitsuba's own plugin (docs/materials.md#a-fit-in-any-mitsuba-scene and docs/materials.md#native-materials-and-exports)
        return model.native(values)
    register_mitsuba()
    out: dict = {"type": PLUGIN, "model": model.name}
    if model.channels != 3:
        out["channels"] = int(model.channels)
    for name, v in values.items():
        out[_key(name)] = float(v[0]) if v.size == 1 else [float(x) for x in v]
    return out
