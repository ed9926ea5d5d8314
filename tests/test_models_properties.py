"""docs/models.md#how-models-are-tested item 3, property tests (hypothesis): every model is non-negative for any parameters in
its box and any directions in the closed upper hemisphere; reciprocal models are reciprocal
(``phong_classic`` is not, and is shown not to be); directional albedo at the defaults is <= 1
for any view direction up to 89.9 degrees (``brdffit.albedo``), and albedo is accurate where it is
known in closed form."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdffit
from brdffit.grid import spherical_to_cartesian
from brdffit.models import get, names

MODELS = names() + ["lambert+ggx+ggx", "lafortune3"]
RECIPROCAL = [n for n in MODELS if get(n).reciprocal]
PAIRS = 16  # direction pairs per example (fixed: one jit compilation per model)
CASES = settings(max_examples=25, deadline=None, derandomize=True)


def param_strategy(model):
    """Each parameter anywhere in its box (bounds included; log axes drawn log-uniformly)."""

    def one(p):
        # Param.finite_range: the bounds, or the physical range on a side where a bound is infinite.
        lo, hi = p.finite_range
        if p.scale == "log":
            a, b = np.log(lo), np.log(hi)
            return st.floats(a, b).map(lambda y, lo=lo, hi=hi: float(np.clip(np.exp(y), lo, hi)))
        return st.floats(lo, hi)

    return st.fixed_dictionaries({p.name: one(p) for p in model.params})


directions = st.lists(
    st.tuples(st.floats(0.0, np.pi / 2), st.floats(0.0, 2 * np.pi)), min_size=PAIRS, max_size=PAIRS
)


def to_vectors(angles):
    a = np.asarray(angles)
    v = spherical_to_cartesian(a[:, 0], a[:, 1])
    v[:, 2] = np.maximum(v[:, 2], 0.0)  # the horizon itself, not -1e-17
    return v


@functools.lru_cache(maxsize=None)
def jitted_eval(name):
    model = get(name)
    return jax.jit(lambda p, wi, wo: model.eval(p, wi, wo))


@pytest.mark.parametrize("name", MODELS)
@CASES
@given(data=st.data())
def test_non_negative_and_finite(name, data):
    model = get(name)
    p = data.draw(param_strategy(model))
    wi = to_vectors(data.draw(directions))
    wo = to_vectors(data.draw(directions))
    f = np.asarray(jitted_eval(name)(p, wi, wo))
    assert np.all(np.isfinite(f)) and np.all(f >= 0), (p, wi, wo, f)


@pytest.mark.parametrize("name", RECIPROCAL)
@CASES
@given(data=st.data())
def test_reciprocal(name, data):
    model = get(name)
    p = data.draw(param_strategy(model))
    wi = to_vectors(data.draw(directions))
    wo = to_vectors(data.draw(directions))
    ev = jitted_eval(name)
    a, b = np.asarray(ev(p, wi, wo)), np.asarray(ev(p, wo, wi))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12 * max(np.max(np.abs(a)), 1.0))


def test_phong_classic_is_not_reciprocal():
    model = get("phong_classic")
    assert not model.reciprocal
    wi = spherical_to_cartesian(np.deg2rad([60.0]), [0.0])
    wo = spherical_to_cartesian(np.deg2rad([30.0]), [np.pi])
    p = model.defaults()
    a, b = model.eval(p, wi, wo), model.eval(p, wo, wi)
    assert not np.allclose(a, b, rtol=1e-3)


@pytest.mark.parametrize("name", MODELS)
@settings(max_examples=8, deadline=None, derandomize=True)
@given(theta=st.floats(0.0, np.deg2rad(89.9)), phi=st.floats(0.0, 2 * np.pi))
def test_albedo_at_defaults_at_most_one(name, theta, phi):
    model = get(name)
    wo = spherical_to_cartesian(theta, phi)
    a = np.asarray(brdffit.albedo(model, model.defaults(), wo))
    assert a.shape == (3,)
    assert np.all(a > 0) and np.all(a <= 1.0), (np.rad2deg(theta), a)


def test_albedo_closed_forms():
    """Lambert: kd at any angle. Normalised Phong at normal incidence: kd + ks exactly, even for
    a lobe of exponent 1e4 (checks that the quadrature resolves sharp lobes)."""
    th = np.deg2rad([0.0, 30.0, 60.0, 85.0, 89.0, 89.9])
    wo = spherical_to_cartesian(th, 0.7 + 0 * th)
    a = np.asarray(brdffit.albedo("lambert", {"kd": np.array([0.2, 0.5, 0.9])}, wo))
    np.testing.assert_allclose(a, np.broadcast_to([0.2, 0.5, 0.9], a.shape), rtol=1e-4)
    for n in (1.0, 20.0, 1e3, 1e4):
        a = np.asarray(brdffit.albedo("phong", {"kd": 0.1, "ks": 0.6, "n": n}, np.array([0.0, 0.0, 1.0])))
        np.testing.assert_allclose(a, 0.7, rtol=1e-4, err_msg=f"n={n}")


@pytest.mark.parametrize("name", ["ggx", "ward"])
def test_albedo_is_the_same_at_every_view_azimuth_and_continuous_at_the_normal(name):
    """The quadrature turns with the mirror direction r of wo (two tangents of r); an isotropic
    model's albedo therefore depends on theta alone, to rounding: views in the xz and yz planes
    (where r has no x component), and at the normal (r = z, where the tangents are chosen, not
    derived) against a view 1e-7 rad off it."""
    model = get(name)
    p = model.defaults()
    theta = np.deg2rad(35.0)
    planes = np.array([[np.sin(theta), 0.0, np.cos(theta)], [0.0, np.sin(theta), np.cos(theta)],
                       [0.0, -np.sin(theta), np.cos(theta)]])
    a = np.asarray(brdffit.albedo(model, p, planes))
    assert a.shape == (3, 3) and np.all(np.isfinite(a))
    np.testing.assert_allclose(a[1:], a[:1].repeat(2, axis=0), rtol=1e-9)
    eps = 1e-7
    normal = np.array([[0.0, 0.0, 1.0], [np.sin(eps), 0.0, np.cos(eps)]])
    a = np.asarray(brdffit.albedo(model, p, normal))
    np.testing.assert_allclose(a[0], a[1], rtol=1e-6)


def test_albedo_takes_any_numeric_direction_as_float64():
    """Integer and float32 view directions are read as float64 (the sum of 65,536 weighted terms
    would lose ~1e-4 in float32): the same albedo as from the float64 direction."""
    p = {"kd": 0.1, "ks": 0.6, "alpha": 0.2, "f0": 0.04}
    ref = np.asarray(brdffit.albedo("ggx", p, np.array([0.0, 0.0, 1.0])))
    for wo in (np.array([0, 0, 1]), np.array([0.0, 0.0, 1.0], np.float32)):
        a = brdffit.albedo("ggx", p, wo)
        assert a.dtype == np.float64
        np.testing.assert_allclose(np.asarray(a), ref, rtol=1e-12)
