"""The ``brdffit`` plugin's BSDF for analytic models: the fit's own formula, run by Dr.Jit (SPEC 8).

``eval`` runs the model's JAX formula translated to Dr.Jit (:mod:`brdffit.render.drjit_formula`),
so the BSDF renders in Mitsuba's default symbolic mode -- no ``brdffit.evaluated_calls()``, no Python
per sample, Mitsuba's own speed and memory -- in every variant, and its parameters are Dr.Jit values
that ``mi.traverse`` exposes and ``prb`` differentiates (keys: the parameter names, ``.`` written
``_``). ``sample``/``pdf`` follow the same lobe mixture as the callback BSDF
(:mod:`brdffit.render.sampling`).

Conventions at the boundary (SPEC 1): in Mitsuba's ``eval(ctx, si, wo)`` ``si.wi`` points to the
camera (our ``wo``) and ``wo`` to the light (our ``wi``); Mitsuba's ``eval`` returns f_r cos(theta_light).
"""

from __future__ import annotations

import functools

import numpy as np


def _key(name: str) -> str:
    return name.replace(".", "_")


@functools.cache
def _symbolic_class(variant: str):
    from .bsdf import bsdf_class_setup

    mi, dr, scalar, sampling = bsdf_class_setup(variant)

    class SymbolicBSDF(mi.BSDF):
        """An analytic model's f_r computed by Dr.Jit from its (translated) JAX formula."""

        def __init__(self, props, model=None, params=None, formula=None, mixture=None, label="brdffit"):
            mi.BSDF.__init__(self, props)
            self.model, self.formula, self.mixture, self.label = model, formula, mixture, label
            #: parameter name -> Dr.Jit Float of its values (width 1 or 3): what traverse exposes
            self.values = {p.name: mi.Float(np.asarray(params[p.name], np.float32).reshape(-1)) if not scalar
                           else [float(x) for x in np.asarray(params[p.name]).reshape(-1)] for p in model.params}
            self.m_flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def _params(self):
            if scalar:
                return self.values
            return {name: [dr.gather(mi.Float, v, i) for i in range(dr.width(v))] for name, v in self.values.items()}

        def _eval_cos(self, si, wo, active):
            light = (wo.x, wo.y, wo.z)
            view = (si.wi.x, si.wi.y, si.wi.z)
            f = self.formula(self._params(), light, view)
            if len(f) == 1:
                f = f * 3
            cos_l = mi.Frame3f.cos_theta(wo)
            up = active & (cos_l > 0) & (mi.Frame3f.cos_theta(si.wi) > 0)
            value = mi.Color3f(f[0] * cos_l, f[1] * cos_l, f[2] * cos_l)
            return dr.select(up, value, mi.Color3f(0.0))

        def eval(self, ctx, si, wo, active=True):
            return self._eval_cos(si, wo, active)

        pdf, eval_pdf, sample = sampling.pdf, sampling.eval_pdf, sampling.sample

        def traverse(self, callback):
            if scalar:
                return
            for name, v in self.values.items():
                callback.put(_key(name), v, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys=None):
            pass  # eval reads self.values each time

        def to_string(self):
            return f"SymbolicBSDF[{self.label}; {self.mixture!r}]"

    return SymbolicBSDF


def symbolic_bsdf(model, params, mixture, label: str, props=None):
    """A Mitsuba BSDF object evaluating ``model`` at ``params`` with Dr.Jit (see the module
    docstring); raises ``drjit_formula.Unsupported`` when the formula cannot be translated."""
    from .._mitsuba import user_mitsuba
    from .drjit_formula import drjit_formula

    mi = user_mitsuba()
    formula = drjit_formula(model)
    cls = _symbolic_class(mi.variant())
    return cls(props if props is not None else mi.Properties(), model=model, params=params, formula=formula,
               mixture=mixture, label=label)
