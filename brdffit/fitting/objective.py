"""The fit's objective: everything a solver evaluates of a model against the data (``problem.Data``).

- the residual (``flat_residual``: the loss's per-sample residuals at a flat parameter vector; the
  values of every loss and the metrics of model values are the losses' own, ``losses.values_metrics``);
- the constants a fit computes once (``fit_constants``: g(f_ref), the direction-only terms, the loss
  of an exact fit) and its loss by the step's route (``model_loss``, ``model_values``);
- the normal equations of one solver step (``normal_equations``), computed with the structure every
  BRDF model shares, as follows.

A step of a least-squares solver needs the loss r.r, the gradient J^T r and the Gauss-Newton
matrix J^T J of the residual r (N samples x C channels, flattened) with respect to the flat
parameter vector v (P entries). The dense way, ``jax.jacfwd`` over all P entries, pushes P
tangents through the whole model and the loss. Two facts of every model make it cheaper; both are
part of the model contract (``brdffit.models.base``) and tested for every model of the library
(``tests/test_structure.py``):

1. **Channel by channel.** Channel c of f_r depends on channel c of a 3-channel parameter only
   (formulas are written with broadcasting). So the Jacobian columns of kd_r, kd_g, kd_b touch
   disjoint rows, and one forward-mode tangent per *parameter* (all its channels at once) gives
   all of them (Curtis-Powell-Reid column compression): K tangents instead of P (ggx: 4 for 8,
   lambert+ggx+ggx: 7 for 13). J^T J is then assembled from per-channel K x K blocks.

2. **Linear parameters** (``Param(linear=True)``: kd, ks, rho...): f = B_0(theta) +
   sum_j lambda_j B_j(theta), with theta the other parameters. When every other parameter is one
   value shared by the channels (all models but ``ashikhmin_shirley``, whose rs is per channel),
   the B_j do not depend on the channel: one evaluation of the formula with the linear
   parameters set to unit vectors (the "channel" axis carrying the basis index) gives every B_j
   on N samples, and forward mode over theta alone (its few tangents) gives their partials. The
   lobe (D, G, F, the half vectors) is computed once per sample, not once per channel and
   tangent. Measured on ggx/UBO-81 (``benchmarks/bench_fit.py`` prints the step time).

The loss enters through g'(f) (every loss is elementwise in f): J = diag(dr/df) df/dv.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..models.base import Model
from . import losses as L
from .problem import Data

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Float


def compression(model: Model) -> np.ndarray:
    """S (C, K, P): S[c, k, p] = 1 when flat entry p is parameter k's value for channel c (or its
    only value, for a parameter shared by the channels)."""
    C, P = model.channels, model.n_free
    S = np.zeros((C, len(model.params), P))
    i = 0
    for k, p in enumerate(model.params):
        n = model.size(p)
        for c in range(C):
            S[c, k, i + (c if n > 1 else 0)] = 1.0
        i += n
    return S


def separable(model: Model) -> bool:
    """Whether fact 2 applies: some linear parameters, every other parameter a single value."""
    return any(p.linear for p in model.params) and all(p.linear or model.size(p) == 1 for p in model.params)


def _assemble(S: Float[Array, "C K P"], J3: Float[Array, "C K N"], r3: Float[Array, "C N"]):
    """(r.r, g, H) from the compressed Jacobian J3 (C, K, N) and the residuals r3 (C, N)."""
    G = jnp.matmul(J3, jnp.swapaxes(J3, 1, 2))  # (C, K, K): measured 3x faster than an einsum over n
    gc = jnp.matmul(J3, r3[:, :, None])[..., 0]  # (C, K)
    H = jnp.einsum("ckp,ckl,clq->pq", S, G, S)
    g = jnp.einsum("ckp,ck->p", S, gc)
    return jnp.sum(r3 * r3), g, H


def _residual_and_slope(loss, f, data: Data, g_ref=None):
    """r (N, C) and dr/df (N, C): every loss is elementwise in f."""
    wi, wo, ref, sqrt_w, cos_i, floor = data
    return jax.jvp(lambda f: L.residual(loss, f, ref, cos_i, sqrt_w, floor, g_ref), (f,), (jnp.ones_like(f),))


def _residual_and_slope_t(loss, f, data: Data, g_ref=None):
    """:func:`_residual_and_slope` for f laid out (C, N): r and dr/df, both (C, N)."""
    wi, wo, ref, sqrt_w, cos_i, floor = data
    g_t = None if g_ref is None else g_ref.T
    return jax.jvp(lambda f: L.residual(loss, f, ref.T, cos_i.T, sqrt_w.T, floor[:, None], g_t), (f,),
                   (jnp.ones_like(f),))


def basis_fn(model: Model):
    """For a :func:`separable` model: basis(theta (n_nl,), wi, wo) -> F (n_lin + 1, N), with
    theta the non-linear parameters in declared order; row j = B_0 + B_j (linear parameter j,
    in declared order), the last row B_0. The rows are a vmap of the formula over the linear
    parameters' unit vectors, so the formula sees parameters of one value each (its contract) and
    what does not depend on them (the lobe: D, G, F) is computed once. The samples are the last,
    contiguous axis: with the basis along the channel axis, (N, n_lin + 1), every product of a
    step read it with a stride of n_lin + 1, and XLA's CPU loops over it ran unvectorised."""
    lin = [p.name for p in model.params if p.linear]
    nonlin = [p.name for p in model.params if not p.linear]
    n_lin = len(lin)

    def basis(theta, wi, wo):
        nonlinear = {name: theta[i : i + 1] for i, name in enumerate(nonlin)}

        def row(unit):  # one row of the basis: the linear parameters set to ``unit`` (one value each)
            p = {name: unit[j : j + 1] for j, name in enumerate(lin)} | nonlinear
            return jnp.broadcast_to(model.formula(p, wi, wo), (wi.shape[0], 1))[:, 0]

        return jax.vmap(row)(jnp.eye(n_lin + 1, n_lin, dtype=wi.dtype))

    return basis


