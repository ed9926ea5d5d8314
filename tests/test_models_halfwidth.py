"""``Model.halfwidth`` (the lobe width the parameter space compares with the sample spacing):
each model's value satisfies the half-maximum equation of its lobe, written here from the papers'
distribution terms, and a few closed-form values."""

from __future__ import annotations

import math

import pytest

from brdffit.models import get as get_model

LN2 = math.log(2.0)


def ggx_ratio(theta, alpha):
    """GGX slope distribution P(tan)/P(0) = (alpha^2 / (alpha^2 + tan^2))^2 (Walter et al. 2007, eq. 33
    without its 1/cos^4 Jacobian, as the models' Beckmann widths also measure the slope distribution)."""
    return (alpha**2 / (alpha**2 + math.tan(theta) ** 2)) ** 2


CASES = [
    # model, params, the lobe's value relative to its peak at half the returned width (or the width for
    # lobes already measured from the mirror direction); each must be 1/2
    ("blinn_phong", {"n": 7.0}, lambda w, p: math.cos(w / 2) ** p["n"]),
    ("ashikhmin_shirley", {"nu": 5.0, "nv": 40.0}, lambda w, p: math.cos(w / 2) ** 40.0),  # the narrower axis
    ("ashikhmin_shirley", {"nu": 40.0, "nv": 5.0}, lambda w, p: math.cos(w / 2) ** 40.0),
    ("phong", {"n": 7.0}, lambda w, p: math.cos(w) ** p["n"]),
    ("phong_classic", {"n": 3.0}, lambda w, p: math.cos(w) ** p["n"]),
    ("lafortune", {"n": 9.0}, lambda w, p: math.cos(w) ** p["n"]),
    ("cook_torrance", {"alpha": 0.3}, lambda w, p: math.exp(-math.tan(w / 2) ** 2 / 0.09)),
    ("ward", {"alpha_x": 0.3, "alpha_y": 0.1}, lambda w, p: math.exp(-math.tan(w / 2) ** 2 / 0.01)),
    ("ward", {"alpha_x": 0.1, "alpha_y": 0.3}, lambda w, p: math.exp(-math.tan(w / 2) ** 2 / 0.01)),
    ("torrance_sparrow", {"m": 0.25}, lambda w, p: math.exp(-((w / 2) / 0.25) ** 2)),
    ("ggx", {"alpha": 0.3}, lambda w, p: ggx_ratio(w / 2, 0.3)),
]


@pytest.mark.parametrize("name, params, lobe", CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_half_maximum(name, params, lobe):
    width = float(get_model(name).halfwidth(params))
    assert 0 < width < math.pi
    assert lobe(width, params) == pytest.approx(0.5, rel=1e-12)


def test_closed_forms():
    assert get_model("blinn_phong").halfwidth({"n": 1.0}) == pytest.approx(2 * math.pi / 3, rel=1e-14)  # cos = 1/2
    assert get_model("phong").halfwidth({"n": 1.0}) == pytest.approx(math.pi / 3, rel=1e-14)
    assert get_model("torrance_sparrow").halfwidth({"m": 1.0}) == pytest.approx(2 * math.sqrt(LN2), rel=1e-14)
    assert get_model("ward").halfwidth({"alpha_x": 1 / math.sqrt(LN2), "alpha_y": 5.0}) == pytest.approx(math.pi / 2, rel=1e-14)
