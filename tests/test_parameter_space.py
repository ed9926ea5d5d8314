"""docs/fitting.md#solvers item 1, docs/fitting.md#parameter-space: default bounds only where the formula needs them,
``physical=True``, ``bounds=`` / ``fixed=`` (API and CLI), ordered lobes, ``at_bound`` and
``warnings``; every model file's doc table equals its parameter table."""

from __future__ import annotations

import json
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.cli import main
from brdffit.errors import UsageError
from brdffit.fitting import FitResult, fit
from brdffit.fitting.space import ParameterSpace, fit_warnings, lobe_halfwidths, sample_spacing
from brdffit.grid import spherical_to_cartesian, ubo_directions, ubo_pairs
from brdffit.models.base import format_range

INF = math.inf


# -- declared tables ---------------------------------------------------------------------------------
def _doc_rows(doc: str):
    """(name, channels, bounds, physical, default, role) of the first RST table of a docstring."""
    lines = doc.split("\n")
    seps = [i for i, line in enumerate(lines) if re.fullmatch(r"=+( +=+)+", line)]
    header = lines[seps[0] + 1]
    starts = [header.index(word) for word in ("name", "channels", "bounds", "physical", "default", "role", "meaning")]
    rows = []
    for line in lines[seps[1] + 1 : seps[2]]:
        if not line[: starts[1]].strip():
            continue  # a continuation line of the meaning column
        cells = [line[a:b].strip() for a, b in zip(starts, starts[1:])]
        rows.append(tuple(cells))
    return rows


@pytest.mark.parametrize("name", models.names())
def test_doc_table_equals_param_table(name):
    model = models.get(name)
    want = [
        (p.name, str(p.channels), format_range(p.lower, p.upper) + (" (log)" if p.scale == "log" else ""),
         format_range(*p.physical), f"{p.default:g}", p.role)
        for p in model.params
    ]
    assert _doc_rows(model.doc) == want


def test_doc_table_parser_sees_a_changed_bound():
    # The comparison above would catch an edited doc table (guards the parser itself).
    doc = models.get("ggx").doc.replace("[1e-4, inf) (log)", "[1e-4, 1] (log)  ", 1)
    assert ("alpha", "1", "[1e-4, 1] (log)", "[1e-4, 1]", "0.2", "roughness") in _doc_rows(doc)


def test_default_bounds_only_where_the_formula_needs_them():
    # docs/fitting.md#fitting: scales non-negative (no upper bound), roughness / exponents positive, f0 in [0, 1];
    # the physical range is finite and inside the bounds for every parameter.
    for name in models.names():
        for p in models.get(name).params:
            assert all(math.isfinite(v) for v in p.physical), (name, p.name)
            assert p.lower <= p.physical[0] <= p.default <= p.physical[1] <= p.upper
            if models.get(name).is_native:
                # docs/materials.md#native-materials-and-exports: a native model's bounds are the ranges its renderer accepts (finite:
                # Mitsuba refuses reflectances above 1), so every native fit exports as it is
                assert math.isfinite(p.lower) and math.isfinite(p.upper), (name, p.name)
                if p.linear:
                    assert (p.lower, p.upper) == (0.0, 1.0), (name, p.name)
                continue
            if p.linear:
                assert (p.lower, p.upper) == (0.0, INF), (name, p.name)
            if p.role in ("roughness", "exponent") and name != "oren_nayar":
                assert p.lower > 0 and p.upper == INF, (name, p.name)
            if p.name in ("f0", "rs"):
                assert (p.lower, p.upper) == (0.0, 1.0)
            if p.name in ("kd", "ks", "rd") and name not in ("phong_classic", "torrance_sparrow"):
                assert p.physical == (0.0, 1.0), (name, p.name)  # albedo <= 1 with physical=True


