"""BRDF sources as Mitsuba BSDFs, with one definition per formula.

Three kinds of source (docs/validation.md#validation-rendering):

- an analytic model (a FitResult, or a ``(model_name, params)`` pair): the very BSDF a user gets
  from ``fit.to_mitsuba()`` (:func:`brdffit.render.export.model_bsdf`): Mitsuba's own plugin for a
  ``mitsuba:*`` fit, otherwise the model's JAX formula translated for Mitsuba
  (:mod:`brdffit.render.symbolic_bsdf`). What is validated is what users render.
- a UBO-81 ``Measurement``: :class:`CallbackBSDF`, a Python ``mi.BSDF`` whose ``eval`` hands
  Mitsuba's direction arrays to the NumPy interpolator of :mod:`brdffit.render.tabulated`.
- an RGL ``.bsdf`` file: Mitsuba's built-in ``measured`` plugin, the full-resolution reference.

How the callback works. Mitsuba dispatches ``bsdf.eval`` through a Dr.Jit virtual call. With
``JitFlag.SymbolicCalls`` off (set by :func:`evaluated_calls`) the call is *evaluated*: Dr.Jit runs
the kernel up to the call, hands the Python method concrete arrays holding only the lanes that
reached this BSDF, and the method may leave Dr.Jit (to NumPy) and come back. In the ``scalar_rgb``
fallback every sample calls the method with scalars: correct, but slow.

Conventions at the boundary (docs/conventions.md#conventions): in Mitsuba's ``eval(ctx, si, wo)``, ``si.wi`` points to the
camera (our ``wo``, the view) and ``wo`` points to the light (our ``wi``), both in the local
shading frame; Mitsuba's ``eval`` returns f_r * cos(theta_light). The callback here and the symbolic
BSDF (:mod:`brdffit.render.symbolic_bsdf`) are the only places that convert between the two.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._mitsuba import evaluated_calls  # noqa: F401 - importable from here
# f_r of an analytic model: the one evaluator (fitting.model_eval, FitResult.eval's too); of any
# Mitsuba BSDF outside a render: .evaluate (eval_bsdf stays importable from here, with evaluated_calls).
from ..fitting.model_eval import eval_model, warm
from .evaluate import eval_bsdf  # noqa: F401

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


#: f_r(wi = towards light, wo = towards viewer) in the local frame -> (N, 3) in 1/sr, NumPy.
BrdfFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


#: Seconds each model compilation took (in the background), for the time report of a validation.
COMPILE_SECONDS: list[float] = []


@functools.cache
def import_native() -> None:
    """Import the native extensions rendering and validation use (Mitsuba / Dr.Jit, FLIP, OpenEXR)
    in the calling thread, before this package starts any background thread.

    A first import of a nanobind extension while another thread runs nanobind code (JAX compiling
    in the background) once failed with "SystemError: <built-in function __import__> returned a
    result with an exception set"; importing them up front removes the race. Mitsuba keeps the
    caller's variant when one is set (a user's own scene loading the ``brdffit`` plugin).
    """
    from .._mitsuba import user_mitsuba

    user_mitsuba()
    import flip_evaluator  # noqa: F401
    import OpenEXR  # noqa: F401


def model_brdf(model, params) -> BrdfFn:
    """NumPy f_r of an analytic model: ``model.eval`` through the one evaluator
    (``fitting.model_eval``: compiled once per model and chunk length, kept on disk), channels
    broadcast to 3. Its program is compiled or loaded in the background from here on (``warm``)."""
    params = model.check_params(params)
    import_native()  # before the compile thread below starts
    warm(model, COMPILE_SECONDS.append)

    def brdf(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        out = eval_model(model, params, wi, wo)
        return np.broadcast_to(out, (out.shape[0], 3)) if out.shape[1] == 1 else out[:, :3]

    return brdf


def _vec_to_numpy(v) -> np.ndarray:
    return np.stack([np.asarray(v.x, np.float64), np.asarray(v.y, np.float64), np.asarray(v.z, np.float64)], -1).reshape(-1, 3)


@functools.cache
def _callback_class(variant: str):
    """The CallbackBSDF class of one Mitsuba variant, defined on first use (it subclasses mi.BSDF)."""
    from .._mitsuba import symbolic_scope
    from .sampling import Mixture, bsdf_class_setup

    mi, dr, scalar, sampling = bsdf_class_setup(variant)

    class CallbackBSDF(mi.BSDF):
        """A reflective RGB BSDF whose f_r is any NumPy function of (wi, wo); see the module docstring.

        ``sample`` and ``pdf`` follow a :class:`~brdffit.render.sampling.Mixture` (cosine-weighted
        unless given); ``eval``, ``pdf`` and ``sample`` agree: a sample's weight is eval / pdf at the
        sampled direction.
        """

        def __init__(self, props, brdf: BrdfFn | None = None, label: str = "callback", mixture=None):
            mi.BSDF.__init__(self, props)
            self.brdf = brdf
            self.label = label
            self.mixture = mixture if mixture is not None else Mixture.cosine()
            self.m_flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def _eval_cos(self, si, wo, active):
            if not scalar and symbolic_scope():
                # Dr.Jit is recording a symbolic call over every registered BSDF, this one included,
                # for a render that runs symbolically: a scene that holds this BSDF renders inside
                # evaluated_calls() and never gets here, so no ray of this one reaches these lanes.
                return dr.zeros(mi.Color3f, max(dr.width(wo), dr.width(si.wi)))
            # Mitsuba: si.wi = view, wo = light. docs/conventions.md#conventions: f_r(light, view) * cos(theta_light).
            if scalar:
                light = np.array([[wo.x, wo.y, wo.z]], np.float64)
                view = np.array([[si.wi.x, si.wi.y, si.wi.z]], np.float64)
            else:
                light, view = _vec_to_numpy(wo), _vec_to_numpy(si.wi)
                n = max(len(light), len(view))  # one of them may be a broadcast single direction
                light, view = np.broadcast_to(light, (n, 3)), np.broadcast_to(view, (n, 3))
            up = (light[:, 2] > 0) & (view[:, 2] > 0)
            value = np.zeros((light.shape[0], 3))
            if up.any():
                f = np.asarray(self.brdf(light[up], view[up]), np.float64)
                # No clean-up of NaN or negative values: the image shows the BRDF as it is (and the
                # tests that every model renders finite, non-negative images mean something).
                value[up] = f * light[up, 2:3]
            if scalar:
                return mi.Color3f(*map(float, value[0])) if active else mi.Color3f(0.0)
            v32 = value.astype(np.float32)
            col = mi.Color3f(mi.Float(v32[:, 0]), mi.Float(v32[:, 1]), mi.Float(v32[:, 2]))
            return dr.select(active, col, mi.Color3f(0.0))

        def eval(self, ctx, si, wo, active=True):
            return self._eval_cos(si, wo, active)

        pdf, eval_pdf, sample = sampling.pdf, sampling.eval_pdf, sampling.sample

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"CallbackBSDF[{self.label}; {self.mixture!r}]"

    return CallbackBSDF


def callback_bsdf(brdf: BrdfFn, label: str = "callback", mixture=None):
    """A Mitsuba BSDF object evaluating ``brdf`` (a NumPy f_r) through :class:`CallbackBSDF`,
    sampled by ``mixture`` (a :class:`~brdffit.render.sampling.Mixture`; cosine when None). Scenes
    holding it render inside :func:`evaluated_calls` (RGB variants)."""
    from .._mitsuba import user_mitsuba

    mi = user_mitsuba()
    return _callback_class(mi.variant())(mi.Properties(), brdf=brdf, label=label, mixture=mixture)


def measured_bsdf(path: str | Path):
    """Mitsuba's built-in ``measured`` plugin for an RGL ``.bsdf`` file, verified before the plugin
    reads it (:func:`brdffit.render.measured.load_measured`)."""
    from ..errors import InputError
    from .measured import load_measured

    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), "no such file")
    return load_measured(path)


class Source:
    """A BRDF to render: its label, its NumPy f_r(wi, wo) and its Mitsuba BSDF (made once).

    Built by :func:`as_source` from a FitResult (anything with ``.model`` and ``.params``), a
    ``(model_name_or_Model, params)`` pair, a UBO-81 ``Measurement``, or a path to an RGL ``.bsdf``
    file (other measurement files are read with ``brdffit.load``).
    """

    def __init__(
        self,
        kind: str,
        label: str,
        brdf: BrdfFn | None = None,
        path: Path | None = None,
        valid: np.ndarray | None = None,
        model=None,
        params=None,
    ):
        self.kind = kind  # "model" | "table" | "rgl"
        self.label = label
        self._brdf = brdf
        self.path = path
        #: (81, 81) bool: the measured UBO entries that are valid (a table source), else None
        self.valid = valid
        #: the analytic model and its parameters (a model source), for the sampling mixture
        self.model, self.params = model, params
        self._bsdf = None

    @property
    def bsdf(self):
        if self._bsdf is None:
            if self.kind == "rgl":
                self._bsdf = measured_bsdf(self.path)
            elif self.model is not None:
                # the BSDF users get from fit.to_mitsuba(): what is validated is what they render
                from .export import model_bsdf

                self._bsdf = model_bsdf(self.model, {k: np.asarray(v, np.float64) for k, v in self.params.items()})
            else:
                self._bsdf = callback_bsdf(self._brdf, self.label)
        return self._bsdf

    def brdf(self, wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> Float[np.ndarray, "N 3"]:
        """f_r(wi = light, wo = view), (N, 3), 1/sr."""
        if self.kind == "rgl":
            from .measured import eval_plugin

            return eval_plugin(self.bsdf, wi, wo)  # as the reader reads the file
        out = np.asarray(self._brdf(np.asarray(wi, np.float64), np.asarray(wo, np.float64)), np.float64)
        return np.broadcast_to(out, (out.shape[0], 3)) if out.shape[1] == 1 else out

    def __repr__(self) -> str:
        return f"Source({self.kind}: {self.label})"


def as_source(obj) -> Source:
    """Interpret any supported BRDF source (see :class:`Source`)."""
    from .. import models
    from ..errors import InputError
    from ..measurement import Measurement
    from .tabulated import UboInterpolator

    if isinstance(obj, Source):
        return obj
    if hasattr(obj, "model") and hasattr(obj, "params"):  # a FitResult (duck-typed)
        model = models.get(obj.model)
        label = model.name if getattr(obj, "converged", True) is not False else f"{model.name} (fit not converged)"
        return Source("model", label, model_brdf(model, obj.params), model=model, params=model.check_params(obj.params))
    if isinstance(obj, tuple) and len(obj) == 2:
        model = models.get(obj[0])
        return Source("model", model.name, model_brdf(model, obj[1]), model=model, params=model.check_params(obj[1]))
    if isinstance(obj, Measurement):
        if obj.grid != "ubo81":
            raise ValueError(
                f"{obj.name}: only a UBO-81 measurement can be rendered as a table (grid={obj.grid!r}); "
                "resample it first with brdffit.resample"
            )
        interp = UboInterpolator.from_measurement(obj)

        def brdf(wi, wo):
            out = interp(wi, wo)
            return np.broadcast_to(out, (out.shape[0], 3)) if out.shape[1] == 1 else out

        valid = (np.asarray(obj.weights) > 0) & np.all(np.isfinite(np.asarray(obj.values)), axis=1)
        return Source("table", obj.name, brdf, valid=valid.reshape(81, 81))
    if isinstance(obj, (str, Path)):
        path = Path(obj)
        if not path.exists():
            raise InputError(str(path), "no such file or folder")
        if path.suffix.lower() == ".bsdf":
            from ..io.rgl import check_tensor_file

            check_tensor_file(path)  # bad input is reported now, before any work
            return Source("rgl", path.stem, path=path)
        from ..io import load, resample

        m = load(path)
        if m.grid != "ubo81":
            m = resample(m, grid="ubo81")
        src = as_source(m)
        src.label = path.stem
        return src
    raise TypeError(
        f"cannot render {type(obj).__name__}: give a FitResult, a (model_name, params) pair, "
        "a UBO-81 Measurement or a path to a measurement file"
    )
