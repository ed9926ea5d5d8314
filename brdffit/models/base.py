"""What a model is: a declared parameter table plus a pure JAX formula (SPEC 4).

A model file defines ``MODEL = Model(...)`` with its parameters, its formula and the paper it
implements; the registry (``brdffit.models``) finds it. Parameter values travel as a dict
``name -> array of shape (size,)`` where ``size`` is 1, or the number of colour channels for a
parameter declared with ``channels=3``.

Unconstrained vector (what a solver sees)
-----------------------------------------
``model.to_unconstrained(params)`` / ``model.from_unconstrained(x)`` map between the params dict and
a flat vector. Each parameter lives in its box [lower, upper], on a linear axis, or on a log axis
(``scale="log"``, automatic for positive bounds spanning >= 2 decades: roughness, exponents) so
that the solver's steps are relative. The map from R to the box is a *fold* (a triangle wave:
reflect at each bound), not a sigmoid: a sigmoid's derivative vanishes towards the bounds, and a
solver whose optimum lies at a bound (kd = 0 for a metal, f0 = 1) crawls there. The fold has slope
+-1 everywhere, so the bound is reached in one step and left again if the data want. On the box
itself the two maps are exact inverses (a bijection box <-> box); outside it the solver's iterate
is folded back, so the model never sees a parameter out of bounds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

Params = Mapping[str, Array]
Formula = Callable[[Params, Array, Array], Array]


@dataclasses.dataclass(frozen=True)
class Param:
    """One declared parameter of a model."""

    name: str
    channels: int  # 1, or 3 = one value per colour channel of the model
    lower: float
    upper: float
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

    def __post_init__(self):
        if self.channels not in (1, 3):
            raise ValueError(f"{self.name}: channels must be 1 or 3")
        if not (self.lower <= self.default <= self.upper):
            raise ValueError(f"{self.name}: default {self.default} outside [{self.lower}, {self.upper}]")
        if self.scale == "auto":
            log = self.lower > 0 and self.upper / self.lower >= 100.0
            object.__setattr__(self, "scale", "log" if log else "linear")
        if self.scale not in ("linear", "log"):
            raise ValueError(f"{self.name}: scale must be 'linear' or 'log'")

    def renamed(self, name: str) -> "Param":
        return dataclasses.replace(self, name=name)

    # axis used by the solver -------------------------------------------------------------------
    def _axis_bounds(self) -> tuple[float, float]:
        if self.scale == "log":
            return math.log(self.lower), math.log(self.upper)
        return self.lower, self.upper

    def to_axis(self, value):
        value = jnp.clip(value, self.lower, self.upper)
        return jnp.log(value) if self.scale == "log" else value

    def from_axis(self, x):
        a, b = self._axis_bounds()
        width = b - a
        if width == 0:
            t = jnp.zeros_like(x)
        else:
            # Fold R onto [a, b] with slope +-1 everywhere (also exactly at the bounds).
            y = jnp.mod(x - a, 2 * width)
            t = jnp.where(y <= width, y, 2 * width - y)
        y = a + t
        return jnp.exp(y) if self.scale == "log" else y


@dataclasses.dataclass(frozen=True)
class Model:
    """A BRDF model: name, parameter table, formula, citation.

    ``formula(params, wi, wo)`` gets a params dict (arrays of shape (size,)) and unit directions
    (N, 3) in the local frame, and returns f_r (N, channels) in 1/sr, without the cosine. It must
    be finite, with finite gradients, for every parameter in bounds and every direction in the
    closed upper hemisphere (use the double-``where`` pattern for branches).
    """

    name: str
    params: tuple[Param, ...]
    formula: Formula
    citation: str
    reciprocal: bool = True
    channels: int = 3
    #: Documentation: the lecture form and how it maps to the BRDF form implemented.
    doc: str = ""
    #: Component models of a composite ("lambert+ggx"), empty for a base model.
    components: tuple[Any, ...] = ()

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

    # -- evaluation -------------------------------------------------------------------------------
    def eval(self, params: Params, wi: Float[Array, "N 3"], wo: Float[Array, "N 3"]) -> Float[Array, "N C"]:
        """f_r(wi, wo), (N, channels), pure JAX and differentiable."""
        wi = jnp.asarray(wi)
        wo = jnp.asarray(wo)
        # Scalars are accepted for any parameter (broadcast over channels by the formula).
        params = {k: jnp.atleast_1d(jnp.asarray(v)) for k, v in params.items()}
        f = self.formula(params, wi, wo)
        return jnp.broadcast_to(f, (wi.shape[0], self.channels))

    # -- solver's view ------------------------------------------------------------------------------
    def to_unconstrained(self, params: Params) -> Float[Array, " P"]:
        params = self.check_params(params)
        return jnp.concatenate([p.to_axis(params[p.name]) for p in self.params])

    def from_unconstrained(self, x: Float[Array, " P"]) -> dict[str, Array]:
        out, i = {}, 0
        for p in self.params:
            n = self.size(p)
            out[p.name] = p.from_axis(x[i : i + n])
            i += n
        return out

    def flatten(self, params: Params) -> Float[Array, " P"]:
        """Params dict -> flat vector of parameter values (not transformed)."""
        params = self.check_params(params)
        return jnp.concatenate([params[p.name] for p in self.params])

    def unflatten(self, v: Float[Array, " P"]) -> dict[str, Array]:
        out, i = {}, 0
        for p in self.params:
            n = self.size(p)
            out[p.name] = v[i : i + n]
            i += n
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Flat lower and upper bounds, in the order of ``flatten``."""
        lo = np.concatenate([np.full(self.size(p), p.lower) for p in self.params])
        hi = np.concatenate([np.full(self.size(p), p.upper) for p in self.params])
        return lo, hi

    def sample(self, key: jax.Array, margin: float = 0.0) -> dict[str, Array]:
        """Random parameters inside the bounds (log-uniform on log axes).

        ``margin`` in [0, 0.5) keeps that fraction of each axis away from both bounds.
        """
        out = {}
        keys = jax.random.split(key, len(self.params))
        for k, p in zip(keys, self.params):
            a, b = p._axis_bounds()
            u = jax.random.uniform(k, (self.size(p),), minval=margin, maxval=1.0 - margin)
            y = a + (b - a) * u
            out[p.name] = jnp.exp(y) if p.scale == "log" else y
        return out

    def table(self) -> str:
        """The parameter table as aligned text (for docs and ``brdffit info``)."""
        rows = [("name", "channels", "lower", "upper", "default", "role", "linear")]
        rows += [
            (p.name, str(p.channels), f"{p.lower:g}", f"{p.upper:g}", f"{p.default:g}", p.role, "yes" if p.linear else "")
            for p in self.params
        ]
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)
