"""``mitsuba:roughplastic`` reads its two precomputed terms from tables of Mitsuba's own quadratures
(``_mitsuba_math.rough_tables``). Computed inside the formula, the quadratures' 1.1 M nodes made a fit
450x slower than a ggx fit and 2.5 GB large, and Mitsuba's internal reflectance, rough at the 1e-4
level in alpha (where its nodes cross the critical angle), left the solver "not converged" on data
that fit to 3e-5 (``benchmarks/bench_native.py`` prints the fit times and memory)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
import brdffit.models as models
from brdffit.models import _mitsuba_math as mm
from brdffit.models import mitsuba_roughplastic

MODEL = models.get("mitsuba:roughplastic")


def _largest_array(fn, *args) -> int:
    """Elements of the largest array the JAX program of fn(*args) makes (sub-programs included)."""
    best = 0

    def walk(jaxpr):
        nonlocal best
        for eqn in jaxpr.eqns:
            best = max([best] + [int(np.prod(v.aval.shape)) for v in eqn.outvars if hasattr(v.aval, "shape")])
            for value in eqn.params.values():
                sub = getattr(value, "jaxpr", value)
                if hasattr(sub, "eqns"):
                    walk(sub)

    walk(jax.make_jaxpr(fn)(*args).jaxpr)
    return best


def test_a_fit_step_holds_no_array_larger_than_its_data():
    """What a fit evaluates -- the formula on the UBO-81 pairs and its derivatives in the two nonlinear
    parameters -- makes no array larger than the data's own (6561 pairs x 3 channels): the 64 x 128 x
    128 quadrature (3.1 M values, times the tangents and the starts) is gone from it."""
    wi, wo = brdffit.ubo_pairs()
    p = MODEL.defaults()

    def f(alpha, ior):
        return MODEL.eval({**p, "alpha": alpha, "int_ior": ior}, wi, wo)

    tangents = (jnp.ones(1), jnp.ones(1))
    size = _largest_array(lambda a, e: jax.jvp(f, (a, e), tangents), p["alpha"], p["int_ior"])
    assert size <= 3 * len(wi), size


def test_the_formula_is_smooth_in_its_roughness():
    """Along alpha the formula has no kinks for the solver to stall on: at 41 values 0.01 apart in
    ln(alpha) about 0.1, its third differences stay below 1e-4 of it (measured 1.2e-5; with Mitsuba's
    quadratures computed in place 1.0e-3: their nodes crossing the critical angle)."""
    wi = np.array([[0.5, 0.1, np.sqrt(0.74)], [0.0, 0.3, np.sqrt(0.91)]])
    wo = np.array([[-0.6, 0.2, np.sqrt(0.60)], [0.4, -0.4, np.sqrt(0.68)]])
    log_alpha = np.log(0.1) + np.linspace(-0.2, 0.2, 41)
    p = {**MODEL.defaults(), "int_ior": jnp.asarray([2.1]), "diffuse_reflectance": jnp.full(3, 0.8)}
    f = np.array([np.asarray(MODEL.eval({**p, "alpha": jnp.asarray([np.exp(x)])}, wi, wo))[:, 0] for x in log_alpha])
    assert np.max(np.abs(np.diff(f, 3, axis=0)) / f[:-3]) < 1e-4


@pytest.mark.parametrize("seed", range(6))
def test_the_tables_follow_mitsubas_quadratures(seed):
    """At random (alpha, int_ior): the transmittance within 2e-4 of itself, the internal reflectance R
    within 5e-3 of what the diffuse term divides by, 1 - R: Mitsuba's R is rough at the 1e-4 level
    where alpha is 0.03-0.5 (see the module docstring), and 1 - R is small where int_ior is large
    (measured: 4.2e-3 at alpha 0.17, int_ior 2.6; below 1e-5 where alpha < 0.01)."""
    rng = np.random.default_rng(seed)
    alpha = jnp.float64(np.exp(rng.uniform(np.log(1e-4), 0.0)))
    eta = jnp.float64(rng.uniform(1.05, 3.0))
    t, r = mm.rough_tables(alpha, eta)
    t_exact, r_exact = mm.external_transmittance(alpha, eta), mm.internal_reflectance(alpha, eta)
    assert np.max(np.abs(np.asarray(t - t_exact)) / np.asarray(t_exact)) < 2e-4
    assert abs(float(r - r_exact)) < 5e-3 * (1.0 - float(r_exact))


@pytest.mark.mitsuba
def test_the_quadratures_the_tables_hold_are_mitsubas():
    """The tables' source: the formula with the quadratures computed in place equals Mitsuba's
    bsdf.eval to 1e-4 at the 99th percentile (the tables are checked against them above)."""
    import test_native_models as native

    exact = lambda a, e: (mm.external_transmittance(a, e), mm.internal_reflectance(a, e))  # noqa: E731
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mitsuba_roughplastic, "rough_tables", exact)
        patch.setattr(native, "PARAM_SETS", 8)
        err = native.relative_errors("mitsuba:roughplastic", seed=3)
    assert np.percentile(err, 99) <= 1e-4
