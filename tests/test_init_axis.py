"""The start grid's axis for one nonlinear parameter (brdffit.fitting.init, module docstring): inside
the bounds with a 4 % margin at each end, logarithmic where the range is positive and spans a
factor of 100 or more; where a bound is infinite, the parameter's declared bound, else its role's
range, else (a role the table does not list: a user's model) [0, 1]. Values worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from brdffit.fitting.init import _axis
from brdffit.models.base import Param

INF = math.inf


def _param(role, lower=-INF, upper=INF, default=0.5):
    return Param("x", 1, lower, upper, default, role, physical=(max(lower, min(default, 0.0)), min(upper, 1e3)))


@pytest.mark.parametrize(("param", "lo", "hi", "expected"), [
    # a role without a range, unbounded: [0, 1], linear, margins 0.04
    (_param("offset"), -INF, INF, [0.04, 0.27, 0.5, 0.73, 0.96]),
    # roughness, unbounded: its role's range [1e-3, 1], log: 10^(-3 + 3 * (0.04, 0.5, 0.96))
    (_param("roughness", default=0.1), -INF, INF, [10 ** -2.88, 10 ** -1.5, 10 ** -0.12]),
    # an exponent bounded below only: from the bound to the role's upper end 1e4, log
    (_param("exponent", lower=1.0, default=10.0), 1.0, INF, [10 ** 0.16, 100.0, 10 ** 3.84]),
    # the lower bound above the role's range: a factor 100 above it, log: 2 x 10^(2 x (0.04, 0.5, 0.96))
    (_param("roughness", lower=0.0, default=0.1), 2.0, INF, [2 * 10 ** 0.08, 20.0, 2 * 10 ** 1.92]),
    # bounded both sides, a ratio under 100: linear inside the bounds
    (_param("shape", lower=0.0, upper=1.0), 0.2, 0.7, [0.22, 0.45, 0.68]),
    # unbounded below, bounded above under the role's lower end: the single value at the bound
    (_param("anisotropy", default=-6.0, upper=-5.0), -INF, -5.0, [-5.0]),
])
def test_the_axis_of_one_parameter(param, lo, hi, expected):
    np.testing.assert_allclose(_axis(param, lo, hi, len(expected) if len(expected) > 1 else 4), expected, rtol=1e-12)


def test_box_least_squares_matches_scipy_and_survives_a_column_the_data_do_not_see():
    """The linear unknowns at a grid point: min |A x - y|^2 on a box, as the init poses it (the
    Gram matrix of unit columns). Reference: scipy.optimize.lsq_linear. A zero column (a linear
    parameter no used sample depends on) gave NaN for every unknown (0 / 0 spread through G x)."""
    import jax.numpy as jnp
    from scipy.optimize import lsq_linear

    from brdffit.fitting.init import _box_lsq

    rng = np.random.default_rng(3)
    A = rng.standard_normal((40, 4))
    A /= np.linalg.norm(A, axis=0)
    y = rng.standard_normal(40)
    lo, hi = np.array([0.0, 0.0, -0.2, 0.0]), np.array([1.0, 0.1, 0.2, 5.0])
    expected = lsq_linear(A, y, bounds=(lo, hi), tol=1e-12, method="bvls").x
    assert np.sum((expected <= lo + 1e-12) | (expected >= hi - 1e-12)) >= 1  # the box matters here

    def solve(A, lo, hi):
        return np.asarray(_box_lsq(jnp.asarray(A.T @ A), jnp.asarray(A.T @ y), jnp.asarray(lo), jnp.asarray(hi),
                                   sweeps=40))

    np.testing.assert_allclose(solve(A, lo, hi), expected, atol=1e-9)
    with_zero = solve(np.column_stack([A, np.zeros(40)]), np.append(lo, 0.0), np.append(hi, 1.0))
    assert np.all(np.isfinite(with_zero)), with_zero
    np.testing.assert_allclose(with_zero[:4], expected, atol=1e-9)


@pytest.mark.parametrize(("model", "points"), [("mitsuba:principled", None), ("ggx", 30)])
def test_a_reseeding_grid_is_bounded_and_keeps_every_roughness(model, points):
    """A lobe re-seeded (``init.reseed_grids``) is scored on every sample: a product of its axes larger than
    RESEED_MAX_POINTS (principled's one lobe: 10 x 3^5 = 2700, 7 s of a fit) is cut to that many points by a
    fixed seed, with every roughness value still in it; a small product (ggx: 10 x 3) is kept whole."""
    import brdffit
    from brdffit.fitting.init import POINTS_ROUGHNESS, RESEED_MAX_POINTS, reseed_grids
    from brdffit.fitting.options import FitOptions

    m = brdffit.models.get(model)
    space = FitOptions().space(m)
    v = space.clip(m.default_vector())[None]
    lobe = tuple(m.lobes[-1].params)
    grids = reseed_grids(space, v, lobe)
    assert grids.shape[1] == (points or RESEED_MAX_POINTS)
    assert len(np.unique(grids, axis=1)[0]) == grids.shape[1]  # no point twice
    roughness = [j for j, p in enumerate(q for q in m.params if not q.linear) if p.role == "roughness"]
    assert len(np.unique(grids[0, :, roughness[0]])) == POINTS_ROUGHNESS
    assert np.array_equal(reseed_grids(space, v, lobe), grids)  # the same points every time
