"""The solver's structured normal equations (``brdffit.fitting.objective``) equal the dense
computation (``jax.jacfwd`` over every entry, then J^T r and J^T J) for every model of the library,
composites with repeated lobes, every loss, monochrome data and parameters on bounds. The dense
form is the reference: it assumes nothing about the model."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.fitting.problem import prepare, resolve_model
from brdffit.fitting.objective import compression, dense_normal_equations, normal_equations, separable
from brdffit.grid import spherical_to_cartesian, ubo_pairs

MODELS = models.names() + ["lambert+ggx+ggx", "lambert+ward+blinn_phong", "oren_nayar+cook_torrance",
                           "lafortune+lafortune", "ashikhmin_shirley+ggx"]


def _data(n=300, channels=3, seed=0):
    rng = np.random.default_rng(seed)
    wi = spherical_to_cartesian(rng.uniform(0, 1.45, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_cartesian(rng.uniform(0, 1.45, n), rng.uniform(0, 2 * np.pi, n))
    ref = rng.uniform(0.01, 3.0, (n, channels))
    ref[:5] *= -0.01  # slightly negative values, as in measured RGB data
    return prepare(brdffit.Measurement(wi, wo, ref, name="random"))


def _compare(name, loss, channels=3, seed=1, v=None):
    mdl = resolve_model(name, channels)
    prep = _data(channels=channels, seed=seed)
    if v is None:
        v = np.asarray(mdl.flatten(mdl.sample(jax.random.PRNGKey(seed), margin=0.05)))
    v = jnp.asarray(v)
    got = jax.jit(normal_equations(mdl, loss))(v, prep.data)
    ref = jax.jit(dense_normal_equations(mdl, loss))(v, prep.data)
    for what, a, b in zip(("loss", "J^T r", "J^T J"), got, ref):
        a, b = np.asarray(a), np.asarray(b)
        scale = np.max(np.abs(b))
        assert scale > 0, (name, what)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * scale, err_msg=f"{name} {loss} {what}")


@pytest.mark.parametrize("name", MODELS)
def test_structured_equals_dense_for_every_model(name):
    _compare(name, "log")


@pytest.mark.parametrize("loss", ["l2", "cosine_l2", "cbrt", "relative"])
@pytest.mark.parametrize("name", ["ggx", "lambert+ggx+ggx", "ashikhmin_shirley"])
def test_structured_equals_dense_for_every_loss(name, loss):
    _compare(name, loss)


def test_monochrome_data():
    _compare("lambert+ggx", "log", channels=1)


def test_parameters_on_their_bounds():
    # kd = 0, f0 at both ends, alpha at its floor: one-sided derivatives are the same in both forms.
    _compare("ggx", "log", v=[0.0, 0.2, 0.0, 1.0, 0.5, 0.0, 1e-4, 1.0])
    _compare("ggx", "log", v=[0.3, 0.2, 0.1, 1.0, 0.5, 2.0, 0.7, 0.0])


def test_which_route_each_model_takes():
    # ashikhmin_shirley's rs is a non-linear parameter per channel: the basis trick does not apply.
    assert not separable(resolve_model("ashikhmin_shirley", 3))
    assert separable(resolve_model("lambert+ggx+ggx", 3))
    # The compression: ggx's 8 entries in 4 columns per channel; kd's red entry is column 0 of
    # channel 0 only, alpha (shared) is column 2 of every channel.
    S = compression(resolve_model("ggx", 3))
    assert S.shape == (3, 4, 8)
    assert S[:, 0, 0].tolist() == [1, 0, 0] and S[:, 2, 6].tolist() == [1, 1, 1]
    assert S.sum() == 3 * 2 + 3 * 2  # 3-channel params: one entry per channel; shared: all channels


def test_a_term_without_linear_parameters():
    # f = kd/pi + a^2 cos(theta_o): B_0 = a^2 cos(theta_o) is not zero (in the library only
    # ashikhmin_shirley has such a term, and it takes the other route).
    from brdffit.models.base import Model, Param

    def formula(p, wi, wo):
        return p["kd"] / jnp.pi + p["a"] ** 2 * wo[:, 2:3]

    mdl = Model("offset", (Param("kd", 3, 0.0, 1.0, 0.5, "albedo", linear=True),
                           Param("a", 1, 0.0, 2.0, 0.5, "shape")), formula, citation="test")
    assert separable(mdl)
    prep = _data()
    v = jnp.asarray([0.2, 0.3, 0.4, 0.7])
    for loss in ("log", "l2"):
        got = jax.jit(normal_equations(mdl, loss))(v, prep.data)
        ref = jax.jit(dense_normal_equations(mdl, loss))(v, prep.data)
        for a, b in zip(got, ref):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", ["ggx", "lambert+ggx+ggx", "ward", "oren_nayar+cook_torrance"])
def test_with_the_once_per_fit_terms(name):
    # What the solver passes: g(f_ref) and the direction-only terms, computed before the loop.
    from brdffit.fitting.losses import reference_transform
    from brdffit.fitting.objective import precompute_geometry

    mdl = resolve_model(name, 3)
    prep = _data(seed=3)
    wi, wo, ref, sqrt_w, cos_i, floor = prep.data
    v = jnp.asarray(np.asarray(mdl.flatten(mdl.sample(jax.random.PRNGKey(3), margin=0.05))))
    geometry = jax.jit(lambda d: precompute_geometry(mdl, d))(prep.data)
    assert geometry is not None
    got = jax.jit(lambda v, d, g, geo: normal_equations(mdl, "log")(v, d, g, geo))(
        v, prep.data, reference_transform("log", ref, cos_i, floor), geometry)
    want = jax.jit(dense_normal_equations(mdl, "log"))(v, prep.data)
    for a, b in zip(got, want):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-11 * np.max(np.abs(np.asarray(b))))


@pytest.mark.parametrize("name", MODELS)
def test_model_values_equal_model_eval(name):
    # What the program evaluates for the result check and the metrics: the step's route (the basis
    # from the direction-only terms) where the model is separable, model.eval otherwise.
    from brdffit.fitting.objective import model_values, precompute_geometry

    mdl = resolve_model(name, 3)
    prep = _data(seed=5)
    v = jnp.asarray(np.asarray(mdl.flatten(mdl.sample(jax.random.PRNGKey(5), margin=0.05))))
    geometry = jax.jit(lambda d: precompute_geometry(mdl, d))(prep.data)
    assert (geometry is not None) == separable(mdl), name
    got = np.asarray(jax.jit(model_values(mdl))(v, prep.data, geometry))
    want = np.asarray(mdl.eval(mdl.unflatten(v), prep.data[0], prep.data[1]))
    assert got.shape == want.shape == (300, 3)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14 * np.max(np.abs(want)), err_msg=name)


@pytest.mark.parametrize("name", ["ggx", "lambert+ggx+ggx", "ward"])
def test_the_geometry_split_gives_the_basis_and_its_partials_unchanged(name):
    """GeometrySplit cuts basis_and_partials in two; joined again they give the same arrays, one
    partial per nonlinear parameter (extra rows of zeros would pass through the step unnoticed, at a
    cost per step)."""
    from brdffit.fitting.objective import basis_and_partials, basis_fn, geometry_split

    mdl = resolve_model(name, 3)
    wi, wo = (jnp.asarray(a[:60]) for a in ubo_pairs())
    n_nl = sum(1 for p in mdl.params if not p.linear)
    theta = jnp.linspace(0.2, 0.4, n_nl)
    split = geometry_split(mdl, 60, "float64")
    got = split.finish(theta, split.precompute(wi, wo))
    want = basis_and_partials(basis_fn(mdl), n_nl)(theta, wi, wo)
    for a, b in zip(got, want):
        assert a.shape == b.shape
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-14)


def _float32_jacobian_error(mdl):
    """The float32 Jacobian's normal equations against the dense float64 ones at a random point, with the once-
    per-fit terms as a solver passes them: (the loss's error, J^T r's, J^T J's; relative to each one's largest
    entry), and the float64 values the step's route gives beside model.eval's."""
    from brdffit.fitting.losses import reference_transform
    from brdffit.fitting.objective import MixedTerms, model_values, precompute_geometry

    prep = _data(seed=4)
    wi, wo, ref, sqrt_w, cos_i, floor = prep.data
    v = jnp.asarray(np.asarray(mdl.flatten(mdl.sample(jax.random.PRNGKey(4), margin=0.05))))
    geometry = jax.jit(lambda d: precompute_geometry(mdl, d, "float32"))(prep.data)
    assert isinstance(geometry, MixedTerms)
    exact, low = geometry
    assert all(a.dtype == jnp.float32 for a in jax.tree_util.tree_leaves(low) if jnp.issubdtype(a.dtype, jnp.floating))
    got = jax.jit(lambda v, d, g, geo: normal_equations(mdl, "log", "float32")(v, d, g, geo))(
        v, prep.data, reference_transform("log", ref, cos_i, floor), geometry)
    want = jax.jit(dense_normal_equations(mdl, "log"))(v, prep.data)
    assert all(np.asarray(a).dtype == np.float64 for a in got)
    errors = [np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b))) for a, b in zip(got, want)]
    values = np.asarray(jax.jit(model_values(mdl))(v, prep.data, geometry))
    return errors, values, np.asarray(mdl.eval(mdl.unflatten(v), wi, wo))


@pytest.mark.parametrize("name", [n for n in MODELS if separable(resolve_model(n, 3))])
def test_a_float32_jacobian_keeps_the_loss_exact_and_the_rest_to_float32(name):
    """``jacobian="float32"`` (fit_btf's texels) where a model declares it (``Model.float32_jacobian``): the loss
    r.r is the float64 one to rounding (a step is accepted, and a fit stops, on it), J^T r and J^T J equal the
    dense float64 ones to float32's precision (and are not float64's), and the values the result check and the
    finish read are float64's. A model that does not declare it keeps float64, and is right not to: its
    float32 partials are not finite or far off."""
    from brdffit.fitting.objective import objective_of

    mdl = resolve_model(name, 3)
    errors, values, want = _float32_jacobian_error(mdl)
    if not mdl.float32_jacobian:
        assert objective_of(mdl, "log", "float32").jacobian == "float64"
        assert not np.all(np.isfinite(errors)) or max(errors[1:]) > 1e-4, (name, errors)
        return
    assert objective_of(mdl, "log", "float32").jacobian == "float32"
    loss, g, H = errors
    assert loss < 1e-12, (name, errors)
    assert 1e-12 < g < 2e-5 and 1e-12 < H < 2e-5, (name, errors)
    np.testing.assert_allclose(values, want, rtol=1e-12, atol=1e-14 * np.max(np.abs(want)), err_msg=name)


def test_a_model_of_the_other_route_keeps_a_float64_jacobian():
    from brdffit.fitting.objective import objective_of

    assert objective_of(resolve_model("ashikhmin_shirley", 3), "log", "float32").jacobian == "float64"
