"""docs/models.md#how-models-are-tested item 4: every model (and a composite) is finite and non-negative, with finite gradients
with respect to its parameters and to both directions, at each parameter's lower bound, upper
bound and default (and all-lower / all-upper corners), over extreme directions: normal incidence,
89, 89.9 and 90 degrees (the horizon), wi == wo, mirror pairs and opposite grazing pairs; in
float32 and float64. One jit compilation per (model, dtype): parameter sets are vmapped."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit.models import get, names
from brdffit.testing import assert_model_well_behaved, extreme_pairs

MODELS = names() + ["lambert+ggx+ggx", "oren_nayar+ward", "lafortune3"]


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64], ids=["f32", "f64"])
@pytest.mark.parametrize("name", MODELS)
def test_finite_nonnegative_with_finite_gradients(name, dtype):
    assert_model_well_behaved(get(name), dtype)


def test_checker_catches_a_nan_gradient():
    """The check itself can fail: sqrt at 0 has an infinite derivative at the pole."""
    bad = dataclasses.replace(get("lambert"), formula=lambda p, wi, wo: p["kd"] * jnp.sqrt(wi[:, :1] ** 2 + wi[:, 1:2] ** 2))
    with pytest.raises(AssertionError, match="d/dwi not finite"):
        assert_model_well_behaved(bad)


def test_stability_pairs_cover_the_brief():
    wi, wo = extreme_pairs()
    assert np.any(np.all(wi == wo, axis=1) & (wi[:, 2] == 0))  # wi == wo at the horizon
    assert np.any(np.all(wo == wi * [-1, -1, 1], axis=1) & (np.abs(wi[:, 2] - np.cos(np.deg2rad(89.9))) < 1e-12))
    assert np.any(np.all(wi == [0, 0, 1], axis=1) & np.all(wo == [0, 0, 1], axis=1))
    assert brdffit.models.get("lambert").eval({"kd": 0.5}, wi[:3], wo[:3]).shape == (3, 3)


def test_capped_exp_stops_at_the_documented_exponents():
    """``_math.capped_exp``: e^100 in float64 and e^35 in float32 (its docstring), values whose
    square (a squared residual) is still finite in that precision; below the cap it is exp."""
    import jax.numpy as jnp

    from brdffit.models._math import capped_exp

    big64 = capped_exp(jnp.asarray([1000.0, 50.0], jnp.float64))
    assert big64.dtype == jnp.float64
    np.testing.assert_allclose(np.asarray(big64), [np.exp(100.0), np.exp(50.0)], rtol=1e-15)
    big32 = capped_exp(jnp.asarray([40.0, 35.5, 20.0], jnp.float32))
    assert big32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(big32), np.float32([np.exp(35.0), np.exp(35.0), np.exp(20.0)]), rtol=1e-6)
    assert np.all(np.isfinite(np.asarray(big32) ** 2))


def test_hz_sq_is_the_squared_cosine_down_to_its_floor():
    """``_math.hz_sq``: cos^2 of the half vector exactly, also at grazing half vectors (cos 1e-3,
    1e-5), and COS_EPS^2 only below COS_EPS (the floor that keeps 1/cos^2 finite)."""
    import jax.numpy as jnp

    from brdffit.models._math import COS_EPS, hz_sq

    z = np.array([1.0, 0.5, 1e-3, 1e-5, 0.1 * COS_EPS, 0.0])
    h = np.stack([np.sqrt(1.0 - z**2), np.zeros_like(z), z], axis=-1)
    got = np.asarray(hz_sq(jnp.asarray(h)))
    assert got.shape == (6, 1)
    np.testing.assert_allclose(got[:, 0], [1.0, 0.25, 1e-6, 1e-10, COS_EPS**2, COS_EPS**2], rtol=1e-12)