def test_sampling_and_fold_with_infinite_bounds():
    model = models.get("ggx")
    for key in jax.random.split(jax.random.key(1), 8):
        v = np.asarray(model.flatten(model.sample(key)))
        assert np.all(v >= 0) and np.all(v[:6] <= 1.0) and 1e-4 <= v[6] <= 1.0  # the finite range
    # Beyond the physical range (ks = 5, alpha = 30): the stock solvers' map into the box
    # (solver_optx.to_box) round-trips exactly with ggx's own bounds, and a step below a lower bound
    # folds back into the box (one reflection: slope +-1).
    from brdffit.fitting.solver_optx import from_box, to_box

    lo, hi = model.bounds()
    assert np.isinf(hi[:6]).all() and hi[7] == 1.0
    v = model.flatten({"kd": [0.2, 0.1, 0.0], "ks": [5.0, 0.5, 0.0], "alpha": [30.0], "f0": [1.0]})
    np.testing.assert_allclose(to_box(from_box(v, lo, hi), lo, hi), v, rtol=1e-12, atol=1e-15)
    ks = dict(model.slices())["ks"]
    x = from_box(v, lo, hi).at[ks].set(-0.3)
    np.testing.assert_allclose(to_box(x, lo, hi)[ks], [0.3, 0.3, 0.3])


# -- ParameterSpace ----------------------------------------------------------------------------------
def test_space_resolution_and_errors():
    m = models.get("lambert+ggx+ggx")
    s = ParameterSpace.build(m, bounds={"ggx2.alpha": (0.01, None)}, fixed={"ggx1.f0": 0.04}, physical=True)
    flat = dict(zip(m.param_names, np.cumsum([0] + [m.size(p) for p in m.params])))
    assert s.hi[flat["kd"]] == 1.0  # physical
    # override; None keeps the bound in force (docs/fitting.md#fitting: bounds= overrides a bound): here the physical 1.0
    assert (s.lo[flat["ggx2.alpha"]], s.hi[flat["ggx2.alpha"]]) == (0.01, 1.0)
    assert not s.free[flat["ggx1.f0"]] and s.lo[flat["ggx1.f0"]] == s.hi[flat["ggx1.f0"]] == 0.04
    assert s.order == ()  # ggx1 and ggx2 are told apart by the user's constraints: no swapping
    # The edges are allowed: a box equal to the formula's range, a value fixed on a bound, and a
    # box wider than the physical range.
    edge = ParameterSpace.build(m, bounds={"ggx1.alpha": (1e-4, INF), "kd": (None, 2.0), "ggx2.alpha": (0.3, 0.3)},
                                fixed={"ggx2.f0": 1.0, "ggx1.f0": 0.0}, physical=True)
    assert (edge.lo[flat["ggx1.alpha"]], edge.hi[flat["ggx1.alpha"]]) == (1e-4, INF)
    assert edge.lo[flat["kd"]] == 0.0 and edge.hi[flat["kd"]] == 2.0
    assert edge.values[flat["ggx2.f0"]] == 1.0 and edge.values[flat["ggx1.f0"]] == 0.0
    assert edge.lo[flat["ggx2.alpha"]] == edge.hi[flat["ggx2.alpha"]] == 0.3  # an empty box is allowed
    # None keeps that side of the box in force: the physical one with physical=True
    for physical, upper in ((True, 1.0), (False, INF)):
        narrowed = ParameterSpace.build(m, bounds={"ggx1.ks": (0.1, None)}, physical=physical)
        assert narrowed.lo[flat["ggx1.ks"]] == 0.1 and narrowed.hi[flat["ggx1.ks"]] == upper


NAMES = "kd, ggx1.ks, ggx1.alpha, ggx1.f0, ggx2.ks, ggx2.alpha, ggx2.f0"


