"""What a model is: a declared parameter table plus a pure JAX formula (docs/models.md#models).

A model file defines ``MODEL = Model(...)`` with its parameters, its formula and the paper it
implements; the registry (``brdffit.models``) finds it. Parameter values travel as a dict
``name -> array of shape (size,)`` where ``size`` is 1, or the number of colour channels for a
parameter declared with ``channels=3``.

Bounds and physical ranges (docs/fitting.md#parameter-space)
------------------------------------------------------
Every parameter declares two ranges:

* its **bounds** ``[lower, upper]``: only what the formula needs (scales non-negative, roughness and
  exponents positive, f0 in [0, 1]). A side the formula leaves open is infinite (``math.inf``):
  measured data are often in arbitrary units, or need more than a plausible value. A fit never
  leaves the bounds, and ``bounds=`` overrides may only narrow them.
* its **physical range** ``physical=(lo, hi)``: a finite, plausible range inside the bounds
  (albedo <= 1, energy conservation where the model has a simple criterion, roughness <= 1, ...),
  applied by ``fit(..., physical=True)``.

Where a bound is infinite, code that needs a finite box -- random parameters (``Model.sample``),
the stress checks of ``brdffit.testing``, the start grid -- uses the physical range on that side
(``Param.finite_range``).

Axes and the fold
-----------------
Each parameter lives in its box [lower, upper], on a linear axis or on a log axis (``scale="log"``,
automatic for a positive lower bound with an upper bound >= 100 times larger or infinite:
roughness, exponents): random parameters (``Model.sample``) are uniform on that axis. The solvers
keep their iterates in the box themselves (``brdffit.fitting.solve``: the default ``lm`` clips each
trial point; optimistix's stock solvers move an unconstrained variable mapped into the box by
``solver_optx.to_box``). That map is :func:`_fold`, a triangle wave (reflect at each finite bound; one
reflection for a one-sided box, the identity for R), not a sigmoid: a sigmoid's derivative
vanishes towards the bounds, and a solver whose optimum lies at a bound (kd = 0 for a metal,
f0 = 1) crawls there. The fold has slope +-1 everywhere, so the bound is reached in one step and
left again if the data want.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np

from .flat import FlatView, flat_view

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Float


Params = Mapping[str, jax.Array]  # jaxtyping's Array is this one
Formula = Callable[[Params, jax.Array, jax.Array], jax.Array]


def _fold(x, a, b):
    """Fold x in R onto [a, b] with slope +-1 everywhere (also exactly at the bounds).

    a, b may be infinite: one finite side is a single reflection, none the identity. Works on
    arrays of bounds (one per element) as well as on scalars.
    """
    a_fin, b_fin = jnp.isfinite(a), jnp.isfinite(b)
    a0 = jnp.where(a_fin, a, 0.0)
    b0 = jnp.where(b_fin, b, 0.0)
    width = jnp.where(a_fin & b_fin, b0 - a0, 1.0)
    both = width > 0
    safe_width = jnp.where(both, width, 1.0)
    y = jnp.mod(x - a0, 2 * safe_width)
    boxed = a0 + jnp.where(y <= safe_width, y, 2 * safe_width - y)
    boxed = jnp.where(both, boxed, a0)  # a zero-width box (lo == hi): the value itself
    lower_only = a0 + jnp.where(x >= a0, x - a0, a0 - x)
    upper_only = b0 - jnp.where(x <= b0, b0 - x, x - b0)
    return jnp.where(a_fin & b_fin, boxed, jnp.where(a_fin, lower_only, jnp.where(b_fin, upper_only, x)))


@dataclasses.dataclass(frozen=True)
class Param:
    """One declared parameter of a model (see the module docstring for bounds and physical range)."""

    name: str
    channels: int  # 1, or 3 = one value per colour channel of the model
    lower: float  # bound the formula needs (may be -inf)
    upper: float  # bound the formula needs (may be inf)
    default: float
    role: str  # albedo | roughness | exponent | fresnel | shape | anisotropy
    #: The model is linear (and increasing) in this parameter: initialisation solves it by
    #: non-negative least squares for every trial of the nonlinear ones (variable projection).
    #: Precisely: with theta the parameters *not* marked linear and lambda those marked linear,
    #: f = B_0(theta) + sum_j lambda_j B_j(theta) -- jointly affine in all linear parameters,
    #: each channel separately. B_0 = 0 in every model of the library except
    #: ``ashikhmin_shirley`` (its specular term does not depend on rd). A parameter that is affine
    #: alone but multiplies another linear one (f0 next to ks; rs next to rd) is not linear.
    linear: bool = False
    #: "linear" or "log": the axis the solver moves on (see module docstring).
    scale: str = "auto"
    doc: str = ""
    #: Plausible range (finite, inside the bounds), applied with ``fit(..., physical=True)``.
    #: None: the bounds themselves (allowed only where both are finite).
    physical: tuple[float, float] | None = None
    #: The values the default start's grid tries (inside the bounds); None: the grid's own axis over
    #: the bounds (``brdffit.fitting.init``). For a parameter whose useful values the bounds do not
    #: say (Lafortune's C, whose length trades against rho).
    grid: tuple[float, ...] | None = None

    def __post_init__(self):
        if self.channels not in (1, 3):
            raise ValueError(f"{self.name}: channels must be 1 or 3")
        # Floats whatever a model file writes (``Param("n", 1, 1, 100, 20, ...)``): bounds and
        # defaults become float64 arrays and JAX constants, never integer ones.
        for field in ("lower", "upper", "default"):
            object.__setattr__(self, field, float(getattr(self, field)))
        if not (self.lower <= self.default <= self.upper) or math.isnan(self.default):
            raise ValueError(f"{self.name}: default {self.default} outside [{self.lower}, {self.upper}]")
        physical = self.physical
        if physical is None:
            physical = (self.lower, self.upper)
        physical = (float(physical[0]), float(physical[1]))
        if not all(math.isfinite(v) for v in physical):
            raise ValueError(f"{self.name}: a physical range must be finite (an infinite bound needs one)")
        if not (self.lower <= physical[0] <= self.default <= physical[1] <= self.upper):
            raise ValueError(
                f"{self.name}: physical range {physical} must lie inside the bounds "
                f"[{self.lower}, {self.upper}] and hold the default {self.default}"
            )
        object.__setattr__(self, "physical", physical)
        if self.scale == "auto":
            log = self.lower > 0 and self.upper / self.lower >= 100.0
            object.__setattr__(self, "scale", "log" if log else "linear")
        if self.scale not in ("linear", "log"):
            raise ValueError(f"{self.name}: scale must be 'linear' or 'log'")
        if self.scale == "log" and not self.lower > 0:
            raise ValueError(f"{self.name}: a log axis needs a positive lower bound")

    def renamed(self, name: str) -> "Param":
        return dataclasses.replace(self, name=name)

    @property
    def finite_range(self) -> tuple[float, float]:
        """The bounds, with the physical range standing in on an infinite side: the box that
        random parameters, stress checks and the start grid use."""
        lo = self.lower if math.isfinite(self.lower) else self.physical[0]
        hi = self.upper if math.isfinite(self.upper) else self.physical[1]
        return lo, hi

    # axis used by the solver -------------------------------------------------------------------
    def _axis_bounds(self, lower=None, upper=None):
        """The box [lower, upper] (declared bounds unless given) on this parameter's axis."""
        lower = self.lower if lower is None else lower
        upper = self.upper if upper is None else upper
        if self.scale == "log":
            return jnp.log(lower), jnp.log(upper)
        return lower, upper


