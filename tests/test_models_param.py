"""``models.base.Param`` and ``Model``: the checks a model author's parameter table goes through,
each message naming the parameter (or model) and the problem, and the rule that picks a log axis
when none is given (module docstring of ``brdffit.models.base``: a positive lower bound and
upper / lower >= 100)."""

from __future__ import annotations

import math
import re

import pytest

from brdffit.models.base import Lobe, Model, Param


def _param(**changes) -> Param:
    fields = {"name": "k", "channels": 1, "lower": 0.0, "upper": 1.0, "default": 0.5, "role": "albedo"}
    return Param(**{**fields, **changes})


@pytest.mark.parametrize(("changes", "message"), [
    ({"channels": 2}, "k: channels must be 1 or 3"),
    ({"channels": 4}, "k: channels must be 1 or 3"),
    ({"default": 1.5}, "k: default 1.5 outside [0.0, 1.0]"),
    ({"default": -0.5}, "k: default -0.5 outside [0.0, 1.0]"),
    ({"default": math.nan}, "k: default nan outside [0.0, 1.0]"),
    ({"upper": math.inf}, "k: a physical range must be finite (an infinite bound needs one)"),
    ({"physical": (0.6, 0.9)}, "k: physical range (0.6, 0.9) must lie inside the bounds [0.0, 1.0] and hold the default 0.5"),
    ({"upper": 2.0, "physical": (0.0, 1.5), "default": 1.8},
     "k: physical range (0.0, 1.5) must lie inside the bounds [0.0, 2.0] and hold the default 1.8"),
    ({"physical": (-1.0, 1.0)}, "k: physical range (-1.0, 1.0) must lie inside the bounds [0.0, 1.0] and hold the default 0.5"),
    ({"scale": "logarithmic"}, "k: scale must be 'linear' or 'log'"),
    ({"scale": "log"}, "k: a log axis needs a positive lower bound"),
    ({"scale": "log", "lower": -1.0}, "k: a log axis needs a positive lower bound"),
])
def test_a_bad_parameter_is_refused_with_its_name_and_the_problem(changes, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        _param(**changes)


@pytest.mark.parametrize("changes", [
    {"channels": 3},                                          # one value per colour channel
    {"default": 0.0}, {"default": 1.0},                       # a default on either bound
    {"physical": (0.5, 0.8)}, {"physical": (0.2, 0.5)},       # ... or on either end of the physical range
    {"physical": (0.0, 1.0)},
    {"lower": -math.inf, "upper": math.inf, "default": 0.0, "physical": (-1.0, 1.0)},
])
def test_edge_values_are_accepted(changes):
    p = _param(**changes)
    assert p.physical == (float(p.physical[0]), float(p.physical[1]))


def test_physical_defaults_to_the_bounds_as_floats():
    assert _param(lower=0, upper=2, default=1).physical == (0.0, 2.0)
    assert isinstance(_param(lower=0, upper=2, default=1).physical[0], float)


@pytest.mark.parametrize(("lower", "upper", "default", "scale"), [
    (1e-3, 0.1, 0.01, "log"),          # upper / lower = 100 exactly: log
    (1e-3, 0.0999, 0.01, "linear"),    # just under 100
    (0.5, 100.0, 1.0, "log"),          # a lower bound below 1 (ratio 200)
    (2.0, 50.0, 3.0, "linear"),        # ratio 25 (their product is 100)
    (2.0, 300.0, 3.0, "log"),          # ratio 150
    (0.0, 1e6, 1.0, "linear"),         # a zero lower bound: no log axis
    (-1.0, 1e3, 1.0, "linear"),
])
def test_the_axis_is_log_for_a_positive_lower_bound_and_a_ratio_of_at_least_100(lower, upper, default, scale):
    p = _param(lower=lower, upper=upper, default=default, physical=(lower, min(upper, 1e3)) if lower >= 0 else (-1.0, 1e3))
    assert p.scale == scale


def test_a_stated_scale_is_kept():
    assert _param(scale="linear", lower=1e-4, upper=1.0, default=0.5).scale == "linear"
    assert _param(scale="log", lower=0.5, upper=1.0, default=0.7).scale == "log"


def test_a_lobe_naming_unknown_parameters_is_refused():
    params = (_param(name="kd"), _param(name="ks"), _param(name="n", lower=1.0, upper=100.0, default=10.0))
    lobes = (Lobe("mine", ("ks", "m")),)
    message = f"model {'mine'!r}: lobe {lobes[0]} names unknown parameters"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        Model("mine", params, lambda p, wi, wo: p["kd"], "", lobes=lobes)
    model = Model("mine", params, lambda p, wi, wo: p["kd"], "")
    assert model.lobes == (Lobe("mine", ("ks", "n")),)  # by default: every parameter but kd
    assert Model("flat", params[:1], lambda p, wi, wo: p["kd"], "").lobes == ()
