"""render_sphere against an independent closed-form shading in NumPy (docs/validation.md#validation-rendering framing).

The closed form knows only docs/validation.md#validation-rendering: pixel (i, j) covers [x0, x0 + 2/size] x [y0 - 2/size, y0] with
centre x = 2(j + 0.5)/size - 1, y = 1 - 2(i + 0.5)/size; the box filter averages over it. A point
(x, y) on the disc has normal n = (x, y, sqrt(1 - x^2 - y^2)), the view is v = +z, radiance is
f_r(wi, wo) (n.l) E. The tangent frame is the documented one (scene.py): s = (z, 0, -x)/|.|,
t = n x s. f_r comes from ``model.eval`` (or Mitsuba's ``measured`` plugin for RGL files); the
geometry, frames, cosines and the footprint average are computed here.
"""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.render import render_sphere
from brdffit.render.bsdf import as_source

from conftest import NO_DATA, RGL_FILES


def closed_form(brdf, lights, size: int, sub: int = 8, irradiance: float = 1.0) -> np.ndarray:
    """(L, size, size, 3): each pixel the mean over sub x sub points of its footprint."""
    off = (np.arange(sub) + 0.5) / sub  # positions inside a pixel, 0..1
    u = (np.arange(size)[:, None] + off[None, :]).reshape(-1) * (2.0 / size) - 1.0  # x of columns
    x = np.tile(u, size * sub)  # rows of sub-samples, top to bottom
    y = -np.repeat(u, size * sub)
    r2 = x * x + y * y
    on = r2 < 1.0
    z = np.sqrt(np.maximum(1.0 - r2, 0.0))
    n = np.stack([x, y, z], -1)[on]
    s = np.stack([n[:, 2], np.zeros(len(n)), -n[:, 0]], -1)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    t = np.cross(n, s)
    v = np.array([0.0, 0.0, 1.0])
    wo = np.stack([s @ v, t @ v, n @ v], -1)
    out = []
    for lgt in np.asarray(lights, np.float64):
        wi = np.stack([s @ lgt, t @ lgt, n @ lgt], -1)
        lit = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        rad = np.zeros((len(n), 3))
        rad[lit] = brdf(wi[lit], wo[lit]) * wi[lit, 2:3] * irradiance
        full = np.zeros((size * sub * size * sub, 3))
        full[on] = rad
        img = full.reshape(size, sub, size, sub, 3).mean(axis=(1, 3))
        out.append(img)
    return np.asarray(out)


def interior(size: int, radius: float = 0.9) -> np.ndarray:
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    x, y = np.meshgrid(c, -c)
    return x * x + y * y < radius * radius


