"""The ``brdffit`` plugin's BSDF: an analytic model's own formula, rendered by Mitsuba in any variant (docs/materials.md#a-fit-in-any-mitsuba-scene).

``eval`` runs the model's JAX formula translated to straight-line code (:mod:`brdffit.render.drjit_formula`):
on Dr.Jit arrays in the JIT variants -- Mitsuba's default symbolic mode, no
``brdffit.evaluated_calls()``, no Python per sample, Mitsuba's own speed and memory, parameters that
``mi.traverse`` exposes and ``prb`` differentiates -- and on Python floats in the scalar variants.
``sample``/``pdf`` draw from the model's lobe mixture (:mod:`brdffit.render.sampling`).

Colour. The formula is traced for the variant's spectrum (3 RGB channels, 4 sampled wavelengths, 1
for mono) and every 3-channel parameter is turned into that spectrum the way Mitsuba's own plugins
turn an RGB property into one (an ``srgb`` spectrum): as it is in RGB variants, its luminance in mono
variants, and in spectral variants the smooth spectrum of Jakob and Hanika's upsampling
(``mi.srgb_model_fetch``/``srgb_model_eval``) evaluated at the ray's wavelengths -- of the colour
divided by its largest channel where that exceeds 1, times that scale (Mitsuba's upsampling is of
reflectances; it clips above 1). Formulas are channel-separable (``Model``'s contract), so each
wavelength sees the formula at that wavelength's parameter values. Polarized variants get the
depolarizing Mueller matrix of that spectrum, as Mitsuba's unpolarized plugins return.

Parameters. Each parameter is a number (or RGB triple) or a Mitsuba texture (parameter maps: a
``bitmap``; any texture a scene nests): ``mi.traverse`` keys are the parameter names with ``.`` written
``_`` -- a number's value itself (an RGB triple in RGB variants, like ``srgb``'s ``value``: the
upsampling coefficients in spectral variants, the luminance in mono), a texture's own keys below it
(``kd.data``).

Conventions at the boundary (docs/conventions.md#conventions): in Mitsuba's ``eval(ctx, si, wo)`` ``si.wi`` points to the
camera (our ``wo``) and ``wo`` to the light (our ``wi``); Mitsuba's ``eval`` returns f_r cos(theta_light).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np


def _key(name: str) -> str:
    return name.replace(".", "_")


@dataclasses.dataclass(frozen=True)
class Texture:
    """A parameter given as a Mitsuba texture (a parameter map, a texture a scene nests), whose values
    are multiplied by ``scale`` (maps above 1 are stored divided by their largest value: see the
    module docstring)."""

    texture: object
    scale: float = 1.0


@functools.cache
def _symbolic_class(variant: str):
    from .sampling import bsdf_class_setup

    mi, dr, scalar, sampling = bsdf_class_setup(variant)
    channels = dr.size_v(mi.UnpolarizedSpectrum)  # 3 RGB, 4 wavelengths, 1 mono
    spectral, mono, polarized = mi.is_spectral, mi.is_monochromatic, mi.is_polarized
    flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide

    def colour_value(rgb):
        """A constant RGB parameter as this variant stores it, and its scale (see the module docstring)."""
        rgb = np.asarray(rgb, np.float64)
        if mono:
            return [float(np.asarray(mi.luminance(mi.ScalarColor3f(*rgb))).reshape(-1)[0])], 1.0
        if not spectral:
            return [float(x) for x in rgb], 1.0
        scale = max(1.0, float(rgb.max()))
        return [float(x) for x in mi.srgb_model_fetch(mi.ScalarColor3f(*(rgb / scale)))], scale

    class SymbolicBSDF(mi.BSDF):
        """An analytic model's f_r computed from its translated JAX formula (see the module docstring)."""

        def __init__(self, props, model=None, params=None, formula=None, mixture=None, label="brdffit"):
            mi.BSDF.__init__(self, props)
            self.model, self.mixture, self.label = model, mixture, label
            self.m_flags = flags
            self.m_components = [flags]
            #: per parameter in model order: (name, "constant" | "colour" | "texture", scale)
            self.kinds = []
            #: parameter name -> its values (Dr.Jit Float, or Python floats in scalar variants), or a Texture
            self.values = {}
            for p in model.params:
                value = params[p.name]
                if isinstance(value, Texture):
                    self.kinds.append((p.name, "texture", value.scale))
                    self.values[p.name] = value.texture
                    continue
                value = np.asarray(value, np.float64).reshape(-1)
                colour = model.size(p) == 3
                stored, scale = colour_value(value) if colour else ([float(value[0])], 1.0)
                self.kinds.append((p.name, "colour" if colour else "constant", scale))
                self.values[p.name] = stored if scalar else mi.Float(np.asarray(stored, np.float32))
            self._formula = formula.scalar if scalar else formula.jit(mi.Float)

        def _cells(self, si, active):
            """Every parameter's value per channel of the variant, in model order (formula arguments)."""
            cells = []
            for name, kind, scale in self.kinds:
                v = self.values[name]
                if kind == "texture":
                    if self.model.size(self.model.param(name)) == 1:
                        cells.append(v.eval_1(si, active) * scale)
                    else:
                        s = v.eval(si, active)
                        cells += [s[i] * scale for i in range(channels)]
                elif kind == "colour" and spectral:
                    coeff = v if scalar else [dr.gather(mi.Float, v, i) for i in range(3)]
                    s = mi.srgb_model_eval((mi.ScalarArray3f if scalar else mi.Array3f)(*coeff), si.wavelengths)
                    cells += [s[i] * scale for i in range(channels)]
                else:
                    cells += v if scalar else [dr.gather(mi.Float, v, i) for i in range(dr.width(v))]
            return cells

        def _eval_cos(self, si, wo, active):
            if scalar:
                cos_l, cos_v = wo.z, si.wi.z
                if not (active and cos_l > 0 and cos_v > 0):
                    return dr.zeros(mi.Spectrum)
                f = self._formula(*self._cells(si, active), wo.x, wo.y, cos_l, si.wi.x, si.wi.y, cos_v)
                value = mi.UnpolarizedSpectrum(*(x * cos_l for x in (f * channels if len(f) == 1 else f)))
                return mi.depolarizer(value) if polarized else value
            cos_l = mi.Frame3f.cos_theta(wo)
            up = active & (cos_l > 0) & (mi.Frame3f.cos_theta(si.wi) > 0)
            f = self._formula(*self._cells(si, up), wo.x, wo.y, wo.z, si.wi.x, si.wi.y, si.wi.z)
            value = dr.select(up, mi.UnpolarizedSpectrum(*(f * channels if len(f) == 1 else f)) * cos_l, 0.0)
            return mi.depolarizer(value) if polarized else value

        def eval(self, ctx, si, wo, active=True):
            return self._eval_cos(si, wo, active)

        pdf, eval_pdf, sample = sampling.pdf, sampling.eval_pdf, sampling.sample

        def traverse(self, callback):
            if scalar:
                return
            for name, kind, _ in self.kinds:
                callback.put(_key(name), self.values[name], mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys=None):
            pass  # eval reads self.values each time

        def to_string(self):
            return f"SymbolicBSDF[{self.label}; {self.mixture!r}]"

    return SymbolicBSDF


def formula_channels(model, variant_channels: int) -> int:
    """The channel count to translate ``model``'s formula for: a one-channel model (monochrome data)
    stays one channel, every other one takes the variant's spectrum."""
    return 1 if model.channels == 1 else variant_channels


def symbolic_bsdf(model, params, mixture, label: str, props=None):
    """A Mitsuba BSDF object (current variant) evaluating ``model`` at ``params`` -- each a value or
    a :class:`Texture` -- from its translated formula, sampled by ``mixture``; raises
    ``drjit_formula.Unsupported`` when the formula cannot be translated."""
    import drjit as dr

    from .._mitsuba import user_mitsuba
    from .drjit_formula import drjit_formula

    mi = user_mitsuba()
    formula = drjit_formula(model, formula_channels(model, dr.size_v(mi.UnpolarizedSpectrum)))
    cls = _symbolic_class(mi.variant())
    return cls(props if props is not None else mi.Properties(), model=model, params=params, formula=formula,
               mixture=mixture, label=label)