#: Materialise the basis's partials before the Jacobian's rows read them, on a CPU (see ``structured`` below); a
#: switch for the benchmark that measures it (``benchmarks/bench_fit.py --step``), read when a program is traced.
PARTIALS_ONCE = True


@functools.lru_cache(maxsize=None)
def normal_equations(model: Model, loss: str, jacobian: str = "float64"):
    """(v (P,), data, g_ref=None, geometry=None) -> (r.r, J^T r (P,), J^T J (P, P)), by the
    cheapest exact route for this model (see the module docstring); equal to the dense computation
    to rounding. ``g_ref`` (``losses.reference_transform`` of the data) and ``geometry``
    (:func:`precompute_geometry`) are what a solver computes once per fit.

    ``jacobian="float32"`` (a :func:`separable` model; see ``JACOBIANS``): the Jacobian's rows, J^T J and
    J^T r in float32, from the direction-only terms in float32 (``geometry`` is then the :class:`MixedTerms`
    :func:`precompute_geometry` gives); the model's values, the residuals and the loss r.r stay in the
    data's precision, so a step is accepted or refused, and a fit stops, on the exact loss."""
    S = compression(model)
    C = model.channels
    if not separable(model):
        residual = flat_residual(model, loss)
        E = S.sum(axis=0).T > 0  # (P, K): flat entry p belongs to parameter k

        def compressed(v, data, g_ref=None, geometry=None):
            Ej = jnp.asarray(E, dtype=v.dtype)

            def r_of(u):
                r = residual(v + Ej @ u, data)
                return r, r

            Jc, r = jax.jacfwd(r_of, has_aux=True)(jnp.zeros((len(model.params),), v.dtype))
            n = r.shape[0] // C
            J3 = jnp.transpose(Jc.reshape(n, C, -1), (1, 2, 0))
            return _assemble(jnp.asarray(S, v.dtype), J3, r.reshape(n, C).T)

        return compressed

    lin = [k for k, p in enumerate(model.params) if p.linear]
    nonlin = [k for k, p in enumerate(model.params) if not p.linear]
    n_lin = len(lin)
    basis = basis_fn(model)
    split = _split_vector(model)

    pairs = [(a, b) for a in range(len(model.params)) for b in range(a, len(model.params))]

    low = jnp.dtype(jacobian)

    def structured(v, data: Data, g_ref=None, geometry=None):
        wi, wo = data[0], data[1]
        theta, lam = split(v)
        mixed = low != v.dtype
        if isinstance(geometry, MixedTerms):  # the basis from the exact terms, its partials from the low ones
            F = geometry_split(model, wi.shape[0], str(wi.dtype)).finish(theta, geometry.exact)[0]
            dF = geometry_split(model, wi.shape[0], str(low)).finish(theta.astype(low), geometry.low)[1]
        elif geometry is not None:
            F, dF = geometry_split(model, wi.shape[0], str(wi.dtype)).finish(theta, geometry)
        else:
            F, dF = basis_and_partials(basis, len(nonlin))(theta, wi, wo)
        # Two results materialised: the basis with its partials, and the residuals with their slopes.
        # Left to itself XLA copies a chain of cheap operations into every loop that reads it, and
        # recomputed the lobe inside each Jacobian row and sum. It does not copy a division: each is
        # divided by a one it cannot see (an optimization_barrier keeps it from folding x / 1), which
        # is exact. Measured on ggx/UBO-81 (one core, the fit's compile options): 0.41 -> 0.37 ms.
        one = jax.lax.optimization_barrier(jnp.ones((), F.dtype))
        if nonlin and mixed and PARTIALS_ONCE and jax.default_backend() == "cpu":
            # XLA fused the channel-free partials' whole expression into each (C, N) float32 row, once per channel; it
            # does not fuse across a conditional. One evaluation (one core): ggx 312 -> 281 us, lambert+ggx+ggx 875 ->
            # 653 us; float64 rows gain nothing. An accelerator is left to fuse (a conditional there waits for the host).
            dF = jax.lax.cond(one > 0, lambda a: a, jnp.zeros_like, dF)
        Ft = F / one
        dFt = dF / one.astype(dF.dtype) if nonlin else None
        B, B0 = Ft[:n_lin] - Ft[n_lin:], Ft[n_lin]
        f = B0[None] + sum(lam[j][:, None] * B[j][None] for j in range(n_lin))  # (C, N)
        r, slope = _residual_and_slope_t(loss, f, data, g_ref)
        r, slope = r / one, slope / one
        loss_value = jnp.sum(r * r)
        if mixed:  # the Jacobian's rows and their sums in the low precision
            r, slope, B, lam = r.astype(low), slope.astype(low), B.astype(low), lam.astype(low)
        rows = [None] * len(model.params)
        for j, k in enumerate(lin):
            rows[k] = slope * B[j][None]
        if nonlin:
            dB0, dB = dFt[:, n_lin], dFt[:, :n_lin] - dFt[:, n_lin:]
            for i, k in enumerate(nonlin):
                rows[k] = slope * (dB0[i][None] + sum(lam[j][:, None] * dB[i, j][None] for j in range(n_lin)))
        # J^T J per channel from its distinct entries (a symmetric K x K block), each a sum over samples.
        G = [jnp.sum(rows[a] * rows[b], axis=-1) for a, b in pairs]  # each (C,)
        blocks = [[None] * len(rows) for _ in rows]
        for (a, b), g in zip(pairs, G):
            blocks[a][b] = blocks[b][a] = g
        Gc = jnp.stack([jnp.stack(row) for row in blocks]).astype(v.dtype)  # (K, K, C)
        gc = jnp.stack([jnp.sum(row * r, axis=-1) for row in rows]).astype(v.dtype)  # (K, C)
        Sv = jnp.asarray(S, v.dtype)
        H = jnp.einsum("ckp,klc,clq->pq", Sv, Gc, Sv)
        g = jnp.einsum("ckp,kc->p", Sv, gc)
        return loss_value, g, H

    return structured


