"""The ``brdffit`` plugin renders right in Mitsuba's default symbolic mode (docs/materials.md#a-fit-in-any-mitsuba-scene): the fit's JAX
formula translated to Dr.Jit, no ``evaluated_calls()`` needed, parameters (and parameter maps)
traversable and differentiable by ``prb``. Before, such a render came out black without a word, and
formulas reading a table, and maps, needed evaluated_calls()."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import drjit as dr
import jax
import numpy as np
import pytest

import brdffit
import brdffit.models as models
from brdffit._mitsuba import mitsuba
from brdffit.render.bsdf import eval_bsdf

pytestmark = pytest.mark.mitsuba
mi = mitsuba()
GGX = {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": 0.3, "f0": 0.1}
LIGHT = np.array([0.4, 0.3, np.sqrt(1 - 0.25)])


def scene(bsdf, size=32, integrator="direct"):
    """A user's scene written by hand: unit sphere, orthographic camera on +z, one sun."""
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, **({"emitter_samples": 1, "bsdf_samples": 0} if integrator == "direct" else {})},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
                   "sampler": {"type": "stratified", "sample_count": 16}},
        "ball": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": [float(-x) for x in LIGHT], "irradiance": {"type": "rgb", "value": 1.0}},
    })


def closed_form(model, params, size):
    """f_r(l, v) (n.l) at the pixel centres of the sphere (docs/validation.md#validation-rendering framing), NumPy."""
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 1.0
    n = np.stack([x[inside], y[inside], np.sqrt(1 - x[inside] ** 2 - y[inside] ** 2)], -1)
    # the sphere's shading frame: only n matters for an isotropic model; l and v in that frame
    t = np.cross([0.0, 1.0, 0.0], n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    frame = np.stack([t, b, n], 1)
    l_loc = np.einsum("nij,j->ni", frame, LIGHT)
    v_loc = np.einsum("nij,j->ni", frame, [0.0, 0.0, 1.0])
    f = np.asarray(models.get(model).eval(params, l_loc, v_loc))
    out = np.zeros((size, size, 3))
    out[inside] = np.where(l_loc[:, 2:3] > 0, f * l_loc[:, 2:3], 0.0)
    return out, inside


def test_plugin_renders_outside_evaluated_calls():
    fit = brdffit.FitResult.from_dict({"model": "ggx", "params": GGX, "converged": True})
    size = 48
    image = np.asarray(mi.render(scene(fit.to_mitsuba(), size), spp=16))[..., :3]  # symbolic: no context
    expected, inside = closed_form("ggx", GGX, size)
    core = inside & (np.hypot(*np.meshgrid(np.arange(size) - size / 2 + 0.5, np.arange(size) - size / 2 + 0.5)) < 0.85 * size / 2)
    assert image[core].mean() > 0.02  # not black
    rel = np.abs(image[core] - expected[core]).mean() / expected[core].mean()
    assert rel < 0.01, rel  # pixel footprint vs pixel centre: a small difference, not a wrong image


@pytest.mark.parametrize("name", ["lambert", "phong", "phong_classic", "blinn_phong", "ward", "torrance_sparrow",
                                  "cook_torrance", "ggx", "oren_nayar", "lafortune", "ashikhmin_shirley",
                                  "lambert+ggx+ggx", "gltf:metallic_roughness", "mitsuba:roughconductor",
                                  "mitsuba:principled", "blender:principled"])
def test_the_translated_formula_equals_the_model(name):
    from brdffit.render.sampling import Mixture
    from brdffit.render.symbolic_bsdf import symbolic_bsdf

    model = models.get(name)
    rng = np.random.default_rng(3)
    worst = []
    for s in range(4):
        p = {k: np.asarray(v) for k, v in model.sample(jax.random.PRNGKey(s), margin=0.1).items()}
        bsdf = symbolic_bsdf(model, p, Mixture.cosine(), name)
        cos = rng.uniform(np.cos(np.radians(85)), 1, (2, 300))
        phi = rng.uniform(0, 2 * np.pi, (2, 300))
        wi, wo = (np.stack([np.sqrt(1 - c**2) * np.cos(f), np.sqrt(1 - c**2) * np.sin(f), c], -1) for c, f in zip(cos, phi))
        ours = eval_bsdf(bsdf, wi, wo)
        # in float32 as Mitsuba computes (the formulas' overflow caps depend on the precision)
        p32 = {k: v.astype(np.float32) for k, v in p.items()}
        ref = np.asarray(model.eval(p32, wi.astype(np.float32), wo.astype(np.float32)), np.float64)
        ref = np.broadcast_to(ref, ours.shape)
        worst.append(np.percentile(np.abs(ours - ref) / (np.abs(ref) + 1e-6 * np.abs(ref).max()), 99))
    assert max(worst) < 1e-4, worst


def _prb_gradient(bsdf, key):
    """The image and d mean(image) / d params[key] of a prb render of the test scene."""
    sc = scene(bsdf, 16, integrator="prb")
    params = mi.traverse(sc)
    dr.enable_grad(params[key])
    params.update()
    image = mi.render(sc, params, spp=4, seed=1)
    dr.backward(dr.mean(image, axis=None))
    return np.asarray(image), np.asarray(dr.grad(params[key])).reshape(-1), set(params.keys())


def test_parameters_are_traversable_and_prb_differentiates_them():
    """prb's gradient of the plugin equals prb's gradient of Mitsuba's own roughconductor where the two
    BSDFs are the same function (ggx with kd 0 and f0 1 is roughconductor with the default eta 0 + 1i,
    F = 1): the same renderer differentiates both, so they must agree, term for term."""
    ks = [0.6, 0.5, 0.4]
    ours = brdffit.FitResult.from_dict({"model": "ggx", "params": {"kd": 0.0, "ks": ks, "alpha": 0.3, "f0": 1.0},
                                        "converged": True}).to_mitsuba()
    native = {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3,
              "specular_reflectance": {"type": "rgb", "value": ks}}
    image, grad, keys = _prb_gradient(ours, "ball.bsdf.ks")
    native_image, native_grad, _ = _prb_gradient(native, "ball.bsdf.specular_reflectance.value")
    assert {"ball.bsdf.kd", "ball.bsdf.ks", "ball.bsdf.alpha", "ball.bsdf.f0"} <= keys
    assert image.mean() > 0.01 and np.allclose(image, native_image, rtol=1e-4, atol=1e-6)
    assert np.all(np.isfinite(grad)) and np.all(grad > 0)
    assert grad == pytest.approx(native_grad, rel=1e-3)


def test_an_unrelated_symbolic_render_is_unaffected():
    fit = brdffit.FitResult.from_dict({"model": "ggx", "params": GGX, "converged": True})
    kept = mi.load_dict(fit.to_mitsuba())  # a brdffit BSDF alive somewhere in the process
    grey = np.asarray(mi.render(scene({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}, 16), spp=4))
    assert np.isfinite(grey).all() and grey.max() > 0.05
    del kept


def test_scalar_variant_renders_the_plugin():
    """A variant is chosen once per process: the scalar one in a child (a user without libLLVM)."""
    code = textwrap.dedent(f"""
        import numpy as np, mitsuba as mi
        mi.set_variant("scalar_rgb")
        import brdffit
        brdffit.register_mitsuba()
        d = {{"type": "brdffit", "model": "ggx", "kd": {GGX['kd']}, "ks": {GGX['ks']}, "alpha": 0.3, "f0": 0.1}}
        s = mi.load_dict({{"type": "scene", "integrator": {{"type": "direct"}},
            "sensor": {{"type": "orthographic", "film": {{"type": "hdrfilm", "width": 8, "height": 8}},
                        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0])}},
            "ball": {{"type": "sphere", "bsdf": d}},
            "sun": {{"type": "directional", "direction": [0, 0, -1]}}}})
        print("bsdf", type(s.shapes()[0].bsdf()).__name__)
        print("mean", float(np.asarray(mi.render(s, spp=1)).mean()))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "bsdf SymbolicBSDF" in run.stdout and float(run.stdout.split("mean")[-1]) > 0.01


def _mean_and_gradient(bsdf, key, spp=8):
    """mean(image) of a prb render of the test scene and its derivative by params[key] (a width-1
    or width-3 parameter; every entry), outside evaluated_calls()."""
    sc = scene(bsdf, 16, integrator="prb")
    params = mi.traverse(sc)
    dr.enable_grad(params[key])
    params.update()
    image = mi.render(sc, params, spp=spp, seed=2)
    mean = dr.mean(image, axis=None)
    dr.backward(mean)
    return float(np.asarray(mean).reshape(-1)[0]), np.asarray(dr.grad(params[key])).reshape(-1)


def _mean(bsdf, key, value, spp=8):
    sc = scene(bsdf, 16, integrator="prb")
    params = mi.traverse(sc)
    params[key] = type(params[key])(value)
    params.update()
    return float(np.asarray(mi.render(sc, params, spp=spp, seed=2)).mean())


BLENDER = {"base_color": [0.6, 0.4, 0.2], "metallic": 0.3, "roughness": 0.4, "ior": 1.5, "specular_tint": 1.0}


def test_a_table_reading_formula_renders_symbolically_with_gradients():
    """blender:principled's formula reads Cycles' lookup table: it runs in Dr.Jit like every other
    (before, its plugin was the JAX callback, refused outside brdffit.evaluated_calls()). Rendered in
    symbolic mode it is the closed form; its parameters are in mi.traverse; prb's derivative by the
    roughness equals the finite difference of two renders with the same samples."""
    bsdf = brdffit.mitsuba_bsdf("blender:principled", BLENDER)
    size = 48
    image = np.asarray(mi.render(scene(bsdf, size), spp=16))[..., :3]
    expected, inside = closed_form("blender:principled", BLENDER, size)
    core = inside & (np.hypot(*np.meshgrid(np.arange(size) - size / 2 + 0.5, np.arange(size) - size / 2 + 0.5)) < 0.85 * size / 2)
    assert np.abs(image[core] - expected[core]).mean() / expected[core].mean() < 0.01
    keys = set(mi.traverse(scene(bsdf, 8)).keys())
    assert {"ball.bsdf.base_color", "ball.bsdf.roughness", "ball.bsdf.ior"} <= keys
    # two Monte Carlo estimates of one derivative: both within 1 % of each other at 256 spp (at 8 spp
    # they differed by 50 %, for Mitsuba's own roughconductor's alpha by 9 %)
    _, grad = _mean_and_gradient(bsdf, "ball.bsdf.roughness", spp=256)
    h = 0.01
    finite = (_mean(bsdf, "ball.bsdf.roughness", 0.4 + h, spp=256) - _mean(bsdf, "ball.bsdf.roughness", 0.4 - h, spp=256)) / (2 * h)
    assert grad[0] == pytest.approx(finite, rel=0.03) and abs(finite) > 1e-3


def test_parameter_maps_render_symbolically_with_gradients():
    """A kd map is a bitmap texture of the plugin (before: a JAX callback looked up per texel, black
    in symbolic mode): outside evaluated_calls() it renders like Mitsuba's diffuse with that bitmap,
    and prb differentiates the map's texels (keys below the parameter: ``kd.data``) as it does
    diffuse's."""
    rng = np.random.default_rng(2)
    kd = rng.uniform(0.1, 0.9, (4, 4, 3))
    ours = brdffit.mitsuba_bsdf("lambert", {"kd": kd})
    theirs = {"type": "diffuse", "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(kd.astype(np.float32)),
                                                 "raw": False, "filter_type": "nearest", "wrap_mode": "clamp"}}
    a = np.asarray(mi.render(scene(ours, 24), spp=8, seed=1))
    b = np.asarray(mi.render(scene(theirs, 24), spp=8, seed=1))
    assert a.mean() > 0.05
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)
    _, grad = _mean_and_gradient(ours, "ball.bsdf.kd.data")
    _, grad_theirs = _mean_and_gradient(theirs, "ball.bsdf.reflectance.data")
    assert np.any(grad != 0) and np.allclose(grad, grad_theirs, rtol=1e-3, atol=1e-9)