@dataclasses.dataclass(frozen=True)
class Lobe:
    """One specular lobe of a model: its kind (the model that defines it) and its parameters, by
    flat name, in the kind's order. Two lobes of one kind are interchangeable: swapping all their
    parameters leaves f_r unchanged (``brdffit.models.compose`` orders them)."""

    kind: str
    params: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Proposal:
    """One term of a model as importance sampling sees it (``brdffit.render.sampling`` draws from a
    mixture of these): ``kind`` cosine | ggx | beckmann | power | half_power, its ``shape``
    (ggx/beckmann: (alpha_u, alpha_v); power: (n, cx, cz); half_power: (nu, nv)), the model's own
    names of the scale parameters that weigh it, and ``minus``: the index of a proposal whose albedo
    is included in this one's when it is isolated (subtract it)."""

    kind: str
    shape: tuple[float, ...] = ()
    scales: tuple[str, ...] = ()
    minus: int | None = None


@dataclasses.dataclass(frozen=True)
class Model:
    """A BRDF model: name, parameter table, formula, citation.

    ``formula(params, wi, wo)`` gets a params dict (arrays of shape (size,)) and unit directions
    (N, 3) in the local frame, and returns f_r (N, channels) in 1/sr, without the cosine. It must
    be finite, with finite gradients, for every parameter in bounds and every direction in the
    closed upper hemisphere (use the double-``where`` pattern for branches). Channel c of the
    result may depend on channel c of a 3-channel parameter only (formulas written with
    broadcasting do), and f_r must be affine in the parameters declared ``linear``: the solver
    computes its Jacobians with that structure (``brdffit.fitting.objective``), and
    ``brdffit.testing.model_problems`` checks both.
    """

    name: str
    params: tuple[Param, ...]
    formula: Formula
    citation: str
    reciprocal: bool = True
    #: Whether a fit may compute this formula's Jacobian in float32 (``FitOptions.jacobian``: fit_btf's texels;
    #: the loss stays float64): True where its partials keep float32's precision for every parameter in bounds
    #: (tested, ``tests/test_structure.py``). False by default and where they do not: lafortune's powers of
    #: the cosine overflow (NaN), roughplastic's tabulated quadratures lose digits (2e-4 relative).
    float32_jacobian: bool = False
    channels: int = 3
    #: Documentation: the lecture form and how it maps to the BRDF form implemented.
    doc: str = ""
    #: Component models of a composite ("lambert+ggx"), empty for a base model.
    components: tuple[Any, ...] = ()
    #: The model's specular lobes. None (the default): one lobe of kind ``name`` made of every
    #: parameter but the diffuse ``kd`` (none for a model with no other parameter).
    lobes: tuple[Lobe, ...] | None = None
    #: ``halfwidth(params) -> radians``: half width at half maximum of the model's lobe, measured
    #: in reflected directions (about twice the half-vector angle for a microfacet lobe), from the
    #: lobe's parameters by their base names (floats, or NumPy arrays of them: one width per fit). None
    #: where the model has no specular lobe.
    #: Used to warn about lobes narrower than the sample spacing (``brdffit.fitting.space``).
    halfwidth: Callable[[Mapping[str, float]], float] | None = None
    #: Native models only (docs/materials.md#native-materials-and-exports): ``to_native(params) -> dict``, what the renderer or format
    #: whose BSDF this formula reproduces loads, from checked parameters as float64 NumPy arrays of
    #: the declared sizes. None for brdffit's own models. See :meth:`native`.
    to_native: Callable[[Mapping[str, np.ndarray]], dict] | None = None
    #: ``sampling(p) -> tuple[Proposal, ...]``: the terms importance sampling draws from, with
    #: ``p(name)`` a parameter's value (float). None: cosine sampling (valid, not fast).
    sampling: Callable[[Callable[[str], float]], tuple[Proposal, ...]] | None = None
    #: The table read once into the flat vector a solver moves, and the formula of that vector
    #: (``brdffit.models.flat``): what the fitting core reads. No part of the model's identity.
    flat: FlatView = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.lobes is None:
            own = tuple(p.name for p in self.params if p.name != "kd")
            object.__setattr__(self, "lobes", (Lobe(self.name, own),) if own else ())
        known = set(self.param_names)
        for lobe in self.lobes:
            if not set(lobe.params) <= known:
                raise ValueError(f"model {self.name!r}: lobe {lobe} names unknown parameters")
        object.__setattr__(self, "flat", flat_view(self))

    def __repr__(self) -> str:
        # short: the docstring and formula are in help(model) / model.doc, not in every repr
        ps = ", ".join(p.name if self.size(p) == 1 else f"{p.name}({self.size(p)})" for p in self.params)
        return f"Model({self.name!r}: {ps}; {self.citation.splitlines()[0] if self.citation else ''})"

    # -- parameter table ------------------------------------------------------------------------
    def param(self, name: str) -> Param:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"model {self.name!r} has no parameter {name!r}; it has {self.param_names}")

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def size(self, p: Param) -> int:
        """Number of values of parameter p in this model (1, or the model's channel count)."""
        return self.channels if p.channels == 3 else 1

    @property
    def n_free(self) -> int:
        """Length of the flat parameter vector."""
        return sum(self.size(p) for p in self.params)

    def with_channels(self, channels: int) -> "Model":
        """The same model for data with another channel count (e.g. 1 for monochrome data)."""
        return dataclasses.replace(self, channels=int(channels))

    def defaults(self, dtype=None) -> dict[str, Array]:
        dtype = dtype or jnp.result_type(float)
        return {p.name: jnp.full((self.size(p),), p.default, dtype=dtype) for p in self.params}

    def default_vector(self) -> np.ndarray:
        """The defaults as a flat float64 NumPy vector (``flatten(defaults())`` without JAX)."""
        return self.flat.defaults.copy()

    def check_params(self, params: Params) -> dict[str, Array]:
        """Params as arrays of the declared sizes; raises ValueError naming what is wrong."""
        out = {}
        missing = [p.name for p in self.params if p.name not in params]
        if missing:
            raise ValueError(f"model {self.name!r}: missing parameters {missing}")
        extra = set(params) - set(self.param_names)
        if extra:
            raise ValueError(f"model {self.name!r}: unknown parameters {sorted(extra)}")
        for p in self.params:
            v = jnp.atleast_1d(jnp.asarray(params[p.name], dtype=jnp.result_type(float)))
            n = self.size(p)
            if v.shape == (1,) and n > 1:
                v = jnp.broadcast_to(v, (n,))
            if v.shape != (n,):
                raise ValueError(f"model {self.name!r}: parameter {p.name!r} has shape {v.shape}, expected ({n},)")
            out[p.name] = v
        return out

    # -- native models (docs/materials.md#native-materials-and-exports) -------------------------------------------------------------------
    @property
    def is_native(self) -> bool:
        """True for a model whose formula is a renderer's or format's own BSDF (``mitsuba:*``,
        ``gltf:*``, ``blender:*``): it does not compose with ``+`` and exports as that BSDF."""
        return self.to_native is not None

    @property
    def target(self) -> str | None:
        """The renderer or format of a native model: the part of its name before ``:``."""
        return self.name.split(":", 1)[0] if self.is_native else None

    def native(self, params: Params) -> dict:
        """What the renderer loads for ``params`` (docs/materials.md#native-materials-and-exports): for ``mitsuba:*`` a ``mi.load_dict``
        dictionary of Mitsuba's own plugin, for ``gltf:*`` a glTF 2.0 material object. Raises
        ValueError for a model that is not native, or parameters outside the bounds (the ranges the
        renderer accepts)."""
        if self.to_native is None:
            from ._registry import native_names

            raise ValueError(f"model {self.name!r} is not a native model; native models: {', '.join(native_names())}")
        checked = {k: np.asarray(v, np.float64).reshape(-1) for k, v in self.check_params(params).items()}
        for p in self.params:
            v = checked[p.name]
            if not np.all(np.isfinite(v)) or np.any(v < p.lower) or np.any(v > p.upper):
                raise ValueError(
                    f"model {self.name!r}: parameter {p.name!r} = {v.tolist()} outside "
                    f"{format_range(p.lower, p.upper)}, the range the renderer accepts"
                )
        return self.to_native(checked)

    # -- evaluation -------------------------------------------------------------------------------
    def eval(self, params: Params, wi: Float[Array, "N 3"], wo: Float[Array, "N 3"]) -> Float[Array, "N C"]:
        """f_r(wi, wo), (N, channels), pure JAX and differentiable."""
        wi = jnp.asarray(wi)
        wo = jnp.asarray(wo)
        # Scalars are accepted for any parameter (broadcast over channels by the formula).
        params = {k: jnp.atleast_1d(jnp.asarray(v)) for k, v in params.items()}
        f = self.formula(params, wi, wo)
        return jnp.broadcast_to(f, (wi.shape[0], self.channels))

    # -- the flat vector ----------------------------------------------------------------------------
    def slices(self):
        """(parameter name, its slice of the flat vector), in the order of :meth:`flatten`."""
        yield from self.flat.slices

    def flatten(self, params: Params) -> Float[Array, " P"]:
        """Params dict -> flat vector of parameter values (not transformed)."""
        params = self.check_params(params)
        return jnp.concatenate([params[p.name] for p in self.params])

    def unflatten(self, v: Float[Array, " P"]) -> dict[str, Array]:
        """The params dict of the flat vector ``v`` (views of it, in the layout of :attr:`flat`)."""
        return {name: v[s] for name, s in self.flat.slices}

    def bounds(self, physical: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Flat lower and upper bounds in the order of ``flatten`` (may be infinite), or the
        physical ranges (finite) with ``physical=True``."""
        lo, hi = self.flat.bounds(physical)
        return lo.copy(), hi.copy()

    def sample(self, key: jax.Array, margin: float = 0.0) -> dict[str, Array]:
        """Random parameters inside ``Param.finite_range`` (the bounds, the physical range on a
        side where the bound is infinite; log-uniform on log axes).

        ``margin`` in [0, 0.5) keeps that fraction of each axis away from both ends.
        """
        out = {}
        keys = jax.random.split(key, len(self.params))
        for k, p in zip(keys, self.params):
            a, b = p._axis_bounds(*p.finite_range)
            u = jax.random.uniform(k, (self.size(p),), minval=margin, maxval=1.0 - margin)
            y = a + (b - a) * u
            out[p.name] = jnp.exp(y) if p.scale == "log" else y
        return out

    def table(self) -> str:
        """The parameter table as aligned text (for docs and ``brdffit info``)."""
        rows = [("name", "channels", "bounds", "physical", "default", "role", "linear")]
        rows += [
            (p.name, str(p.channels), format_range(p.lower, p.upper), format_range(*p.physical), f"{p.default:g}",
             p.role, "yes" if p.linear else "")
            for p in self.params
        ]
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


def format_range(lo: float, hi: float) -> str:
    """``[0, 1]``, ``[1e-4, inf)``: the notation of the model files' parameter tables."""

    def num(v):
        if v == math.pi / 2:
            return "pi/2"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if v != 0 and not 1e-2 <= abs(v) < 1e4:
            return np.format_float_scientific(v, trim="-", exp_digits=1).replace("+", "")
        return f"{v:g}"

    return ("(" if math.isinf(lo) else "[") + f"{num(lo)}, {num(hi)}" + (")" if math.isinf(hi) else "]")
