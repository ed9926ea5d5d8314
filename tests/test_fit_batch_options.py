"""fit_batch's options beyond the defaults: given starts (with and without the grid), the progress bar,
and that each fit's metrics and Gauss-Newton matrix come out of the batch program (a per-fit program
after it would cost a compile and a call per fit). Small Lambert and GGX problems."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.fitting import fit, fit_batch
from brdffit.fitting.options import default_starts
from test_fit_core import TRUE, _measurement


@pytest.fixture(scope="module")
def two():
    return [_measurement({**TRUE, "alpha": [a]}, n=200, noise=0.01, seed=i) for i, a in enumerate((0.2, 0.3))]


def test_given_starts_without_the_grid_are_where_each_fit_starts(two):
    starts = [{**TRUE, "alpha": [0.15]}, {**TRUE, "alpha": [0.4], "f0": [0.5]}]
    rs = fit_batch(two, "ggx", starts=starts, grid=False, max_steps=3)
    for r, s in zip(rs, starts):
        assert r.options["init"] == "given"
        assert set(r.seconds) == {"compile", "run", "init"} and r.seconds["init"] == 0.0  # as fit's
        for name, value in s.items():
            np.testing.assert_allclose(r.start[name], value, rtol=1e-12, err_msg=name)
    # flat vectors (the model's free-parameter order) are the same starts
    flat = [models.get("ggx").flatten(models.get("ggx").check_params(s)) for s in starts]
    again = fit_batch(two, "ggx", starts=flat, grid=False, max_steps=3)
    for r, q in zip(again, rs):
        for name in q.params:
            np.testing.assert_allclose(r.start[name], q.start[name], rtol=1e-12)
            np.testing.assert_allclose(r.params[name], q.params[name], rtol=1e-9)


def test_a_given_start_is_ranked_beside_the_grid(two):
    """The truth as a start beats every grid point: the fit starts there."""
    truth = [{**TRUE, "alpha": [a]} for a in (0.2, 0.3)]
    rs = fit_batch(two, "ggx", starts=truth, max_steps=1, multistart=0)
    for r, t in zip(rs, truth):
        assert r.options["init"] == "grid"
        np.testing.assert_allclose(r.start["alpha"], t["alpha"], rtol=1e-12)


def test_starts_of_the_wrong_number_or_size_are_refused(two):
    with pytest.raises(brdffit.UsageError, match="1 starts for 2 measurements"):
        fit_batch(two, "ggx", starts=[TRUE])
    with pytest.raises(brdffit.UsageError, match="starts have 3 values, model ggx has 8"):
        fit_batch(two, "ggx", starts=np.zeros((2, 3)))


def test_the_progress_bar_counts_the_fits(two, capsys):
    rs = fit_batch(two, "lambert", progress=True)
    shown = capsys.readouterr()
    assert len(rs) == 2 and "fit_batch lambert" in shown.err and "2/2" in shown.err, shown
    assert shown.out == ""  # stdout stays for results


def test_each_fits_metrics_and_gauss_newton_matrix_come_from_the_batch_program(two, monkeypatch):
    """Every program a batch compiles or calls is a stage of the pipeline (start, round, finish): no
    program of one fit runs after them for its metrics or J^T J (any module's ``compiled`` is watched)."""
    import sys

    from brdffit.fitting import cache

    asked = []
    real = cache.compiled

    def spy(key, *a, **kw):
        asked.append(key[0])
        return real(key, *a, **kw)

    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("brdffit") and getattr(module, "compiled", None) is real:
            monkeypatch.setattr(module, "compiled", spy)
    batch = fit_batch(two, "ggx")
    assert asked and set(asked) <= {"start", "round", "finish"}, asked
    monkeypatch.undo()
    for r, m in zip(batch, two):
        single = fit(m, "ggx")
        for name in ("alpha", "f0"):
            np.testing.assert_allclose(r.stderr[name], single.stderr[name], rtol=2e-3, err_msg=name)
        for key, value in single.metrics.items():
            assert r.metrics[key] == pytest.approx(value, rel=2e-3, abs=1e-12), key


SHARDED = """
import json, sys
import jax
import numpy as np
sys.path.insert(0, sys.argv[1])
from test_fit_core import TRUE, _measurement
import brdffit
ms = [_measurement({**TRUE, "alpha": [a]}, n=200, noise=0.01, seed=i) for i, a in enumerate((0.2, 0.3, 0.25, 0.15))]
rs = brdffit.fit_batch(ms, "ggx", chunk=2)
print(json.dumps({"devices": len(jax.local_devices()), "alpha": [float(r.params["alpha"][0]) for r in rs],
                  "converged": [r.converged for r in rs]}))
"""


def test_the_batch_axis_is_sharded_over_several_devices_with_the_same_results():
    """Two CPU devices (XLA's host device count): chunks of two fits are split over them."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", BRDFFIT_CACHE="off")
    run = subprocess.run([sys.executable, "-c", SHARDED, str(Path(__file__).parent)], capture_output=True,
                         text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["devices"] == 2 and all(got["converged"]), got
    ms = [_measurement({**TRUE, "alpha": [a]}, n=200, noise=0.01, seed=i) for i, a in enumerate((0.2, 0.3, 0.25, 0.15))]
    single = [float(r.params["alpha"][0]) for r in fit_batch(ms, "ggx", chunk=2)]
    np.testing.assert_allclose(got["alpha"], single, rtol=1e-6)


def test_lobes_of_one_kind_come_out_narrowest_first_in_a_batch():
    truth = {"kd": [0.2, 0.2, 0.2], "ggx1.ks": [0.3, 0.3, 0.3], "ggx1.alpha": [0.08], "ggx1.f0": [0.5],
             "ggx2.ks": [0.2, 0.2, 0.2], "ggx2.alpha": [0.4], "ggx2.f0": [0.5]}
    ms = [_measurement(truth, model="lambert+ggx+ggx", n=300, seed=s) for s in (0, 1)]
    for r in fit_batch(ms, "lambert+ggx+ggx", max_steps=30):
        assert r.params["ggx1.alpha"][0] <= r.params["ggx2.alpha"][0], r.params
    # started with the lobes the other way round, the solve ends there; the result is reordered
    swapped = {**truth, "ggx1.ks": truth["ggx2.ks"], "ggx1.alpha": [0.4], "ggx2.ks": truth["ggx1.ks"],
               "ggx2.alpha": [0.08]}
    for r in fit_batch(ms, "lambert+ggx+ggx", starts=[swapped, swapped], grid=False, max_steps=30):
        assert r.params["ggx1.alpha"][0] == pytest.approx(0.08, rel=0.05), r.params
        np.testing.assert_allclose(r.params["ggx1.ks"], truth["ggx1.ks"], rtol=0.05)
        assert r.params["ggx2.alpha"][0] == pytest.approx(0.4, rel=0.05), r.params


def test_a_batch_records_what_it_solved_in_each_fits_options(two):
    """``options`` tells how a fit was made: a batch fit says so, and ``starts`` counts the starts
    solved (1 + multistart; fit's default when multistart is None), as ``fit`` records it."""
    for multistart in (0, 2, None):
        rs = fit_batch(two, "ggx", multistart=multistart, max_steps=5)
        single = fit(two[0], "ggx", multistart=multistart, max_steps=5)
        want = 1 + (default_starts(models.get("ggx")) - 1 if multistart is None else multistart)
        for r in rs:
            assert r.options["batch"] is True
            assert r.options["starts"] == single.options["starts"] == want, (multistart, r.options)
            assert r.options["multistart"] == multistart


def test_reordered_lobes_carry_their_standard_errors_in_a_batch():
    """A batch fit started with the lobes the other way round ends at the same optimum, reordered
    narrowest first: its J'J must be permuted on rows and columns alike, so that its standard
    errors equal those of the fit started in order (noisy data: standard errors not ~0)."""
    truth = {"kd": [0.2, 0.2, 0.2], "ggx1.ks": [0.3, 0.3, 0.3], "ggx1.alpha": [0.08], "ggx1.f0": [0.5],
             "ggx2.ks": [0.2, 0.2, 0.2], "ggx2.alpha": [0.4], "ggx2.f0": [0.5]}
    swapped = {**truth, "ggx1.ks": truth["ggx2.ks"], "ggx1.alpha": [0.4], "ggx2.ks": truth["ggx1.ks"],
               "ggx2.alpha": [0.08]}
    ms = [_measurement(truth, model="lambert+ggx+ggx", n=400, noise=0.02, seed=s) for s in (0, 1)]
    in_order = fit_batch(ms, "lambert+ggx+ggx", starts=[truth, truth], grid=False)
    reordered = fit_batch(ms, "lambert+ggx+ggx", starts=[swapped, swapped], grid=False)
    for a, b in zip(in_order, reordered):
        assert a.converged and b.converged, (a.status, b.status)
        assert b.params["ggx1.alpha"][0] < b.params["ggx2.alpha"][0]
        for name in a.params:
            np.testing.assert_allclose(b.params[name], a.params[name], rtol=1e-4, err_msg=name)
            if a.stderr[name] is None:  # at a bound, or not determined: the same in both
                assert b.stderr[name] is None, name
            else:
                np.testing.assert_allclose(b.stderr[name], a.stderr[name], rtol=1e-3, err_msg=name)
        assert {"ggx1.alpha", "ggx1.ks", "ggx2.alpha", "ggx2.ks"} <= {k for k, v in a.stderr.items() if v is not None}