@pytest.mark.parametrize("bounds, fixed, message", [
    ({"nosuch": (0, 1)}, None, f"bounds: model 'lambert+ggx+ggx' has no parameter 'nosuch'; it has {NAMES}"),
    (None, {"nosuch": 1}, f"fixed: model 'lambert+ggx+ggx' has no parameter 'nosuch'; it has {NAMES}"),
    ({"ggx1.alpha": (0.5, 0.1)}, None, "bounds for 'ggx1.alpha': lower 0.5 is above upper 0.1"),
    ({"ggx1.alpha": (0.0, 0.1)}, None,
     "bounds for 'ggx1.alpha': (0, 0.1) leaves the range the formula allows, [0.0001, inf]"),
    ({"ggx1.f0": (None, 2.0)}, None, "bounds for 'ggx1.f0': (0, 2) leaves the range the formula allows, [0, 1]"),
    ({"ggx1.alpha": (float("nan"), 0.1)}, None, "lower bound for 'ggx1.alpha': NaN is not a value"),
    ({"kd": 0.5}, None, "bounds for 'kd': expected (lower, upper), got 0.5"),
    ({"kd": "ab"}, None, "bounds for 'kd': expected (lower, upper), got 'ab'"),
    ({"kd": (0.1, 0.2, 0.3)}, None, "bounds for 'kd': expected (lower, upper), got (0.1, 0.2, 0.3)"),
    (None, {"ggx1.f0": 1.5}, "fixed value for 'ggx1.f0': 1.5 outside its bounds [0, 1]"),
    (None, {"ggx1.f0": -0.1}, "fixed value for 'ggx1.f0': -0.1 outside its bounds [0, 1]"),
    ({"ggx1.f0": (0.2, 0.5)}, {"ggx1.f0": 0.6}, "fixed value for 'ggx1.f0': 0.6 outside its bounds [0.2, 0.5]"),
    (None, {"kd": [0.1, 0.2]}, "fixed value for 'kd': expected 1 or 3 numbers, got [0.1, 0.2]"),
    (None, {"kd": [[0.1]]}, "fixed value for 'kd': expected 1 or 3 numbers, got [[0.1]]"),
])
def test_space_refusals_in_full(bounds, fixed, message):
    with pytest.raises(UsageError) as caught:
        ParameterSpace.build(models.get("lambert+ggx+ggx"), bounds, fixed)
    assert str(caught.value) == message


def test_canonical_swaps_whole_lobes_and_keeps_f():
    m = models.get("lambert+ggx+ggx")
    p = {"kd": [0.1, 0.1, 0.1], "ggx1.ks": [0.9, 0.8, 0.7], "ggx1.alpha": [0.4], "ggx1.f0": [0.2],
         "ggx2.ks": [0.3, 0.2, 0.1], "ggx2.alpha": [0.05], "ggx2.f0": [0.9]}
    v = np.asarray(m.flatten(p))
    s = ParameterSpace.build(m)
    c = m.unflatten(s.canonical(v))
    assert float(c["ggx1.alpha"][0]) == 0.05 and float(c["ggx2.alpha"][0]) == 0.4
    np.testing.assert_array_equal(c["ggx1.ks"], [0.3, 0.2, 0.1])
    np.testing.assert_array_equal(c["ggx2.f0"], [0.2])
    wi, wo = ubo_pairs()
    np.testing.assert_allclose(m.eval(c, wi, wo), m.eval(p, wi, wo), rtol=1e-13)
    np.testing.assert_array_equal(s.canonical(s.canonical(v)), s.canonical(v))
    # float64 out whatever comes in (a float32 vector from a user's own code included)
    assert s.canonical(v.astype(np.float32)).dtype == np.float64
    # A fixed parameter tells the lobes apart: no swap (it would move the fixed value).
    held = ParameterSpace.build(m, fixed={"ggx2.f0": 0.9})
    np.testing.assert_array_equal(held.canonical(v), v)
    # Exponents: narrowest first means the larger exponent first (lafortune3 lobes too).
    lf = models.get("lafortune3")
    q = {k: np.asarray(a) for k, a in lf.defaults().items()}
    q["n1"], q["n3"] = np.asarray([20.0]), np.asarray([2000.0])
    out = lf.unflatten(ParameterSpace.build(lf).canonical(lf.flatten(q)))
    assert [float(out[f"n{j}"][0]) for j in (1, 2, 3)] == [2000.0, 200.0, 20.0]


# -- fits --------------------------------------------------------------------------------------------
def _scattered(model, params, n=400, seed=0):
    rng = np.random.default_rng(seed)
    wi = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    wo = spherical_to_cartesian(rng.uniform(0, 1.3, n), rng.uniform(0, 2 * np.pi, n))
    m = models.get(model)
    return brdffit.Measurement(wi, wo, np.asarray(m.eval(m.check_params(params), wi, wo)), name=f"syn-{model}")


def _ubo(model, params, name):
    wi, wo = ubo_pairs()
    m = models.get(model)
    f = np.asarray(m.eval(m.check_params(params), wi, wo))
    return brdffit.Measurement(wi, wo, f, grid="ubo81", name=name)


GLOSSY = {"kd": [0.05, 0.04, 0.03], "ks": [1.6, 1.6, 1.6], "alpha": [0.15], "f0": [0.05]}


