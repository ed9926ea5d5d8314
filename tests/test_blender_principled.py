"""blender:principled equals Blender 5's Cycles (docs/materials.md#native-materials-and-exports: within 2 %), measured as a gonioreflectometer:
a large plane with the exported material, a sun of angle 0 towards wi, an orthographic camera from
wo, direct light only; the pixel is f (n.wi) E. Broken copies of the formula fail the same check."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdffit import models
from brdffit.models import _cycles_math as cy
from brdffit.models import blender_principled as bp

MODEL = models.get("blender:principled")
TOLERANCE = 0.02  # docs/materials.md#native-materials-and-exports


def random_pairs(rng, n, max_deg=85.0):
    theta = np.radians(rng.uniform(0, max_deg, (n, 2)))
    phi = rng.uniform(0, 2 * np.pi, (n, 2))
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    return d[:, 0], d[:, 1]


def relative_errors(model, cases):
    """max over channels of |model f (n.wi) - Cycles| / (|Cycles| + 1e-4), per sample."""
    out = []
    for params, wi, wo, cycles_values in cases:
        ours = np.asarray(model.eval(params, wi, wo)) * wi[:, 2:3]
        out.append((np.abs(ours - cycles_values) / (np.abs(cycles_values) + 1e-4)).max(1))
    return np.concatenate(out)


@pytest.fixture(scope="module")
def measured(blender):
    """40 random parameter sets (the whole box, roughness 0.01..1 on its log axis) x 12 random
    direction pairs up to 85 degrees, each measured in Cycles from the exported native dict."""
    rng = np.random.default_rng(30)
    cases = []
    for k in range(40):
        params = {n: np.asarray(v) for n, v in MODEL.sample(jax.random.PRNGKey(k)).items()}
        wi, wo = random_pairs(rng, 12)
        cases.append((params, wi, wo, blender.gonio(MODEL.native(params), wi, wo)))
    return cases


def test_equals_cycles_within_two_percent(measured):
    err = relative_errors(MODEL, measured)
    assert err.size == 480
    # measured: median 3e-6, max 2.2e-4 (Cycles runs in float32; the table is a quadrature of
    # Cycles' Monte Carlo one)
    assert err.max() <= TOLERANCE, (np.percentile(err, 99), err.max())


def test_broken_copies_fail_the_same_check(measured):
    """Each copy changes one thing Cycles does; each is caught on the same measurements."""
    not_squared = lambda p, wi, wo: bp.formula({**p, "roughness": jnp.sqrt(p["roughness"])}, wi, wo)  # alpha = r
    swapped = lambda p, wi, wo: bp.formula(p, wo, wi)  # the layering's view cosine taken at the light
    no_layering = lambda p, wi, wo: bp.formula(p, wi, wo) + (1 - p["metallic"]) * p["base_color"] / jnp.pi * (
        1.0 - _layer(p, wo))  # the diffuse not attenuated by the specular layer
    for name, formula in (("roughness not squared", not_squared), ("light and view swapped", swapped),
                          ("no layering", no_layering)):
        err = relative_errors(dataclasses.replace(MODEL, formula=formula), measured)
        assert err.max() > 5 * TOLERANCE, name


def _layer(p, wo):
    """The diffuse weight under the specular layer (the model's own terms, for the broken copy)."""
    f0 = cy.f0_from_ior(p["ior"]) * 2.0 * bp.SPECULAR_IOR_LEVEL
    eta = cy.ior_from_f0(f0)
    f0s = jnp.clip(f0 * p["specular_tint"], 0.0, 1.0)
    e = cy.lookup_3d(jnp.asarray(cy.gen_schlick_ior_s()), p["roughness"], jnp.clip(wo[:, 2:3], 1e-7, 1),
                     jnp.sqrt((eta - 1) / (eta + 1)))
    return jnp.where(f0 > 0, jnp.clip(1 - (f0s + (1 - f0s) * e), 0, 1), 1.0)


def test_table_at_zero_roughness_is_the_fresnel_curve():
    """At roughness 0 the visible normal is the normal: the table's first column is the remapped
    Fresnel factor at the view cosine, here from the textbook Fresnel equations (Hecht, Optics)."""
    table = cy.gen_schlick_ior_s()
    g = np.arange(16) / 15
    mu = np.clip(g, 1e-4, 1)
    z = np.clip(g, 1e-4, 0.99)
    for k in (3, 8, 15):
        n = (1 + z[k] ** 2) / (1 - z[k] ** 2)
        sin_t = np.sqrt(1 - mu**2) / n
        cos_t = np.sqrt(1 - sin_t**2)
        rs = (mu - n * cos_t) / (mu + n * cos_t)
        rp = (n * mu - cos_t) / (n * mu + cos_t)
        f = 0.5 * (rs**2 + rp**2)
        f0 = ((n - 1) / (n + 1)) ** 2
        np.testing.assert_allclose(table[k, :, 0], np.clip((f - f0) / (1 - f0), 0, 1), atol=2e-3)
    assert np.all((table >= 0) & (table <= 1))


def test_native_pins_the_distribution_and_every_input_the_formula_assumes():
    native = MODEL.native({"base_color": [0.1, 0.2, 0.3], "metallic": 0.4, "roughness": 0.3, "ior": 1.45,
                           "specular_tint": 0.7})
    assert native["distribution"] == "GGX"
    inputs = native["inputs"]
    assert inputs["Base Color"] == pytest.approx([0.1, 0.2, 0.3]) and inputs["Specular Tint"] == pytest.approx([0.7] * 3)
    assert (inputs["Metallic"], inputs["Roughness"], inputs["IOR"], inputs["Specular IOR Level"]) == pytest.approx(
        (0.4, 0.3, 1.45, 0.5))
    assert all(inputs[k] == 0.0 for k in ("Coat Weight", "Sheen Weight", "Transmission Weight", "Subsurface Weight",
                                           "Diffuse Roughness", "Anisotropic"))
    assert MODEL.is_native and MODEL.target == "blender" and not MODEL.reciprocal
    with pytest.raises(ValueError, match="ior"):
        MODEL.native({**{p.name: p.default for p in MODEL.params}, "ior": 0.9})


def test_no_specular_layer_is_lambert():
    """IOR 1 leaves Cycles no specular closure (F0 = 0): base_color / pi exactly."""
    wi, wo = random_pairs(np.random.default_rng(2), 50)
    p = {"base_color": [0.3, 0.6, 0.9], "metallic": 0.0, "roughness": 0.4, "ior": 1.0,
         "specular_tint": 1.0}
    np.testing.assert_allclose(np.asarray(MODEL.eval(p, wi, wo)), np.broadcast_to([[0.3, 0.6, 0.9]], (50, 3)) / np.pi,
                               rtol=1e-12)
