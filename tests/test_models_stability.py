"""Issue 3 item 4: every model (and a composite) is finite and non-negative, with finite gradients
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
