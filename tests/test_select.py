"""``brdffit.select``'s rule on candidates whose errors are set by construction (no solver in the
loop): "tolerance" takes the fewest parameters within ``tolerance`` (5 % by default) of the best,
"aic"/"bic" the lowest information criterion."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

import brdffit
from brdffit import models
from brdffit.errors import UsageError
from brdffit.fitting import fit, select
from brdffit.fitting.losses import evaluate
from brdffit.fitting.problem import prepare
from brdffit.grid import spherical_to_cartesian

TRUE = {"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.25], "f0": [0.3]}


@pytest.fixture(scope="module")
def case():
    """A ggx table, the best lambert fit S, and a ggx candidate C made worse (ks scaled) until
    its log loss is exactly S's / 1.5: S has 3 parameters, C 8, and S is 50 % worse."""
    rng = np.random.default_rng(3)
    n = 300
    wi = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    g = models.get("ggx")
    m = brdffit.Measurement(wi, wo, np.asarray(g.eval(g.check_params(TRUE), wi, wo)), name="select-case")
    data = prepare(m).data
    simple = fit(m, "lambert")
    e_simple = evaluate(simple.model, simple.params, data)["log"]
    one_step = fit(m, "ggx", init=TRUE, max_steps=1)

    def worse(scale):
        params = {k: np.asarray(v, np.float64) for k, v in TRUE.items()}
        params["ks"] = params["ks"] * scale
        return params

    def excess(scale):
        return evaluate(one_step.model, worse(scale), data)["log"] - e_simple / 1.5

    scale = brentq(excess, 1.0, 50.0, xtol=1e-14)
    complex_ = dataclasses.replace(one_step, params=worse(scale))
    return m, simple, complex_, e_simple


def test_the_default_tolerance_is_five_percent(case):
    m, simple, complex_, _ = case
    assert (simple.n_params, complex_.n_params) == (3, 8)
    # 50 % worse is outside the default 5 %: the better, larger model.
    assert select(m, [simple, complex_]).model_name == "ggx"
    # Within a wider tolerance the fewer parameters win; just outside it they do not.
    assert select(m, [simple, complex_], tolerance=0.51).model_name == "lambert"
    assert select(m, [simple, complex_], tolerance=0.49).model_name == "ggx"


def test_zero_tolerance_keeps_the_best(case):
    m, simple, complex_, _ = case
    assert select(m, [simple, complex_], tolerance=0.0).model_name == "ggx"


def test_an_exact_candidate_scores_with_the_floor_of_the_sse():
    """An exact fit has SSE ~ 0: the criteria take ln(max(SSE, 1e-300) / n), finite."""
    rng = np.random.default_rng(4)
    n = 200
    wi = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    lam = models.get("lambert")
    m = brdffit.Measurement(wi, wo, np.asarray(lam.eval(lam.check_params({"kd": [0.3, 0.2, 0.1]}), wi, wo)), name="flat")
    exact = fit(m, "lambert")
    e = evaluate(exact.model, exact.params, prepare(m).data)["log"]
    assert e * 3 * n < 1.0  # the floor at work is the 1e-300 one, not a larger one
    sel = select(m, [exact], criterion="aic")
    want = 3 * n * math.log(max(e * 3 * n, 1e-300) / (3 * n)) + 2.0 * 3
    assert sel.scores["lambert/lm/log"] == pytest.approx(want, rel=1e-12)


def test_tolerance_reason_and_scores(case):
    m, simple, complex_, e_simple = case
    sel = select(m, [complex_, simple], tolerance=0.6)
    assert sel.reason == (f"lambert (3 parameters): log {e_simple:.4g} is within 60% of the best "
                          f"(ggx/lm/log, {e_simple / 1.5:.4g}, 8 parameters); 2 of 2 candidates qualified and it "
                          "has the fewest parameters")
    assert sel.scores == pytest.approx({"lambert/lm/log": e_simple, "ggx/lm/log": e_simple / 1.5}, rel=1e-9)


@pytest.mark.parametrize("criterion, penalty", [("aic", lambda n: 2.0), ("bic", math.log)])
def test_information_criteria(case, criterion, penalty):
    """n ln(SSE / n) + k x penalty, SSE = loss x n (losses are means of squared residuals): the
    1.5x error ratio is worth n ln 1.5 = 122 (n = 300 samples x 3 channels) against 5 parameters'
    penalty, so the larger model wins on both criteria."""
    m, simple, complex_, e_simple = case
    n = 900
    sel = select(m, [simple, complex_], criterion=criterion)
    assert sel.model_name == "ggx"
    want = n * math.log(e_simple / 1.5) + penalty(n) * 8
    assert sel.scores["ggx/lm/log"] == pytest.approx(want, rel=1e-9)
    assert sel.reason == f"ggx (8 parameters) has the lowest {criterion.upper()} ({want:.2f}) on log"


def test_no_candidates_and_bad_arguments(case):
    m, simple, complex_, _ = case
    with pytest.raises(UsageError) as caught:
        select(m, [])
    assert str(caught.value) == "select: no candidates"
    with pytest.raises(UsageError) as caught:
        select(m, [simple], metric="nope")
    assert str(caught.value) == ("select: unknown metric 'nope'; known: cbrt, cosine_l2, l2, log, log_rmse, "
                                 "max_abs_error, mean_rel_error, rel_rmse, relative, rmse")
    with pytest.raises(UsageError) as caught:
        select(m, [simple], criterion="best")
    assert str(caught.value) == "select: criterion must be 'tolerance', 'aic' or 'bic', not 'best'"