@pytest.fixture(scope="module")
def glossy():
    return _ubo("ggx", GLOSSY, "ks16")


def test_default_ks_exceeds_one_when_the_data_want_it(glossy):
    r = fit(glossy, "ggx")
    assert r.converged, r.status
    np.testing.assert_allclose(r.params["ks"], 1.6, rtol=1e-4)
    np.testing.assert_allclose(r.params["alpha"], 0.15, rtol=1e-4)
    assert r.at_bound == {} and r.warnings == ()  # alpha 0.15 is resolved on the UBO grid


def test_physical_keeps_albedo_at_most_one(glossy):
    r = fit(glossy, "ggx", physical=True)
    assert np.all(r.params["ks"] <= 1.0) and np.all(r.params["kd"] <= 1.0)
    assert r.at_bound == {"ks": "upper"}
    assert any(w.startswith("ks ended on its upper bound 1 (its physical range") for w in r.warnings)
    assert r.options["physical"] is True


def test_fixed_and_bounds_hold():
    truth = {"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.25], "f0": [0.3]}
    meas = _scattered("ggx", truth)
    r = fit(meas, "ggx", fixed={"f0": 0.1, "kd": [0.3, 0.25, 0.1]}, bounds={"alpha": (0.3, 0.6)})
    assert r.params["f0"].tolist() == [0.1]  # exactly, not approximately
    assert r.metrics["log"] == pytest.approx(r.loss_value, rel=1e-9)  # the solver held it too
    assert r.params["kd"].tolist() == [0.3, 0.25, 0.1]
    assert 0.3 <= float(r.params["alpha"][0]) <= 0.6
    assert r.at_bound == {"alpha": "lower"}  # the data want 0.25
    assert "f0" not in r.at_bound and r.stderr["f0"] is None
    assert any("alpha ended on its lower bound 0.3 (set by bounds=)" in w for w in r.warnings)
    assert r.options["fixed"] == {"f0": [0.1], "kd": [0.3, 0.25, 0.1]}


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["optx_lm", "scipy"])
def test_fixed_and_bounds_hold_for_other_solvers(solver):
    meas = _scattered("ggx", {"kd": [0.3, 0.2, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.25], "f0": [0.3]})
    r = fit(meas, "ggx", solver=solver, fixed={"f0": 0.1}, bounds={"alpha": (0.3, 0.6)})
    assert r.params["f0"].tolist() == [0.1]
    assert 0.3 <= float(r.params["alpha"][0]) <= 0.6 and r.at_bound == {"alpha": "lower"}


def test_composite_lobes_come_out_ordered():
    truth = {"kd": [0.2, 0.2, 0.2], "ggx1.ks": [0.5, 0.5, 0.5], "ggx1.alpha": [0.5], "ggx1.f0": [0.1],
             "ggx2.ks": [0.3, 0.3, 0.3], "ggx2.alpha": [0.08], "ggx2.f0": [0.1]}
    meas = _scattered("lambert+ggx+ggx", truth)
    # Started at the truth, whose lobes are in the wrong order: the result is its ordered twin.
    r = fit(meas, "lambert+ggx+ggx", init=truth, solver="lm")
    assert float(r.params["ggx1.alpha"][0]) <= float(r.params["ggx2.alpha"][0])
    np.testing.assert_allclose(r.params["ggx1.alpha"], 0.08, rtol=1e-4)
    np.testing.assert_allclose(r.params["ggx2.ks"], 0.5, rtol=1e-4)


def test_narrow_lobe_and_undetermined_parameter_warnings():
    assert math.degrees(sample_spacing(ubo_directions())) == pytest.approx(14.49, abs=0.01)
    # the cache keys it by the bytes: float32 or a list of the same directions is the same set
    assert math.degrees(sample_spacing(ubo_directions().astype(np.float32))) == pytest.approx(14.49, abs=0.01)
    assert math.degrees(sample_spacing(ubo_directions()[:200].tolist())) == pytest.approx(
        math.degrees(sample_spacing(ubo_directions()[:200])), rel=1e-12)
    r = fit(_ubo("ggx", dict(GLOSSY, alpha=[0.03], ks=[0.5] * 3), "sharp"), "ggx")
    assert any("narrower than the sample spacing" in w for w in r.warnings), r.warnings
    # The sentence for a parameter without a standard error that is not on a bound:
    space = ParameterSpace.build(models.get("ggx"))
    v = np.asarray(models.get("ggx").flatten(GLOSSY))
    out = fit_warnings(space, v, {}, {"kd": np.ones(3), "ks": None, "alpha": np.ones(1), "f0": np.ones(1)}, None)
    assert out == ["ks is not determined by the data (it trades off against other parameters; no standard error)."]


