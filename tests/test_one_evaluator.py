"""One evaluator of an analytic model outside a fit (docs/DESIGN.md#layers): ``FitResult.eval``, the renderer's
callback BSDF and the sampler's lobe weights all run ``fitting.model_eval``'s compiled program, so
what a fit reports and what a render shows cannot come from two code paths."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.fitting import model_eval
from brdffit.grid import ubo_pairs


@pytest.fixture
def fit_result():
    wi, wo = ubo_pairs()
    g = brdffit.models.get("ggx")
    p = g.check_params({"kd": [0.3, 0.2, 0.1], "ks": 0.6, "alpha": 0.15, "f0": 0.3})
    f = np.asarray(g.eval(p, wi, wo))
    return brdffit.fit(brdffit.Measurement(wi, wo, f, grid="ubo81", name="one"), "ggx")


def test_fit_result_eval_and_the_renderer_run_the_same_compiled_program(fit_result, monkeypatch):
    from brdffit.render.bsdf import model_brdf

    seen = []
    real = model_eval._program

    def recorded(model, length):
        seen.append((model.name, length))
        return real(model, length)

    monkeypatch.setattr(model_eval, "_program", recorded)
    monkeypatch.setattr(model_eval, "_WARM", {})  # this model's background compile not yet started
    rng = np.random.default_rng(0)
    wi = rng.normal(size=(40, 3))
    wo = rng.normal(size=(40, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    via_result = fit_result.eval(wi, wo)
    assert seen == [("ggx", model_eval.CHUNK)]
    brdf = model_brdf(fit_result.model, fit_result.params)
    model_eval._WARM[fit_result.model].join()  # the background compile of the renderer's program
    assert seen == [("ggx", model_eval.CHUNK)] * 2
    via_renderer = brdf(wi, wo)
    assert seen == [("ggx", model_eval.CHUNK)] * 3
    np.testing.assert_array_equal(via_result, via_renderer)  # the very same numbers
    # and both are the model's JAX formula
    direct = np.asarray(fit_result.model.eval(fit_result.model.check_params(fit_result.params), wi, wo))
    np.testing.assert_allclose(via_result, direct, rtol=1e-12)


def test_the_evaluator_pads_any_length_to_its_two_compiled_shapes(fit_result):
    m, p = fit_result.model, fit_result.params
    rng = np.random.default_rng(1)
    for n in (1, model_eval.SMALL, model_eval.SMALL + 1, 3 * 1000):
        wi = np.tile([0.3, 0.1, 0.0], (n, 1))
        wi[:, 2] = rng.uniform(0.2, 1.0, n)
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo = wi[::-1] * np.array([-1.0, -1.0, 1.0])
        got = model_eval.eval_model(m, p, wi, wo)
        want = np.asarray(m.eval(m.check_params(p), wi, wo))
        assert got.shape == (n, 3)
        np.testing.assert_allclose(got, want, rtol=1e-12, err_msg=str(n))
