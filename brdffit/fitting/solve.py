"""Solving one start (docs/fitting.md#fitting): the constants a fit computes once, the solve by its solver family, and
the check of its result.

Solver families, one per file: ``lm`` (the default, brdffit's bounded Levenberg-Marquardt:
``solver_lm``), optimistix's stock ``optx_lm`` / ``gauss_newton`` / ``dogleg`` / ``bfgs``
(``solver_optx``), and ``scipy`` (``solver_scipy``, run in Python by the driver). ``atol`` is an
optional absolute floor on the loss (0 by default). Every solve returns a status code
(``_fit_defaults.STATUS_TEXT``); its result is never NaN.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ..models.base import Model
from . import losses as L
from .problem import Data
from .solver_lm import BoundedLevenbergMarquardt, solve_lm
from .solver_optx import solve_stock, stock_solver


class FitConstants(NamedTuple):
    """What every step of one fit reads and nothing changes (computed once per fit)."""

    g_ref: jax.Array  # the loss's transform of the measured values (``losses.reference_transform``)
    geometry: Any  # a separable model's direction-only terms (``structure.precompute_geometry``), or None
    loss_floor: jax.Array  # () the loss of an exact fit (residuals at roundoff level)


def fit_constants(model: Model, loss: str, data: Data, geometry=None) -> FitConstants:
    """What every step of a fit shares and computes once (jit-able): g(f_ref) of the loss
    (``losses.reference_transform``), the direction-only terms of a separable model
    (``structure.precompute_geometry``, or None; ``geometry``: already computed, for the directions
    a batch's fits share), and the loss of an exact fit relative to the data ((1e-13)^2 x the loss of
    f = 0: residuals at roundoff level)."""
    from .structure import precompute_geometry

    wi, wo, ref, sqrt_w, cos_i, floor = data
    if geometry is None:
        geometry = precompute_geometry(model, data)
    # Computed with the channels first, (C, N): XLA vectorises the last axis, and N x 3 it runs as N
    # rows of three (ggx/UBO-81's log transform: 0.49 -> 0.09 ms, a fifth of a texel's solve).
    # Materialised once: XLA would otherwise recompute g(f_ref) (a log1p per value) inside every
    # fusion that reads it (loss floor, start, result check, metrics).
    ref_t, cos_t, sqrt_w_t, floor_t = ref.T, cos_i.T, sqrt_w.T, floor[:, None]
    g_t, geometry = jax.lax.optimization_barrier((L.reference_transform(loss, ref_t, cos_t, floor_t), geometry))
    r0 = L.residual(loss, jnp.zeros_like(ref_t), ref_t, cos_t, sqrt_w_t, floor_t, g_t)
    return FitConstants(None if g_t is None else g_t.T, geometry, 1e-26 * jnp.sum(r0 * r0))


def model_loss(model: Model, loss: str):
    """loss_of(v, data, consts): the fit's loss at v, the model's values by the step's route
    (``structure.model_values``: model.eval costs ~10x more on ggx/UBO-81)."""
    from .structure import model_values

    values = model_values(model)

    def loss_of(v, data, consts):
        wi, wo, ref, sqrt_w, cos_i, floor = data
        r = L.residual(loss, values(v, data, consts.geometry), ref, cos_i, sqrt_w, floor, consts.g_ref)
        return jnp.sum(r * r)

    return loss_of


def make_solver(name: str, rtol: float, atol: float, normal_equations: Callable | None = None):
    """The optimistix solver object behind a solver name (not ``scipy``)."""
    if name == "lm":
        return BoundedLevenbergMarquardt(rtol=rtol, atol=atol, normal_equations=normal_equations)
    return stock_solver(name, rtol, atol)


def solve_one(model: Model, loss: str, solver_name: str, rtol: float, atol: float, max_steps: int):
    """The jit-able solve of one start, at most ``max_steps`` steps. ``lm``: run(v0 (P,), data, lo, hi,
    free, consts, resume=None) -> (v, Resume, done, code, steps) (``solver_lm.solve_lm``: it continues
    from a previous round's ``resume``); a stock solver: run(v0, data, lo, hi, free, consts) -> the same,
    its ``Resume`` holding the loss at v (``c``), at v0 (``c0``) and J^T J at v (``H``). ``consts``:
    :func:`fit_constants` of the data. The caller checks the result (:func:`result_check`)."""
    if solver_name == "lm":
        return solve_lm(model, loss, rtol, atol, max_steps)
    return solve_stock(model, loss, solver_name, rtol, atol, max_steps, model_loss(model, loss))
