"""fit.json may record the bounds its fit ran in (``bounds``: name -> [lower, upper], numbers or
per-channel lists, or {"lower": ..., "upper": ...}); reading it checks the parameters against those
bounds and refuses a malformed record with one message naming the problem."""

from __future__ import annotations

import json

import pytest

from brdffit.errors import InputError
from brdffit.fitting.result import FitResult
from test_reliability import fit_doc


OUTSIDE = "parameter 'kd' = [1.5, 0.2, 0.1] lies outside its recorded bounds"


def _read(tmp_path, **changes):
    p = tmp_path / "fit.json"
    p.write_text(json.dumps(fit_doc(**changes)))
    return FitResult.from_json(p)


@pytest.mark.parametrize("bounds", [{"kd": [0, 2]}, {"kd": {"lower": 0, "upper": 2}},
                                    {"kd": [[0, 0, 0], [2, 1, 1]]},
                                    {"kd": [[1.5, 0.2, 0.1], [1.5, 0.2, 0.1]]}])  # a fixed parameter
def test_recorded_bounds_forms_accepted(tmp_path, bounds):
    r = _read(tmp_path, params={"kd": [1.5, 0.2, 0.1]}, bounds=bounds)
    assert r.params["kd"].tolist() == [1.5, 0.2, 0.1]


@pytest.mark.parametrize(("bounds", "message"), [
    ({"kd": [0, 1]}, f"{OUTSIDE} [0, 1]"),
    ({"kd": {"lower": 0, "upper": 1}}, f"{OUTSIDE} [0, 1]"),
    ({"kd": [[0, 0, 0], [2, 0.1, 1]]}, f"{OUTSIDE} [0, 0, 0, 2, 0.1, 1]"),  # channel 1 above
    ({"kd": [0.2, 2]}, f"{OUTSIDE} [0.2, 2]"),  # channel 2 below
    ([0, 2], "field 'bounds' must be an object name -> [lower, upper]"),
    ({"kd": [0, 2, 3]}, "bounds.kd must be [lower, upper]"),
    ({"kd": {"lower": 0}}, "bounds.kd must be [lower, upper]"),
    ({"kd": (0)}, "bounds.kd must be [lower, upper]"),
    ({"kd": [2, 0]}, "bounds.kd is not an interval: [2, 0]"),
    ({"kd": [float("nan"), 2]}, "bounds.kd is not an interval"),
    ({"kd": [0, float("nan")]}, "bounds.kd is not an interval"),
    ({"kd": [[0, 0, 0], [2, 2]]}, "bounds.kd: lower has 3 entries, upper 2"),  # was a bare ValueError
    ({"kd": [[0, 0], [2, 2]]}, "bounds.kd has 2/2 entries, the parameter 3"),
    ({"kd": ["a", 2]}, "bounds.kd lower"),
    ({"kd": [0, "b"]}, "bounds.kd upper"),
])
def test_malformed_or_violated_recorded_bounds_refused(tmp_path, bounds, message):
    with pytest.raises(InputError) as info:
        _read(tmp_path, params={"kd": [1.5, 0.2, 0.1]}, bounds=bounds)
    assert info.value.path == str(tmp_path / "fit.json")
    assert info.value.problem.startswith(message), info.value.problem


def test_without_a_record_the_models_bounds_apply(tmp_path):
    with pytest.raises(InputError, match="lies outside its bounds of lambert"):
        _read(tmp_path, params={"kd": [-0.5, 0.2, 0.1]})
    assert _read(tmp_path, params={"kd": [0.5, 0.2, 0.1]}, bounds=None).params["kd"][0] == 0.5
