"""A fit in any Mitsuba 3 scene (SPEC 8): the ``brdffit`` BSDF plugin and its dict (its XML file is
written by :mod:`brdffit.materials.mitsuba_xml`, with every material format).

The plugin is the symbolic BSDF of :mod:`brdffit.render.symbolic_bsdf`: ``eval`` is the JAX
``model.eval`` the fit was made with, translated to Dr.Jit (one definition of the formula, two
tracers), ``sample``/``pdf`` the lobe mixture of :mod:`brdffit.render.sampling`; where a formula
cannot be translated, the callback BSDF of :mod:`brdffit.render.bsdf` (render those scenes inside
:func:`brdffit.evaluated_calls`). Its properties are the model name and the parameters, each under
its SPEC name with ``.`` written ``_`` (Mitsuba reserves the dot: ``ggx1.ks`` -> ``ggx1_ks``)::

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
    """Constructor of the ``brdffit`` plugin: the model in ``props`` as a :mod:`symbolic_bsdf` (its JAX
    formula run by Dr.Jit), or the callback BSDF where the formula cannot be translated."""
    from .. import models
    from .bsdf import _callback_class, model_brdf
    from .sampling import Mixture

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
    params = model.check_params({by_key[k]: np.asarray(props[k], np.float64).reshape(-1) for k in by_key})
    from .._mitsuba import user_mitsuba
    from .drjit_formula import Unsupported
    from .symbolic_bsdf import symbolic_bsdf

    mixture = Mixture.for_model(model, params)
    try:  # the formula run by Dr.Jit: renders in any mode, no evaluated_calls() needed
        return symbolic_bsdf(model, {k: np.asarray(v) for k, v in params.items()}, mixture,
                             f"brdffit:{model.name}", props=props)
    except Unsupported as exc:  # a formula the translation does not cover: the JAX callback
        mi = user_mitsuba()
        _refuse_unless_evaluated(mi, model, exc)
        cls = _callback_class(mi.variant())
        return cls(props, brdf=model_brdf(model, params), label=f"brdffit:{model.name}", mixture=mixture)


def _refuse_unless_evaluated(mi, model, why) -> None:
    """The callback BSDF answers only inside ``brdffit.evaluated_calls()`` (Dr.Jit's symbolic mode
    cannot call Python with arrays; it traces the BSDF and gets zeros): a scene made outside it gets
    one clear error naming the context, at load time, instead of rendering black without a word."""
    from .._mitsuba import in_evaluated_calls

    if mi.variant().startswith("scalar") or in_evaluated_calls():
        return  # scalar variants and evaluated calls run the callback
    raise ValueError(f"brdffit BSDF ({model.name}): its formula cannot run in Dr.Jit's symbolic mode ({why}); "
                     "load and render scenes that hold it inside brdffit.evaluated_calls()")


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
    """The callback BSDF of parameter *maps*: each parameter a value, or an (H, W) / (H, W, size)
    array over the surface's uv. Texel (row i, column j) covers u in [j/W, (j+1)/W) and v in
    [i/H, (i+1)/H): the layout of Mitsuba's own ``bitmap`` texture (nearest lookup, no filtering).
    The formula is the JAX ``model.eval`` per texel; sampling follows the mixture of the map's mean
    parameters (a valid density everywhere; best where texels are alike)."""
    import jax
    import jax.numpy as jnp

    from .. import models
    from ..fitting.model_eval import CHUNK, SMALL
    from .bsdf import callback_bsdf, import_native
    from .sampling import Mixture

    model = models.get(model)
    shapes = {np.shape(v)[:2] for v in params.values() if np.ndim(v) >= 2}
    if len(shapes) != 1:
        raise ValueError(f"parameter maps must share one (H, W) shape, got {sorted(shapes)}")
    (height, width), = shapes
    flat = {}
    for p in model.params:
        if p.name not in params:
            raise ValueError(f"model {model.name!r}: missing parameter {p.name!r}")
        v = np.asarray(params[p.name], np.float64)
        size = model.size(p)
        v = v.reshape(height, width, -1) if v.ndim >= 2 else v.reshape(1, 1, -1)
        flat[p.name] = np.broadcast_to(v, (height, width, size)).reshape(height * width, size)
    mean = {k: v.mean(axis=0) for k, v in flat.items()}
    import_native()
    per_lane = jax.jit(jax.vmap(lambda q, a, b: model.eval(q, a[None], b[None])[0]))

    def uv_brdf(wi, wo, uv):
        col = np.clip(np.floor(uv[:, 0] * width), 0, width - 1).astype(np.int64)
        row = np.clip(np.floor(uv[:, 1] * height), 0, height - 1).astype(np.int64)
        texel = row * width + col
        n = len(texel)
        out = np.empty((n, model.channels))
        length = SMALL if n <= SMALL else CHUNK  # two compiled shapes, as for a single parameter set
        for start in range(0, n, length):
            stop = min(n, start + length)
            idx = np.zeros(length, np.int64)
            idx[: stop - start] = texel[start:stop]
            a = np.tile([0.0, 0.0, 1.0], (length, 1))
            b = a.copy()
            a[: stop - start], b[: stop - start] = wi[start:stop], wo[start:stop]
            q = {k: jnp.asarray(v[idx]) for k, v in flat.items()}
            out[start:stop] = np.asarray(per_lane(q, jnp.asarray(a), jnp.asarray(b)))[: stop - start]
        return np.broadcast_to(out, (n, 3)) if out.shape[1] == 1 else out[:, :3]

    return callback_bsdf(None, f"brdffit:{model.name} (maps {height}x{width})", Mixture.for_model(model, model.check_params(mean)),
                         uv_brdf=uv_brdf)


def mitsuba_bsdf(model_or_fit, params=None):
    """A BSDF for ``mi.load_dict`` rendering ``model_or_fit`` (a FitResult, or a model name /
    Model with ``params``) in any Mitsuba 3 scene: the ``brdffit`` plugin's dict (registered here
    for the current variant). With parameter *maps* (any value an (H, W) or (H, W, size) array,
    e.g. a per-texel BTF fit) it is a BSDF object instead, looked up by uv (see :func:`map_bsdf`);
    it goes into a scene dict the same way. Render scenes that hold parameter maps inside
    :func:`brdffit.evaluated_calls` (the maps are looked up per texel by JAX)."""
    if not hasattr(model_or_fit, "params") and _is_map(params):
        return map_bsdf(model_or_fit, params)
    model, values = _model_and_params(model_or_fit, params)
    if model.target == "mitsuba":  # a native fit is Mitsuba's own plugin (SPEC 8, 13)
        return model.native(values)
    register_mitsuba()
    out: dict = {"type": PLUGIN, "model": model.name}
    if model.channels != 3:
        out["channels"] = int(model.channels)
    for name, v in values.items():
        out[_key(name)] = float(v[0]) if v.size == 1 else [float(x) for x in v]
    return out
