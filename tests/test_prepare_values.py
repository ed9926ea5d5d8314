"""``problem.prepare`` (what every fit sees) on a small Measurement, field by field against
values written out: excluded samples (each reason counted; a sample may have several) get weight
0 and safe stand-ins, weights are normalised to a mean over samples and channels, cosines are
clipped, the floor is 1 % of the weighted mean |f_ref| per channel; and its refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

import brdffit
from brdffit.errors import UsageError
from brdffit.fitting.problem import prepare

UP = [0.0, 0.0, 1.0]


def _unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    return [x / n, y / n, z / n]


def _case():
    # lights and views exactly on the horizon (z = 0) count as below it
    wi = np.array([_unit(0.3, 0.0, 0.9), _unit(0.0, 0.6, 0.5), [1.0, 0.0, 0.0], _unit(1.0, 0.0, 1e-9), UP, UP])
    wo = np.array([UP, _unit(0.2, 0.2, 0.9), UP, UP, [0.0, 1.0, 0.0], UP])
    values = np.array([[0.5, -0.1], [2.0, 4.0], [1.0, 1.0], [0.2, 0.1], [3.0, 3.0], [np.nan, 1.0]])
    weights = np.array([1.0, 3.0, 1.0, 0.0, 1.0, 2.0])
    return brdffit.Measurement(wi, wo, values, weights=weights, name="case"), wi, wo, values, weights


def test_fields_written_out():
    m, wi, wo, values, weights = _case()
    p = prepare(m)
    used = [0, 1]  # 2: light on the horizon, 3: weight 0, 4: view on the horizon, 5: non-finite
    assert p.n_used == 2 and p.n_excluded == 4 and p.channels == 2
    assert p.excluded == {"weight 0": 1, "non-finite value": 1, "light below horizon": 1, "view below horizon": 1}
    assert p.used.tolist() == [True, True, False, False, False, False]
    d_wi, d_wo, ref, sqrt_w, cos_i, floor = (np.asarray(a) for a in p.data)
    for k in range(6):
        if k in used:
            np.testing.assert_array_equal(d_wi[k], wi[k])
            np.testing.assert_array_equal(d_wo[k], wo[k])
            np.testing.assert_array_equal(ref[k], values[k])
        else:  # value 0, weight 0; a direction no formula may see (on or below the horizon) becomes the
            # normal, one a formula can evaluate (left out for its weight or value) stays: tables that share
            # their directions keep sharing them (problem.stack)
            assert ref[k].tolist() == [0.0, 0.0] and sqrt_w[k, 0] == 0.0
            if k in (2, 4):
                assert d_wi[k].tolist() == UP and d_wo[k].tolist() == UP
            else:
                np.testing.assert_array_equal(d_wi[k], wi[k])
                np.testing.assert_array_equal(d_wo[k], wo[k])
    w_sum = 1.0 + 3.0
    for k in used:  # sum of squared residuals = weighted mean over samples and channels
        assert sqrt_w[k, 0] == pytest.approx(math.sqrt(weights[k] / (w_sum * 2)), rel=1e-15)
    assert cos_i[:, 0].tolist() == pytest.approx([wi[0, 2], wi[1, 2], 1.0, 1e-7, 1.0, 1.0], rel=1e-15)  # 3: kept, clipped
    for c in range(2):
        mean_abs = (1.0 * abs(values[0, c]) + 3.0 * abs(values[1, c])) / w_sum
        assert floor[c] == pytest.approx(0.01 * mean_abs, rel=1e-15)
    assert all(a.dtype == np.float64 for a in (d_wi, d_wo, ref, sqrt_w, cos_i, floor))


def test_grazing_light_cosine_is_clipped_not_zero():
    m, wi, *_ = _case()
    w = np.asarray(m.weights).copy()
    w[3] = 1.0  # the light at z = 1e-9 is above the horizon: used, with its cosine clipped to 1e-7
    p = prepare(m.replace(weights=w))
    assert p.used[3] and float(np.asarray(p.data[4])[3, 0]) == 1e-7
    # a reason no sample has is not listed
    assert p.excluded == {"non-finite value": 1, "light below horizon": 1, "view below horizon": 1}


def test_extra_weights_multiply_and_exclude():
    m, wi, wo, values, weights = _case()
    extra = np.array([2.0, 0.0, 1.0, 1.0, 1.0, 1.0])  # sample 1 dropped by the caller (a scene's usage)
    p = prepare(m, extra)
    assert p.used.tolist() == [True, False, False, False, False, False] and p.n_used == 1
    # every left-out sample has its reason, the caller's weights included
    assert p.excluded == {"weight 0": 1, "non-finite value": 1, "light below horizon": 1, "view below horizon": 1,
                          "weight 0 in weights=": 1} and p.n_excluded == 5
    assert float(np.asarray(p.data[3])[0, 0]) == pytest.approx(math.sqrt(2.0 / (2.0 * 2)), rel=1e-15)
    odd = extra.copy()
    odd[0] = np.nan  # a NaN extra weight excludes its sample
    with pytest.raises(UsageError) as caught:
        prepare(m, odd)
    assert str(caught.value) == ("case: no valid samples to fit (all have weight 0, non-finite values or lie "
                                 "below the horizon)")
    odd[0] = np.inf  # an infinite one is refused (docs/fitting.md#hostile-but-valid-data): it would leave every other sample weight 0
    with pytest.raises(UsageError) as caught:
        prepare(m, odd)
    assert str(caught.value) == ("case: weights=: 1 sample(s) have an infinite weight (the first: sample 0); "
                                 "weights must be finite (0 leaves a sample out)")
    with pytest.raises(UsageError) as caught:
        prepare(m, np.ones(5))
    assert str(caught.value) == "weights has shape (5,), expected (6,)"


def test_not_a_measurement():
    with pytest.raises(UsageError) as caught:
        prepare({"values": [1.0]})
    assert str(caught.value) == "expected a brdffit.Measurement, got dict"