def test_json_round_trip_and_older_files(glossy, tmp_path):
    r = fit(glossy, "ggx", physical=True)
    back = FitResult.from_json(r.to_json())
    assert back.at_bound == r.at_bound and back.warnings == r.warnings and back.warnings
    d = json.loads(r.to_json())
    del d["at_bound"], d["warnings"]  # a fit.json written before these fields existed
    old = FitResult.from_json(json.dumps(d))
    assert old.at_bound == {} and old.warnings == ()


# -- CLI ---------------------------------------------------------------------------------------------
def test_cli_bound_fix_physical(glossy, tmp_path, capsys):
    src = tmp_path / "g.npz"
    brdffit.save(glossy, src)
    out = tmp_path / "fit"
    assert main(["fit", str(src), "--model", "ggx", "--fix", "f0=0.05", "--bound", "alpha=0.01,0.5",
                 "--physical", "-o", str(out)]) == 0
    d = json.loads((out / "fit.json").read_text())
    assert d["params"]["f0"] == [0.05] and max(d["params"]["ks"]) <= 1.0
    assert d["at_bound"] == {"ks": "upper"}
    err = capsys.readouterr().err
    assert "warning: ks ended on its upper bound 1" in err
    for args, message in (
        (["--bound", "nosuch=0,1"], "no parameter 'nosuch'"),
        (["--bound", "alpha=0.5"], "expected two numbers"),
        (["--fix", "f0=x"], "'x' is not a number"),
        (["--fix", "f0=2"], "outside its bounds"),
    ):
        assert main(["fit", str(src), "--model", "ggx", *args, "-o", str(tmp_path / "bad")]) == 2, args
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_fit_batch_takes_the_same_space():
    truth = {"kd": [0.3, 0.2, 0.1], "ks": [1.4, 1.3, 1.2], "alpha": [0.25], "f0": [0.3]}
    batch = [_scattered("ggx", truth, seed=s) for s in (0, 1)]
    rs = brdffit.fit_batch(batch, "ggx", fixed={"f0": 0.3}, bounds={"alpha": (0.05, 0.5)})
    for r in rs:
        assert r.params["f0"].tolist() == [0.3]
        np.testing.assert_allclose(r.params["ks"], [1.4, 1.3, 1.2], rtol=1e-4)  # ks > 1 by default
        assert r.at_bound == {} and r.warnings == ()
    rp = brdffit.fit_batch(batch[:1], "ggx", physical=True)[0]
    # f0 is shared by the channels: raising it lets two of them stay below the cap.
    assert list(rp.at_bound) == ["ks"] and rp.at_bound["ks"].startswith("upper")
    assert np.all(rp.params["ks"] <= 1.0) and np.isclose(rp.params["ks"], 1.0).any()


