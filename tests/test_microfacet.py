"""The GGX kit (brdffit/models/_microfacet.py): each form equal to one written independently here
(NumPy, float64, the forms of the papers), and every GGX model evaluating it, none its own copy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from brdffit import models
from brdffit.models import _microfacet as mf

#: The models whose lobes are GGX: each must take D, G and the half width from the kit.
GGX_MODELS = ("ggx", "gltf:metallic_roughness", "blender:principled", "mitsuba:principled",
              "mitsuba:roughconductor", "mitsuba:roughplastic")


def upper(rng, n, max_deg=88.0):
    cos = rng.uniform(math.cos(math.radians(max_deg)), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    sin = np.sqrt(1.0 - cos**2)
    return np.stack([sin * np.cos(phi), sin * np.sin(phi), cos], -1)


def test_d_is_walters_and_normalised():
    """Walter et al. 2007 eq. 33 in the textbook form, and int D (n.h) dw = 1 (quadrature in theta)."""
    rng = np.random.default_rng(1)
    h = upper(rng, 400)
    for alpha in (0.02, 0.2, 0.7, 1.5):
        c2 = h[:, 2:3] ** 2
        textbook = alpha**2 / (np.pi * (c2 * (alpha**2 - 1.0) + 1.0) ** 2)
        np.testing.assert_allclose(np.asarray(mf.ggx_d(h, alpha)), textbook, rtol=1e-10)
        theta = np.linspace(0.0, np.pi / 2, 200001)
        ht = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
        integrand = np.asarray(mf.ggx_d(ht, alpha))[:, 0] * np.cos(theta) * np.sin(theta) * 2.0 * np.pi
        assert np.trapezoid(integrand, theta) == pytest.approx(1.0, rel=1e-5), alpha


def test_anisotropic_d_is_the_isotropic_one_when_round_and_normalised_when_not():
    rng = np.random.default_rng(2)
    h = upper(rng, 400)
    np.testing.assert_allclose(np.asarray(mf.ggx_d_aniso(h, 0.3, 0.3)), np.asarray(mf.ggx_d(h, 0.3)), rtol=1e-10)
    theta, phi = np.meshgrid(np.linspace(0, np.pi / 2, 1501), np.linspace(0, 2 * np.pi, 1501), indexing="ij")
    hh = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1).reshape(-1, 3)
    d = np.asarray(mf.ggx_d_aniso(hh, 0.2, 0.6)).reshape(theta.shape)
    inner = np.trapezoid(d * np.cos(theta) * np.sin(theta), phi[0], axis=1)
    assert np.trapezoid(inner, theta[:, 0]) == pytest.approx(1.0, rel=1e-4)


def test_g1_is_walters_closed_form_and_one_over_one_plus_lambda():
    rng = np.random.default_rng(3)
    w = upper(rng, 400)
    c = w[:, 2:3]
    for alpha in (0.05, 0.4, 1.2):
        walter = 2.0 * c / (c + np.sqrt(alpha**2 + (1.0 - alpha**2) * c * c))  # eq. 34
        np.testing.assert_allclose(np.asarray(mf.smith_g1(w, alpha)), walter, rtol=1e-10)
        np.testing.assert_allclose(np.asarray(mf.smith_g1(w, alpha)), 1.0 / (1.0 + np.asarray(mf.smith_lambda(w, alpha))),
                                   rtol=1e-12)


def test_anisotropic_g1_uses_the_roughness_seen_along_the_azimuth():
    """Heitz 2014 eq. 80: alpha_o = sqrt(cos^2 phi ax^2 + sin^2 phi ay^2)."""
    rng = np.random.default_rng(4)
    w = upper(rng, 400)
    phi = np.arctan2(w[:, 1:2], w[:, 0:1])
    alpha_o = np.sqrt(np.cos(phi) ** 2 * 0.1**2 + np.sin(phi) ** 2 * 0.5**2)
    c = w[:, 2:3]
    walter = 2.0 * c / (c + np.sqrt(alpha_o**2 + (1.0 - alpha_o**2) * c * c))
    np.testing.assert_allclose(np.asarray(mf.smith_g1_aniso(w, 0.1, 0.5)), walter, rtol=1e-10)


def test_height_correlated_g2_is_the_gltf_visibility():
    """glTF 2.0 appendix B: V = G2 / (4 |n.l| |n.v|) = 1 / (2 (|n.v| sqrt(a^2 + (1 - a^2) (n.l)^2) + ...))."""
    rng = np.random.default_rng(5)
    wi, wo = upper(rng, 400), upper(rng, 400)
    nl, nv = wi[:, 2:3], wo[:, 2:3]
    for alpha in (0.05, 0.4, 1.0):
        a2 = alpha**2
        v = 0.5 / (nv * np.sqrt(a2 + (1 - a2) * nl**2) + nl * np.sqrt(a2 + (1 - a2) * nv**2))
        np.testing.assert_allclose(np.asarray(mf.smith_g2(wi, wo, alpha)) / (4 * nl * nv), v, rtol=1e-10)


def test_halfwidth_is_where_the_slope_distribution_falls_to_half():
    """D cos^4 th_h (the distribution of microfacet slopes) is half its peak at half the half width
    (a reflected direction turns twice the half vector); D alone is near half there for small alpha."""
    for alpha in (0.01, 0.1, 0.5, 1.0):
        th = mf.halfwidth(alpha) / 2.0
        h = np.array([[math.sin(th), 0.0, math.cos(th)]])
        peak = np.asarray(mf.ggx_d(np.array([[0.0, 0.0, 1.0]]), alpha))[0, 0]
        ratio = float(np.asarray(mf.ggx_d(h, alpha))[0, 0] * math.cos(th) ** 4 / peak)
        assert ratio == pytest.approx(0.5, rel=1e-12), alpha
    alphas = np.array([0.01, 0.1, 0.5, 1.0])  # one width per fit, as the fit driver asks for them
    assert np.asarray(mf.halfwidth(alphas)).tolist() == [mf.halfwidth(float(a)) for a in alphas]


def _values(model, rng):
    p = {k: np.asarray(v) for k, v in model.defaults().items()}
    wi, wo = upper(rng, 64, 80.0), upper(rng, 64, 80.0)
    return np.asarray(model.formula(p, wi, wo))


@pytest.mark.parametrize("name", GGX_MODELS)
@pytest.mark.parametrize("part", ["ggx_d", "ggx_d_aniso", "smith_g1", "smith_g1_aniso", "smith_g2"])
def test_every_ggx_model_evaluates_the_kit(monkeypatch, name, part):
    """Halving one part of the kit changes the model exactly where the model uses that part: a
    model with a copy of its own would not change. Which parts each uses is written out here."""
    uses = {"ggx": {"ggx_d", "smith_g1"}, "gltf:metallic_roughness": {"ggx_d", "smith_g2"},
            "blender:principled": {"ggx_d", "smith_g2"}, "mitsuba:principled": {"ggx_d_aniso", "smith_g1_aniso", "smith_g1"},
            "mitsuba:roughconductor": {"ggx_d", "smith_g1"}, "mitsuba:roughplastic": {"ggx_d", "smith_g1"}}
    model = models.get(name)
    before = _values(model, np.random.default_rng(6))
    original = getattr(mf, part)
    monkeypatch.setattr(mf, part, lambda *a: 0.5 * original(*a))
    after = _values(model, np.random.default_rng(6))
    assert (not np.allclose(after, before, rtol=1e-6)) == (part in uses[name]), (name, part)


@pytest.mark.parametrize("name", GGX_MODELS)
def test_every_ggx_model_takes_its_half_width_from_the_kit(monkeypatch, name):
    model = models.get(name)
    p = {k: float(np.asarray(v).ravel()[0]) for k, v in model.defaults().items()}
    before = model.halfwidth(p)
    monkeypatch.setattr(mf, "halfwidth", lambda alpha: 7.0)
    assert before != 7.0 and model.halfwidth(p) == 7.0