# -- the residual and the constants of a fit ---------------------------------------------------------

@functools.lru_cache(maxsize=None)
def flat_residual(model: Model, loss: str):
    """r(v, data) with v the flat vector of parameter values (bounded; scipy's view)."""
    f_r = model.flat.f_r

    def fn(v, data: Data) -> Float[Array, " M"]:
        wi, wo, ref, sqrt_w, cos_i, floor = data
        return L.residual(loss, f_r(v, wi, wo), ref, cos_i, sqrt_w, floor).reshape(-1)

    return fn


class FitConstants(NamedTuple):
    """What every step of one fit reads and nothing changes (computed once per fit)."""

    g_ref: jax.Array  # the loss's transform of the measured values (``losses.reference_transform``)
    geometry: Any  # a separable model's direction-only terms (:func:`precompute_geometry`), or None
    loss_floor: jax.Array  # () the loss of an exact fit (residuals at roundoff level)


def fit_constants(model: Model, loss: str, data: Data, geometry=None, jacobian: str = "float64") -> FitConstants:
    """What every step of a fit shares and computes once (jit-able): g(f_ref) of the loss
    (``losses.reference_transform``), the direction-only terms of a separable model
    (:func:`precompute_geometry`, or None; ``geometry``: already computed, for the directions
    a batch's fits share), and the loss of an exact fit relative to the data ((1e-13)^2 x the loss of
    f = 0: residuals at roundoff level)."""
    wi, wo, ref, sqrt_w, cos_i, floor = data
    if geometry is None:
        geometry = precompute_geometry(model, data, jacobian)
    # Computed with the channels first, (C, N): XLA vectorises the last axis, and N x 3 it runs as N
    # rows of three (ggx/UBO-81's log transform: 0.49 -> 0.09 ms, a fifth of a texel's solve).
    # Materialised once: XLA would otherwise recompute g(f_ref) (a log1p per value) inside every
    # fusion that reads it (loss floor, start, result check, metrics).
    ref_t, cos_t, sqrt_w_t, floor_t = ref.T, cos_i.T, sqrt_w.T, floor[:, None]
    g_t, geometry = jax.lax.optimization_barrier((L.reference_transform(loss, ref_t, cos_t, floor_t), geometry))
    r0 = L.residual(loss, jnp.zeros_like(ref_t), ref_t, cos_t, sqrt_w_t, floor_t, g_t)
    return FitConstants(None if g_t is None else g_t.T, geometry, 1e-26 * jnp.sum(r0 * r0))


