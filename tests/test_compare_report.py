"""brdffit.compare's Report without fitting: the JSON file, the Jupyter table's ranking, and the
Pareto front's ties (docs/fitting.md#fitting: "Rows whose errors tie within rtol keep only the fastest")."""

from __future__ import annotations

import json

from brdffit.fitting.compare import Report


def _row(model, solver, loss_log, run_s):
    return {"model": model, "solver": solver, "loss": "log", "n_params": 2, "loss_log": loss_log,
            "log_rmse": loss_log, "run_s": run_s, "compile_s": 0.5, "steps": 3, "converged": True}


ROWS = (_row("ggx", "lm", 0.02, 1.0), _row("lambert", "lm", 0.5, 0.1), _row("ward", "bfgs", 0.01, 3.0))


def test_to_json_writes_what_it_returns_with_a_final_newline(tmp_path):
    rep = Report(ROWS, "felt")
    text = rep.to_json(tmp_path / "r.json")
    assert (tmp_path / "r.json").read_text() == text + "\n"
    assert json.loads(text) == {"data_name": "felt", "rows": [dict(r) for r in ROWS]}


def test_the_jupyter_table_ranks_rows_by_log_loss():
    html = Report(ROWS, "felt")._repr_html_()
    assert "<p><b>felt</b>: 3 fits, ranked by log loss</p>" in html
    assert ("<table><tr><th>model</th><th>solver</th><th>loss</th><th>n_params</th><th>loss_log</th>"
            "<th>log_rmse</th><th>run_s</th><th>compile_s</th><th>steps</th><th>converged</th></tr>") in html
    assert html.index("<td>ward</td>") < html.index("<td>ggx</td>") < html.index("<td>lambert</td>")


def test_exact_ties_keep_the_first_of_equally_fast_rows_even_without_tolerance():
    rows = (_row("ggx", "lm", 0.02, 1.0), _row("ggx", "lmb", 0.02, 1.0), _row("ggx", "dogleg", 0.03, 0.5))
    front = Report(rows).pareto(rtol=0.0)
    assert [r["solver"] for r in front] == ["dogleg", "lm"]
    # a lower error by less than rtol is a tie: the faster row stays, alone
    near = (_row("ggx", "lm", 0.02 * (1 - 1e-8), 2.0), _row("ggx", "lmb", 0.02, 1.0))
    assert [r["solver"] for r in Report(near).pareto()] == ["lmb"]
    assert [r["solver"] for r in Report(near).pareto(rtol=0.0)] == ["lmb", "lm"]


def test_repr_names_the_data_the_rows_and_the_best_log_loss():
    rows = ROWS + (_row("ggx", "dogleg", 0.0123456, 2.0),)
    assert repr(Report(rows, "felt")) == "Report('felt': 4 rows; best log loss 0.01 (ward / bfgs))"
    assert repr(Report(rows[:2] + rows[3:], "felt")) == "Report('felt': 3 rows; best log loss 0.01235 (ggx / dogleg))"
    assert repr(Report((), "empty")) == "Report('empty': 0 rows)"


def test_compare_without_models_fits_every_registered_model(monkeypatch):
    """``models=None`` (the default) means every model of the registry: here a registry of two, so
    that the test fits two small models, not all of them."""
    import numpy as np

    import brdffit
    from brdffit import models as registry
    from brdffit.fitting import compare

    monkeypatch.setattr(registry, "names", lambda: ["lambert", "phong"])
    wi, wo = brdffit.ubo_pairs()
    m = brdffit.Measurement(wi=wi, wo=wo, values=np.full((6561, 1), 0.2), grid="ubo81", name="grey")
    seen = []
    rep = compare(m, solvers=["lm"], progress=seen.append)
    assert [r["model"] for r in rep.rows] == ["lambert", "phong"] and len(seen) == 2
    assert compare(m, models=[], solvers=["lm"]).rows[0]["model"] == "lambert"  # empty: the same default
