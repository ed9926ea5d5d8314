"""Native models equal their renderer (docs/materials.md#native-materials-and-exports): the ``mitsuba:*`` formulas against Mitsuba 3's
own ``bsdf.eval``, ``gltf:metallic_roughness`` against an independent implementation of the glTF 2.0
spec's appendix B; deliberately broken copies are caught."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import brdffit
import brdffit.models as models
from brdffit.models import _mitsuba_math, mitsuba_principled, mitsuba_roughconductor, mitsuba_roughplastic

MITSUBA_MODELS = ["mitsuba:roughconductor", "mitsuba:roughplastic", "mitsuba:principled"]
PARAM_SETS, PAIRS = 24, 400


def directions(rng, n, max_deg=85.0):
    """Directions uniform in solid angle up to max_deg from the normal."""
    cos = rng.uniform(math.cos(math.radians(max_deg)), 1.0, n)
    sin = np.sqrt(1 - cos**2)
    phi = rng.uniform(0, 2 * np.pi, n)
    return np.stack([sin * np.cos(phi), sin * np.sin(phi), cos], -1)


def relative_errors(model, formula=None, seed=0):
    """|ours - Mitsuba| / (|Mitsuba| + floor) over random parameter sets and direction pairs up to 85
    degrees. Mitsuba evaluates in float32, so the floor is 1e-4 of the largest value of each set
    (values that small are float32 round-off of the peak's terms, not the BRDF)."""
    from brdffit._mitsuba import mitsuba
    from brdffit.render.bsdf import eval_bsdf

    mi = mitsuba()
    m = models.get(model)
    rng = np.random.default_rng(seed)
    out = []
    for s in range(PARAM_SETS):
        p = {k: np.asarray(v) for k, v in m.sample(jax.random.PRNGKey(seed * 1000 + s)).items()}
        wi, wo = directions(rng, PAIRS), directions(rng, PAIRS)
        ours = np.asarray((formula or m.formula)({k: np.asarray(v) for k, v in p.items()}, wi, wo))
        ours = np.broadcast_to(ours, (PAIRS, 3))
        theirs = eval_bsdf(mi.load_dict(m.native(p)), wi, wo)
        out.append(np.abs(ours - theirs) / (np.abs(theirs) + 1e-4 * np.abs(theirs).max()))
    return np.concatenate(out).ravel()


#: roughplastic's formula reads its two precomputed terms from tables of Mitsuba's quadratures, smooth
#: between their nodes, where Mitsuba's internal reflectance is rough at the 1e-4 level in alpha
#: (tests/test_roughplastic_tables.py): measured 1.8e-3 at the 99th percentile, short of the contract's
#: 1e-3 (the quadratures computed in place: 1.1e-5, but a fit 450x slower and 2.5 GB large). A known
#: shortfall, kept visible: the contract's test fails for it (strict), and a second test holds it at the
#: level measured.
ROUGHPLASTIC_SHORT = pytest.mark.xfail(strict=True, reason="tabulated Mitsuba quadratures: 1.8e-3 at p99, "
                                                           "contract 1e-3 (see ROUGHPLASTIC_SHORT)")


@pytest.mark.mitsuba
@pytest.mark.parametrize("model", [pytest.param(m, marks=ROUGHPLASTIC_SHORT) if m == "mitsuba:roughplastic" else m
                                   for m in MITSUBA_MODELS])
def test_mitsuba_models_equal_mitsuba(model):
    err = relative_errors(model)
    assert np.percentile(err, 99) <= 1e-3, np.percentile(err, [50, 99, 100])


@pytest.mark.mitsuba
def test_roughplastic_stays_at_the_level_its_tables_reach():
    err = relative_errors("mitsuba:roughplastic")
    assert np.percentile(err, 99) <= 2.5e-3, np.percentile(err, [50, 99, 100])


def _schlick(cos, *args):
    """A wrong Fresnel for the broken copies: Schlick's, with f0 0.04."""
    return 0.04 + 0.96 * (1 - cos) ** 5


@pytest.mark.mitsuba
def test_broken_copies_are_caught(monkeypatch):
    """The equality test discriminates: each deliberately broken formula leaves the tolerance."""
    conductor = models.get("mitsuba:roughconductor")
    squared = lambda p, wi, wo: conductor.formula({**p, "alpha": p["alpha"] ** 2}, wi, wo)  # noqa: E731
    assert np.percentile(relative_errors("mitsuba:roughconductor", squared, seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:
        patch.setattr(mitsuba_roughconductor, "fresnel_conductor", lambda c, eta, k: _schlick(c) + 0 * eta)
        assert np.percentile(relative_errors("mitsuba:roughconductor", seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:  # roughplastic's diffuse term without its internal reflectance
        tables = _mitsuba_math.rough_tables
        patch.setattr(mitsuba_roughplastic, "rough_tables", lambda alpha, eta: (tables(alpha, eta)[0], 0.0 * alpha))
        assert np.percentile(relative_errors("mitsuba:roughplastic", seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:
        patch.setattr(mitsuba_roughplastic, "fresnel_dielectric", lambda c, eta: (_schlick(c), None, None))
        assert np.percentile(relative_errors("mitsuba:roughplastic", seed=1), 99) > 1e-2
    principled = models.get("mitsuba:principled")
    unsquared = lambda p, wi, wo: principled.formula({**p, "roughness": np.sqrt(p["roughness"])}, wi, wo)  # noqa: E731
    assert np.percentile(relative_errors("mitsuba:principled", unsquared, seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:
        patch.setattr(mitsuba_principled, "fresnel_dielectric", lambda c, eta: (_schlick(c), None, None))
        assert np.percentile(relative_errors("mitsuba:principled", seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:  # Burley's diffuse without its retro-reflection
        lambertian = lambda cos: 0.0 * cos  # noqa: E731
        patch.setattr(mitsuba_principled, "schlick_weight", lambertian)
        assert np.percentile(relative_errors("mitsuba:principled", seed=1), 99) > 1e-2
    with monkeypatch.context() as patch:  # the clearcoat with a GGX of its alpha instead of GTR1
        patch.setattr(mitsuba_principled, "gtr1_d", _mitsuba_math.ggx_d)
        assert np.percentile(relative_errors("mitsuba:principled", seed=1), 99) > 1e-2


# -- glTF: the spec's appendix B, written again independently -------------------------------------

def gltf_reference(base, metallic, roughness, L, V):
    """glTF 2.0 appendix B in its mix()/fresnel_mix() form, NumPy, float64: material =
    mix(dielectric_brdf, metal_brdf, metallic) with the height-correlated Smith G written as G (not
    as the visibility V) and D in the spec's own (N.H)^2 (alpha^2 - 1) + 1 form."""
    N = np.array([0.0, 0.0, 1.0])
    H = (L + V) / np.linalg.norm(L + V, axis=1, keepdims=True)
    a = roughness**2
    NL, NV, NH = L @ N, V @ N, H @ N
    VH, HL = np.sum(V * H, 1), np.sum(H * L, 1)
    D = a**2 * (NH > 0) / (np.pi * (NH**2 * (a**2 - 1) + 1) ** 2)
    G = (2 * np.abs(NL) * np.abs(NV) * (HL > 0) * (VH > 0)
         / (np.abs(NV) * np.sqrt(a**2 + (1 - a**2) * NL**2) + np.abs(NL) * np.sqrt(a**2 + (1 - a**2) * NV**2)))
    specular_brdf = (D * G / (4 * np.abs(NL) * np.abs(NV)))[:, None]
    diffuse_brdf = np.asarray(base)[None, :] / np.pi

    def mix(x, y, t):
        return x * (1 - t) + y * t

    def fresnel_mix(ior, base_layer, layer):
        f0 = ((1 - ior) / (1 + ior)) ** 2
        fr = (f0 + (1 - f0) * (1 - np.abs(VH)) ** 5)[:, None]
        return mix(base_layer, layer, fr)

    def conductor_fresnel(f0, bsdf):
        return bsdf * (f0 + (1 - f0) * (1 - np.abs(VH)[:, None]) ** 5)

    metal_brdf = conductor_fresnel(np.asarray(base)[None, :], specular_brdf)
    dielectric_brdf = fresnel_mix(1.5, diffuse_brdf, specular_brdf)
    return mix(dielectric_brdf, metal_brdf, metallic)


def gltf_errors(formula=None, seed=0):
    m = models.get("gltf:metallic_roughness")
    rng = np.random.default_rng(seed)
    out = []
    for s in range(PARAM_SETS):
        p = {k: np.asarray(v) for k, v in m.sample(jax.random.PRNGKey(seed * 1000 + s)).items()}
        L, V = directions(rng, PAIRS), directions(rng, PAIRS)
        ours = np.asarray((formula or m.formula)(p, L, V))
        ref = gltf_reference(p["base_color"], p["metallic"][0], p["roughness"][0], L, V)
        out.append(np.abs(ours - ref) / np.abs(ref))
    return np.concatenate(out).ravel()


def test_gltf_equals_the_spec():
    assert gltf_errors().max() <= 1e-5


def test_gltf_broken_copies_are_caught():
    m = models.get("gltf:metallic_roughness")
    unsquared = lambda p, wi, wo: m.formula({**p, "roughness": np.sqrt(p["roughness"])}, wi, wo)  # noqa: E731
    assert gltf_errors(unsquared, seed=2).max() > 1e-2
    no_metal_tint = lambda p, wi, wo: m.formula({**p, "metallic": 0.0 * p["metallic"]}, wi, wo)  # noqa: E731
    assert gltf_errors(no_metal_tint, seed=2).max() > 1e-2


# -- what native() writes, and what native models refuse -------------------------------------------

def test_native_writes_every_setting_it_relies_on():
    c = models.get("mitsuba:roughconductor")
    d = c.native(c.defaults())
    assert d["type"] == "roughconductor" and d["distribution"] == "ggx" and "material" not in d
    assert d["eta"]["type"] == d["k"]["type"] == "spectrum"  # not RGB: see mitsuba_roughconductor
    p = models.get("mitsuba:roughplastic")
    d = p.native(p.defaults())
    assert (d["type"], d["distribution"], d["ext_ior"], d["nonlinear"]) == ("roughplastic", "ggx", 1.0, False)
    g = models.get("gltf:metallic_roughness")
    d = g.native({"base_color": [0.1, 0.2, 0.3], "metallic": 0.5, "roughness": 0.25})
    assert d == {"pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.2, 0.3, 1.0], "metallicFactor": 0.5,
                                          "roughnessFactor": 0.25}}


def test_native_models_refuse_composition_and_out_of_range_values():
    with pytest.raises(KeyError, match="do not compose"):
        models.get("lambert+mitsuba:roughplastic")
    p = models.get("mitsuba:roughplastic")
    with pytest.raises(ValueError, match="'diffuse_reflectance' = \\[1.5, 0.2, 0.2\\] outside \\[0, 1\\]"):
        p.native({**p.defaults(), "diffuse_reflectance": [1.5, 0.2, 0.2]})
    with pytest.raises(ValueError, match="not a native model"):
        models.get("ggx").native(models.get("ggx").defaults())
    assert models.get("gltf:metallic_roughness").is_native and not models.get("ggx").is_native


@pytest.mark.parametrize("model", [*MITSUBA_MODELS, "gltf:metallic_roughness"])
def test_native_models_fit_through_the_common_path(model):
    """Data made by the model itself (no noise) are fitted back to a small loss by brdffit.fit."""
    m = models.get(model)
    truth = m.sample(jax.random.PRNGKey(7), margin=0.2)
    wi, wo = brdffit.ubo_pairs()
    values = np.asarray(m.eval(truth, wi, wo))
    fit = brdffit.fit(brdffit.Measurement(wi, wo, values, grid="ubo81", name="synthetic"), model)
    assert fit.model.name == model and fit.metrics["log_rmse"] < 1e-3, (fit.status, fit.metrics, fit.params, truth)
    m.native(fit.params)  # a native fit exports as it is: inside the renderer's ranges