def model_loss(model: Model, loss: str):
    """(loss_of, measures): loss_of(v, data, consts), the fit's loss at v; measures(v, data, geometry=None), the
    loss and every metric of the model's values at v (``losses.values_metrics``: a finish's). The model's values
    by the step's route (:func:`model_values`: model.eval costs ~10x more on ggx/UBO-81)."""
    values = model_values(model)

    def loss_of(v, data, consts):
        wi, wo, ref, sqrt_w, cos_i, floor = data
        r = L.residual(loss, values(v, data, consts.geometry), ref, cos_i, sqrt_w, floor, consts.g_ref)
        return jnp.sum(r * r)

    def measures(v, data, geometry=None):
        return L.values_metrics(values(v, data, geometry), data, (loss,))

    return loss_of, measures


def _split_vector(model: Model):
    """v (P,) -> (theta (n_nl,): the non-linear parameters, lam (n_lin, C): the linear ones per
    channel), both in declared order (a separable model's non-linear parameters are single values)."""
    lin = [k for k, p in enumerate(model.params) if p.linear]
    nonlin = [k for k, p in enumerate(model.params) if not p.linear]
    starts = np.cumsum([0] + [model.size(p) for p in model.params])
    C = model.channels

    def split(v):
        theta = jnp.stack([v[starts[k]] for k in nonlin]) if nonlin else jnp.zeros((0,), v.dtype)
        lam = jnp.stack([jnp.broadcast_to(v[starts[k] : starts[k + 1]], (C,)) for k in lin])
        return theta, lam

    return split


def basis_and_partials(basis, n_nl: int):
    """(theta, wi, wo) -> (F (n_lin + 1, N), dF (n_nl, n_lin + 1, N) or None): the basis and its
    partials in theta (a vmap of JVPs, laid out for the products of the step)."""

    def fn(theta, wi, wo):
        if not n_nl:
            return basis(theta, wi, wo), None
        return jax.vmap(lambda t: jax.jvp(lambda th: basis(th, wi, wo), (theta,), (t,)), out_axes=(None, 0))(
            jnp.eye(n_nl, dtype=theta.dtype))

    return fn


