"""The light/view order and the cosine at the Mitsuba boundary, pinned with Mitsuba's own BSDFs and
closed forms (no shared data needed): ``eval_bsdf`` (how a render's reference is tabulated) and the
RGL reader (``brdffit.load`` of a ``.bsdf``) must both return f_r(light, view) in 1/sr, i.e. Mitsuba's
``eval(si.wi = view, wo = light)`` divided by cos(theta_light)."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.grid import spherical_to_cartesian
from tensor_file import isotropic_material

pytestmark = pytest.mark.mitsuba


def _pairs(n=40, seed=3):
    rng = np.random.default_rng(seed)
    light = spherical_to_cartesian(rng.uniform(0.05, 1.35, n), rng.uniform(0, 2 * np.pi, n))
    view = spherical_to_cartesian(rng.uniform(0.05, 1.35, n), rng.uniform(0, 2 * np.pi, n))
    return light, view


def _mi():
    from brdffit._mitsuba import mitsuba

    return mitsuba()


def test_eval_bsdf_diffuse_is_albedo_over_pi():
    from brdffit.render.bsdf import eval_bsdf

    bsdf = _mi().load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}})
    light, view = _pairs()
    f = eval_bsdf(bsdf, light, view)
    np.testing.assert_allclose(f, np.broadcast_to(np.array([0.2, 0.5, 0.8]) / np.pi, f.shape), rtol=1e-5)


def ggx_closed_form(alpha, light, view):
    """Walter et al. 2007 GGX with Smith G1 per direction and F = 1 (roughconductor, material 'none')."""
    h = light + view
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ci, co, ch = light[:, 2], view[:, 2], h[:, 2]
    a2 = alpha * alpha
    D = a2 / (np.pi * (ch * ch * (a2 - 1) + 1) ** 2)

    def g1(c):
        t2 = (1 - c * c) / (c * c)
        return 2 / (1 + np.sqrt(1 + a2 * t2))

    return D * g1(ci) * g1(co) / (4 * ci * co)


def test_eval_bsdf_roughconductor_equals_walter_ggx():
    from brdffit.render.bsdf import eval_bsdf

    alpha = 0.4
    bsdf = _mi().load_dict({"type": "roughconductor", "distribution": "ggx", "alpha": alpha, "material": "none"})
    light, view = _pairs(seed=5)
    f = eval_bsdf(bsdf, light, view)
    expect = ggx_closed_form(alpha, light, view)
    np.testing.assert_allclose(f, np.repeat(expect[:, None], 3, axis=1), rtol=2e-4, atol=1e-6)


def _material_closed_form(light, view, rgb0, rgb1):
    """f_r(light, view) of ``isotropic_material``: its eval depends on theta(si.wi = view) only."""
    t = np.arccos(np.clip(view[:, 2], -1, 1)) / (np.pi / 2)
    stored = np.asarray(rgb0) + (np.asarray(rgb1) - np.asarray(rgb0)) * t[:, None]
    return stored / light[:, 2:3]


RGB0, RGB1 = [0.2, 0.4, 0.6], [1.0, 0.9, 0.3]


def test_eval_bsdf_on_a_non_reciprocal_measured_material(tmp_path):
    from brdffit.render.bsdf import eval_bsdf, measured_bsdf

    path = isotropic_material(tmp_path / "m.bsdf", RGB0, RGB1)
    light, view = _pairs(seed=7)
    f = eval_bsdf(measured_bsdf(path), light, view)
    expect = _material_closed_form(light, view, RGB0, RGB1)
    np.testing.assert_allclose(f, expect, rtol=2e-4)
    # the swapped order differs clearly (the guard is not vacuous)
    assert np.max(np.abs(_material_closed_form(view, light, RGB0, RGB1) / expect - 1)) > 0.3


def test_rgl_reader_light_view_and_cosine(tmp_path):
    path = isotropic_material(tmp_path / "m.bsdf", RGB0, RGB1)
    light, view = _pairs(seed=11)
    m = brdffit.load(path, wi=light, wo=view)
    np.testing.assert_allclose(np.asarray(m.wi), light, atol=1e-12)
    np.testing.assert_allclose(np.asarray(m.values), _material_closed_form(light, view, RGB0, RGB1), rtol=2e-4)
    # on the UBO-81 grid too (default directions), table[light, view]
    t = brdffit.load(path).table()
    d = brdffit.ubo_directions()
    k_l, k_v = 40, 7
    np.testing.assert_allclose(t[k_l, k_v], _material_closed_form(d[[k_l]], d[[k_v]], RGB0, RGB1)[0], rtol=2e-4)