def test_warning_sentences_name_the_lobe_and_the_bound():
    """The sentences of ``fit_warnings``, in full: a composite names its lobe by prefix, a single
    lobe by kind; the width is twice the half width at half maximum; a bound says where it comes
    from; an undetermined parameter says so."""
    spacing = math.radians(14.5)
    composite = models.get("lambert+ggx+ggx")
    space = ParameterSpace.build(composite, bounds={"ggx2.ks": (0.0, 2.0)})
    v = composite.flatten({"kd": [0.2] * 3, "ggx1.ks": [0.5] * 3, "ggx1.alpha": [0.03], "ggx1.f0": [0.1],
                           "ggx2.ks": [2.0] * 3, "ggx2.alpha": [0.4], "ggx2.f0": [0.1]})
    at_bound = space.at_bound(v)
    assert at_bound == {"ggx2.ks": "upper"}
    got = fit_warnings(space, v, at_bound, {"kd": None, "ggx1.f0": np.ones(1)}, spacing)
    (hw,) = [h for lobe, h in lobe_halfwidths(composite, v) if lobe.params[0] == "ggx1.ks"]
    assert got == [
        "ggx2.ks ended on its upper bound 2 (set by bounds=).",
        f"lobe ggx1 is narrower than the sample spacing (width {math.degrees(2 * hw):.2g} degrees at half maximum, "
        "samples 14.5 degrees apart): the samples see little more than its peak, so its width and scale are "
        "poorly determined.",
        "kd is not determined by the data (it trades off against other parameters; no standard error).",
    ]
    single = models.get("ggx")
    v1 = single.flatten({"kd": [0.2] * 3, "ks": [0.5] * 3, "alpha": [0.03], "f0": [0.1]})
    (line,) = fit_warnings(ParameterSpace.build(single), v1, {}, {}, spacing)
    assert line.startswith("the ggx lobe is narrower than the sample spacing (width ")
    # The narrow-lobe test is on the full width: 2 x the half width, not the half width itself.
    assert fit_warnings(ParameterSpace.build(single), v1, {}, {}, 2 * hw - 1e-9) == []


@pytest.mark.parametrize("given, message", [
    ({"bounds": {"alpha": ("a", 1.0)}}, "lower bound for 'alpha': 'a' is not a number"),
    ({"bounds": {"alpha": (0.1, [1])}}, "upper bound for 'alpha': [1] is not a number"),
    ({"fixed": {"f0": None}}, "fixed value for 'f0': None is not a number"),
    ({"fixed": {"f0": float("nan")}}, "fixed value for 'f0': NaN is not a value"),
])
def test_a_value_that_is_not_a_number_is_named(given, message):
    with pytest.raises(UsageError) as caught:
        ParameterSpace.build(models.get("ggx"), **given)
    assert str(caught.value) == message


def test_at_bound_per_channel_and_its_tolerance():
    """A parameter counts as on a finite bound within AT_BOUND_RTOL (1e-6) of its box's width (of
    its finite_range where the box is infinite); per channel where only some channels are; never
    for a held parameter or an infinite bound; and where each bound comes from, for the warnings."""
    g = models.get("ggx")
    space = ParameterSpace.build(g, bounds={"ks": (0.0, 2.0)}, fixed={"f0": 0.5}, physical=True)
    width = 2.0  # ks's box
    v = g.flatten({"kd": [0.0, 0.5, 1.0], "ks": [0.9e-6 * width, 0.5, 2.0 - 0.9e-6 * width],
                   "alpha": [0.5], "f0": [0.5]})
    assert space.at_bound(v) == {"kd": "lower in channel 0; upper in channel 2",
                                 "ks": "lower in channel 0; upper in channel 2"}
    off = g.flatten({"kd": [0.5, 0.5, 0.5], "ks": [1.1e-6 * width, 1.0, 2.0 - 1.1e-6 * width],
                     "alpha": [1.0], "f0": [0.5]})
    assert space.at_bound(off) == {"alpha": "upper"}  # ks just outside the tolerance; f0 held
    both = g.flatten({"kd": [1.0, 1.0, 0.0], "ks": [0.0, 0.0, 0.0], "alpha": [0.5], "f0": [0.5]})
    assert space.at_bound(both) == {"kd": "lower in channel 2; upper in channels 0, 1", "ks": "lower"}
    # The formula's box only: ks has no upper bound, so a large ks is on none.
    free = ParameterSpace.build(g)
    assert free.at_bound(g.flatten({"kd": [0.5] * 3, "ks": [1e6] * 3, "alpha": [0.5], "f0": [0.5]})) == {}
    # an infinite box measures its tolerance on the parameter's finite_range (alpha: 1e-6 x ~1)
    lo_alpha = g.param("alpha").lower
    assert free.at_bound(g.flatten({"kd": [0.5] * 3, "ks": [0.5] * 3, "alpha": [lo_alpha + 5e-7],
                                    "f0": [0.5]})) == {"alpha": "lower"}
    assert space.bound_origin("ks", "upper") == "set by bounds="
    assert space.bound_origin("kd", "upper") == "its physical range; fit without physical=True to allow more"
    assert space.bound_origin("kd", "lower") == "the formula's limit"
    assert free.bound_origin("f0", "upper") == "the formula's limit"
    # with physical=True, a bound equal to the formula's (f0 <= 1) is still the formula's limit
    assert ParameterSpace.build(g, physical=True).bound_origin("f0", "upper") == "the formula's limit"
    assert (space.describe_bound("ks", "upper"), space.describe_bound("kd", "upper")) == (2.0, 1.0)