class GeometrySplit:
    """:func:`basis_and_partials` cut in two by data dependence (JAX's partial evaluation): the part
    that depends on the directions only (half vectors, cosines, tan^2, (1 - l.h)^5 ...) runs once
    per fit (``precompute``), the rest at every step (``finish``). The solver's loop cannot do
    this by itself: XLA does not hoist these out of the while loop. Measured on ggx/UBO-81: the
    basis and its partials 0.21 -> 0.06 ms per step."""

    def __init__(self, model: Model, n: int, dtype: str):
        from jax._src.interpreters import partial_eval as pe  # jax is pinned (pyproject)

        n_nl = sum(1 for p in model.params if not p.linear)
        fn = basis_and_partials(basis_fn(model), n_nl)
        spec = (jax.ShapeDtypeStruct((n_nl,), dtype), jax.ShapeDtypeStruct((n, 3), dtype),
                jax.ShapeDtypeStruct((n, 3), dtype))
        closed, self.out_tree = jax.make_jaxpr(fn, return_shape=True)(*spec)
        self.out_tree = jax.tree_util.tree_structure(self.out_tree)
        self.known, self.unknown, _, _ = pe.partial_eval_jaxpr_nounits(closed, [True, False, False], instantiate=True)

    def precompute(self, wi, wo) -> tuple:
        from jax._src import core

        return tuple(core.eval_jaxpr(self.known.jaxpr, self.known.consts, wi, wo))

    def finish(self, theta, geometry):
        from jax._src import core

        out = core.eval_jaxpr(self.unknown.jaxpr, self.unknown.consts, *geometry, theta)
        return jax.tree_util.tree_unflatten(self.out_tree, out)


class MixedTerms(NamedTuple):
    """The direction-only terms of a fit whose Jacobian is in a lower precision than its data
    (:func:`precompute_geometry`): the values read ``exact``, the Jacobian's partials ``low``."""

    exact: tuple
    low: tuple


@functools.lru_cache(maxsize=32)
def geometry_split(model: Model, n: int, dtype: str) -> GeometrySplit:
    return GeometrySplit(model, n, dtype)


def precompute_geometry(model: Model, data: Data, jacobian: str = "float64"):
    """The direction-only part of a separable model's step (see :class:`GeometrySplit`), or None
    (a model of the other route, or one whose formula JAX cannot split). With a ``jacobian`` precision
    below the data's: :class:`MixedTerms`, the terms and the terms in that precision (from which
    :func:`normal_equations` computes the partials)."""
    if not separable(model):
        return None
    wi, wo = data[0], data[1]
    try:
        terms = geometry_split(model, wi.shape[0], str(wi.dtype)).precompute(wi, wo)
    except Exception:  # noqa: BLE001 - the unsplit step is exact too, only slower
        return None
    low = jnp.dtype(jacobian)
    if low == wi.dtype:
        return terms
    return MixedTerms(terms, tuple(a.astype(low) if jnp.issubdtype(a.dtype, jnp.floating) else a for a in terms))


@functools.lru_cache(maxsize=None)
def model_values(model: Model):
    """(v (P,), data, geometry=None) -> f (N, C): the model's values, by the step's route when the
    model is :func:`separable` and ``geometry`` (:func:`precompute_geometry`) is given
    (f = B_0 + B lambda from the direction-only terms: ~0.1 ms on ggx/UBO-81, where
    ``model.eval`` takes ~1 ms), else ``model.eval``. Equal to ``model.eval`` to rounding (tested)."""
    n_lin = sum(1 for p in model.params if p.linear)
    split = _split_vector(model)

    def values(v, data: Data, geometry=None):
        wi, wo = data[0], data[1]
        if geometry is None or not separable(model):
            return model.flat.f_r(v, wi, wo)
        theta, lam = split(v)
        if isinstance(geometry, MixedTerms):
            geometry = geometry.exact
        F, _ = geometry_split(model, wi.shape[0], str(wi.dtype)).finish(theta, geometry)  # partials: dead code
        return (F[n_lin][None] + lam.T @ (F[:n_lin] - F[n_lin:])).T  # f = B_0 + B lam, (N, C)

    return values


