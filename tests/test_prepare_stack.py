"""``problem.prepare_stack`` (the texels of a BTF at once) equals ``prepare`` of each texel's
Measurement stacked: excluded samples, per-texel weight normalisation and floors included."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.errors import UsageError
from brdffit.fitting.problem import prepare, prepare_stack
from brdffit.grid import ubo_pairs


def test_equals_prepare_of_each_texel():
    wi, wo = ubo_pairs()
    rng = np.random.default_rng(5)
    n, N = 4, len(wi)
    values = rng.uniform(0.0, 2.0, (n, N, 3))
    values[1, 10] = np.nan  # one texel with a non-finite sample
    values[2, :, 1] *= 1e-6  # another with a dim channel (its own floor)
    values[3, 5:2000] = np.inf  # many excluded: its weights sum differs from the others
    weights = rng.uniform(0.5, 1.5, N)
    weights[:20] = 0.0
    wo = wo.copy()
    wo[30, 2] = -0.1  # a view below the horizon
    got = prepare_stack(values, wi, wo, weights)
    for k in range(n):
        want = prepare(brdffit.Measurement(wi, wo, values[k], weights=weights, name=f"t{k}")).data
        for a, b in zip(got, want):
            np.testing.assert_allclose(a[k], np.asarray(b), rtol=1e-15, atol=0)


def test_a_texel_without_valid_samples_is_a_usage_error():
    wi, wo = ubo_pairs()
    values = np.ones((2, len(wi), 3))
    values[1] = np.nan
    with pytest.raises(UsageError, match=r"tile\[1\]: no valid samples"):
        prepare_stack(values, wi, wo, np.ones(len(wi)), name="tile")