def test_only_lobes_of_one_kind_are_interchangeable():
    """ggx and cook_torrance lobes have equal parameter boxes, yet are different formulas: never
    swapped. Two kinds with two lobes each give two groups."""
    assert ParameterSpace.build(models.get("ggx+cook_torrance")).order == ()
    assert ParameterSpace.build(models.get("phong+blinn_phong")).order == ()
    order = ParameterSpace.build(models.get("ggx+ggx+blinn_phong+blinn_phong")).order
    assert [[lobe.params[0] for lobe in group] for group in order] == [["ggx1.ks", "ggx2.ks"],
                                                                       ["blinn_phong1.ks", "blinn_phong2.ks"]]


def test_fold_reflects_into_the_bounds_by_hand():
    """``models.base._fold``: x folded onto [a, b] by reflection at the bounds (period 2 (b - a)),
    one reflection for one finite bound, the identity for none, the bound itself for a = b; bounds
    given per element. Expected values worked out by hand; the slope is +-1 everywhere, also at the
    bounds, and never NaN (infinite bounds included)."""
    from brdffit.models.base import _fold

    inf = np.inf
    cases = [  # (x, a, b, folded)
        (0.25, 0.0, 1.0, 0.25), (1.25, 0.0, 1.0, 0.75), (2.5, 0.0, 1.0, 0.5), (-0.25, 0.0, 1.0, 0.25),
        (-1.5, 0.0, 1.0, 0.5), (3.75, 0.0, 1.0, 0.25), (9.0, 2.0, 5.0, 3.0), (-4.0, 2.0, 5.0, 2.0),
        (-2.0, 1.0, inf, 4.0), (3.0, 1.0, inf, 3.0), (5.0, -inf, 2.0, -1.0), (0.0, -inf, 2.0, 0.0),
        (7.0, -inf, inf, 7.0), (3.0, 1.0, 1.0, 1.0), (-3.0, 1.0, 1.0, 1.0), (6.5, 2.0, 5.0, 3.5),
        (1.0, -inf, 2.0, 1.0),
    ]
    x, a, b, expected = (np.array(c, np.float64) for c in zip(*cases))
    np.testing.assert_allclose(np.asarray(_fold(jnp.asarray(x), jnp.asarray(a), jnp.asarray(b))), expected,
                               rtol=0, atol=1e-12)
    for xi, ai, bi, want in cases:  # scalars too
        assert float(_fold(xi, ai, bi)) == pytest.approx(want, abs=1e-12)
    slope = jax.vmap(jax.grad(_fold), in_axes=(0, 0, 0))
    at = np.array([0.0, 1.0, 0.5, 1.0, 2.0, 7.0])
    lo = np.array([0.0, 0.0, 0.0, 1.0, -inf, -inf])
    hi = np.array([1.0, 1.0, 1.0, inf, 2.0, inf])
    np.testing.assert_array_equal(np.abs(np.asarray(slope(jnp.asarray(at), jnp.asarray(lo), jnp.asarray(hi)))), 1.0)


def test_bounds_alone_or_fixed_alone_narrow_the_space_and_none_gives_the_models_own():
    from brdffit.fitting.space import parameter_space

    ggx = models.get("ggx")
    alpha = dict(ggx.slices())["alpha"].start
    narrowed = parameter_space(ggx, bounds={"alpha": (0.3, 0.5)})
    assert (narrowed.lo[alpha], narrowed.hi[alpha]) == (0.3, 0.5) and narrowed.free.all()
    held = parameter_space(ggx, fixed={"alpha": 0.2})
    assert not held.free[alpha] and held.values[alpha] == 0.2 and held.free.sum() == ggx.n_free - 1
    own = parameter_space(ggx)
    lo, hi = ggx.bounds()
    np.testing.assert_array_equal(own.lo, lo)
    np.testing.assert_array_equal(own.hi, hi)
    assert own.free.all() and parameter_space(ggx) is own  # built once per model