def mean_relative_difference(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """sum |a - b| / sum |b| over the masked pixels of all images and channels."""
    m = np.broadcast_to(mask[None, ..., None], a.shape)
    return float(np.abs(a - b)[m].sum() / np.abs(b)[m].sum())


def unit(theta_deg, phi_deg):
    t, p = np.deg2rad(theta_deg), np.deg2rad(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


LIGHTS = np.array([unit(0, 0), unit(35, 120), unit(65, 300)])
GGX = {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.3, "f0": 0.1}


def test_ggx_matches_closed_form():
    size = 48
    img = render_sphere(("ggx", GGX), LIGHTS, size=size, spp=64)
    ref = closed_form(as_source(("ggx", GGX)).brdf, LIGHTS, size)
    assert img.shape == (3, size, size, 3) and img.dtype == np.float32
    assert mean_relative_difference(img, ref, interior(size)) < 0.01
    # outside the disc (pixel centres) is exactly zero
    assert np.all(img[:, ~interior(size, 1.0)] == 0)


def test_framing_orientation_and_irradiance():
    """Light from +x lights the right half, from +y the top half; radiance scales with irradiance."""
    size = 32
    img = render_sphere(("lambert", {"kd": 0.5}), [unit(90, 0), unit(90, 90)], size=size, spp=4, irradiance=2.0)
    assert img[0, size // 2, -4].mean() > 0 and img[0, size // 2, 3].mean() == 0
    assert img[1, 3, size // 2].mean() > 0 and img[1, -4, size // 2].mean() == 0
    # (theta, phi) pairs give the same images as unit vectors
    again = render_sphere(("lambert", {"kd": 0.5}), np.deg2rad([[90, 0], [90, 90]]), size=size, spp=4, irradiance=2.0)
    np.testing.assert_allclose(again, img, rtol=1e-6, atol=1e-7)
    # centre pixel under a light from the camera: kd/pi * cos 0 * E (the pixel is nearly flat)
    centre = render_sphere(("lambert", {"kd": 0.5}), [0, 0, 1], size=size, spp=4, irradiance=2.0)
    np.testing.assert_allclose(centre[0, size // 2, size // 2], 0.5 / np.pi * 2.0, rtol=2e-3)


#: Anisotropic settings so that the tangent frame matters (axis-swapped values render differently).
SPECIAL = {
    "ward": {"kd": 0.1, "ks": 0.3, "alpha_x": 0.1, "alpha_y": 0.4},
    "ashikhmin_shirley": {"rd": 0.1, "rs": 0.3, "nu": 10.0, "nv": 300.0},
}


@pytest.mark.parametrize("name", [*models.names(), "lambert+ggx+ggx"])
def test_every_model_matches_closed_form(name):
    model = models.get(name)
    params = SPECIAL.get(name, {k: np.asarray(v) for k, v in model.defaults().items()})
    size = 32
    img = render_sphere((name, params), LIGHTS, size=size, spp=64)
    assert np.all(np.isfinite(img)) and np.all(img >= 0) and img.max() > 0
    ref = closed_form(as_source((name, params)).brdf, LIGHTS, size)
    assert mean_relative_difference(img, ref, interior(size)) < 0.01, name


def test_anisotropic_frame_is_the_documented_one():
    """Swapping the roughness axes changes the image and the closed form follows (frame check)."""
    size = 32
    p = SPECIAL["ward"]
    q = {**p, "alpha_x": p["alpha_y"], "alpha_y": p["alpha_x"]}
    a = render_sphere(("ward", p), LIGHTS[1:2], size=size, spp=64)
    b = render_sphere(("ward", q), LIGHTS[1:2], size=size, spp=64)
    m = interior(size)
    assert mean_relative_difference(a, b, m) > 0.1
    assert mean_relative_difference(b, closed_form(as_source(("ward", q)).brdf, LIGHTS[1:2], size), m) < 0.02


@pytest.mark.skipif(not RGL_FILES, reason=NO_DATA)
@pytest.mark.parametrize("path", RGL_FILES[:2] + [p for p in RGL_FILES if "golden" in p.name][:1], ids=lambda p: p.stem)
def test_rgl_matches_closed_form(path):
    size = 48
    img = render_sphere(path, LIGHTS, size=size, spp=64)
    ref = closed_form(as_source(path).brdf, LIGHTS, size)
    assert np.all(np.isfinite(img))
    assert mean_relative_difference(img, ref, interior(size)) < 0.02


def test_fitresult_source_is_duck_typed():
    class Fit:
        model = models.get("ggx")
        params = GGX

    a = render_sphere(Fit(), LIGHTS[:1], size=16, spp=4)
    b = render_sphere(("ggx", GGX), LIGHTS[:1], size=16, spp=4)
    np.testing.assert_array_equal(a, b)


def test_bad_lights_and_sources():
    with pytest.raises(ValueError):
        render_sphere(("lambert", {"kd": 0.5}), [[0, 0, 0]], size=8)
    with pytest.raises(ValueError):
        render_sphere(("lambert", {"kd": 0.5}), np.zeros((2, 4)), size=8)
    with pytest.raises(brdffit.InputError, match="no such file"):
        render_sphere("/nonexistent/x.bsdf", [0, 0, 1], size=8)
    with pytest.raises(TypeError):
        render_sphere(42, [0, 0, 1], size=8)


def test_table_source_matches_closed_form():
    """A UBO-81 Measurement renders as the closed form of its interpolated table."""
    from brdffit import Measurement
    from brdffit.grid import ubo_pairs

    wi, wo = ubo_pairs()
    values = np.random.default_rng(3).uniform(0.05, 0.5, (6561, 3))
    m = Measurement(wi, wo, values, name="random_table", grid="ubo81")
    size = 32
    img = render_sphere(m, LIGHTS, size=size, spp=64)
    ref = closed_form(as_source(m).brdf, LIGHTS, size)
    assert mean_relative_difference(img, ref, interior(size)) < 0.01


def test_top_level_exports():
    assert brdffit.render_sphere is render_sphere
    assert brdffit.validate is brdffit.render.validate and brdffit.Validation is brdffit.render.Validation


def test_non_finite_brdf_values_are_not_hidden():
    """The callback passes what the BRDF returns: a NaN shows up in the image (no silent clean-up)."""
    from brdffit.render.bsdf import Source

    def brdf(wi, wo):
        out = np.full((wi.shape[0], 3), 0.1)
        out[wi[:, 0] > 0.5] = np.nan
        return out

    img = render_sphere(Source("model", "nan test", brdf), [0, 0, 1], size=16, spp=1)
    assert np.isnan(img).any() and np.isfinite(img[0, 8, 8]).all()