class Objective(NamedTuple):
    """One model under one loss, as the stages, starts and solvers of a fit evaluate it: built once per (model,
    loss) (:func:`objective_of`) and handed to them whole. What they evaluate is here, so that they see the model
    and the loss through it alone; the model itself only names their compiled programs (``model``, ``loss``) and
    lays out the grid of starts."""

    model: Model
    loss: str
    jacobian: str  # the precision of the Jacobian's rows and sums (``JACOBIANS``)
    residual: Callable  # (v, data) -> r (M,), the loss's residuals at a flat vector (:func:`flat_residual`)
    normal_equations: Callable  # (v, data, g_ref=None, geometry=None) -> (r.r, J^T r, J^T J)
    values: Callable  # (v, data, geometry=None) -> f (N, C), by the step's route (:func:`model_values`)
    basis: Callable | None  # (theta, wi, wo) -> the basis (L + 1, N) of a separable model (:func:`basis_fn`), or None
    loss_at: Callable  # (v, data, consts) -> the fit's loss at v (:func:`model_loss`)
    measures: Callable  # (v, data, geometry=None) -> the fit's loss and every metric at v (:func:`model_loss`)
    values_residual: Callable  # (f, ref, cos_i, sqrt_w, floor) -> residuals (N, C) of values f (``losses.residual``)
    row_weights: Callable  # (ref, cos_i, floor) -> the weights (N, C) of the loss made linear at the reference
    constants: Callable  # (data, geometry=None) -> FitConstants (:func:`fit_constants`)
    geometry: Callable  # (data) -> the direction-only terms, or None (:func:`precompute_geometry`)


#: The precisions of a step's Jacobian (``FitOptions.jacobian``): "float64", or "float32" for a :func:`separable`
#: model that declares it safe (``Model.float32_jacobian``): its rows, J^T J and J^T r; the loss stays exact.
#: Measured on the shared measured files (benchmarks/README.md): the fits' losses equal the float64 ones within
#: 4.7e-7 relative, in the same steps; ggx's evaluation 0.31 -> 0.25 ms on one core.
JACOBIANS = ("float64", "float32")


def jacobian_precision(model: Model, jacobian: str) -> str:
    """The precision a fit of ``model`` computes its Jacobian in when ``jacobian`` is asked (see :func:`objective_of`)."""
    return jacobian if separable(model) and model.float32_jacobian else "float64"


@functools.lru_cache(maxsize=None)
def objective_of(model: Model, loss: str, jacobian: str = "float64") -> Objective:
    """The :class:`Objective` of ``model`` under ``loss``, its Jacobian in the precision ``jacobian`` where the
    model is :func:`separable` and declares its partials safe in float32 (``Model.float32_jacobian``; else
    float64: the other route's Jacobian is forward mode through the model), one per process: the stages'
    compiled programs are kept per objective."""
    jacobian = jacobian_precision(model, jacobian)
    return Objective(model, loss, jacobian, flat_residual(model, loss), normal_equations(model, loss, jacobian),
                     model_values(model), basis_fn(model) if separable(model) else None, *model_loss(model, loss),
                     functools.partial(L.residual, loss),
                     functools.partial(L.linearised_row_weights, loss),
                     functools.partial(fit_constants, model, loss, jacobian=jacobian),
                     functools.partial(precompute_geometry, model, jacobian=jacobian))


def dense_normal_equations(model: Model, loss: str):
    """The reference: jacfwd over all P entries (what the structured forms must equal)."""
    residual = flat_residual(model, loss)

    def fn(v, data):
        J, r = jax.jacfwd(lambda u: (residual(u, data),) * 2, has_aux=True)(v)
        return r @ r, J.T @ r, J.T @ J

    return fn


__all__ = ["Objective", "objective_of", "normal_equations", "model_values", "dense_normal_equations", "compression",
           "separable"]

