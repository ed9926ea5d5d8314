"""Users' surfaces of docs/DESIGN.md#where-users-meet-brdffit (defects 3, 5, 6, 10): Report.pareto, FitResult.eval, light
directions, reprs, dir(brdffit), `brdffit models`, `fit --help`, `info`, tables when piped."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest

import brdffit
from brdffit import Measurement, models
from brdffit.cli import main
from brdffit.errors import UsageError
from brdffit.fitting.compare import Report
from brdffit.fitting.result import FitResult
from brdffit.grid import ubo_pairs

GGX = {"kd": [0.3, 0.25, 0.2], "ks": [0.3, 0.3, 0.3], "alpha": [0.3], "f0": [0.05]}


def fit_result(params=GGX, model="ggx") -> FitResult:
    m = models.get(model)
    return FitResult(model=m, params={k: np.asarray(v, np.float64) for k, v in m.check_params(params).items()},
                     loss="log", loss_value=0.0, metrics={"rmse": 0.1, "log_rmse": 0.01}, steps=3, converged=True,
                     status="converged", seconds={"run": 0.1, "compile": 1.0}, solver="lm", data_name="table",
                     n_used=6561, n_excluded=0)


def row(model, solver, loss_log, run_s):
    return {"model": model, "solver": solver, "loss": "log", "loss_log": loss_log, "run_s": run_s, "converged": True}


# -- defect 3: ties on the Pareto front keep the fastest -------------------------------------------
def test_pareto_ties_keep_the_fastest():
    # the cc_ibiza_sunset case: five solvers reach one loss; lmb is fastest
    rows = (
        row("ggx", "lm", 0.001545, 1.58),
        row("ggx", "lmb", 0.001545 * (1 + 3e-7), 0.12),  # equal within 1e-6 relative
        row("ggx", "dogleg", 0.001545, 0.9),
        row("ggx", "bfgs", 0.001545 * (1 - 2e-7), 2.2),
        row("ggx", "scipy", 0.001545, 0.5),
        row("lambert", "lm", 0.03, 0.01),
        row("lambert", "scipy", 0.03, 0.05),
        row("lambert+ggx+ggx", "lm", 0.0009, 3.0),
        row("lambert+ggx+ggx", "scipy", 0.0011, 4.0),  # slower and worse: off the front
    )
    front = Report(rows, "cc_ibiza_sunset").pareto()
    assert [(r["model"], r["solver"]) for r in front] == [("lambert", "lm"), ("ggx", "lmb"), ("lambert+ggx+ggx", "lm")]


def test_pareto_keeps_a_slower_row_that_is_clearly_better():
    rows = (row("a", "lm", 1.0, 1.0), row("b", "lm", 1.0 - 1e-3, 2.0), row("c", "lm", 1.0 - 1e-9, 0.5))
    # c ties with a (1e-9 relative) and is faster: a drops; b is better by 1e-3: it stays
    assert [r["model"] for r in Report(rows).pareto()] == ["c", "b"]


def test_pareto_plot_labels_only_the_front():
    rows = tuple(row("ggx", s, 0.001545, t) for s, t in (("lm", 1.58), ("lmb", 0.12), ("scipy", 0.5)))
    fig = Report(rows, "x").plot()
    labels = [t.get_text() for t in fig.axes[0].texts]
    assert labels == ["ggx / lmb"]


# -- defect 5: FitResult.eval shapes, horizon --------------------------------------------------------
def test_fit_eval_shapes_and_horizon():
    r = fit_result()
    wi = np.array([0.0, 0.6, 0.8])
    wo = np.array([0.0, -0.6, 0.8])
    one = r.eval(wi, wo)
    assert isinstance(one, np.ndarray) and one.shape == (3,)
    # by hand: at the mirror configuration h = n; D = 1 / (pi alpha^2), Schlick with h.l = 0.8,
    # separable Smith G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)) with tan^2 = 0.5625
    a, f0 = 0.3, 0.05
    d = 1 / (np.pi * a * a)
    f = f0 + (1 - f0) * (1 - 0.8) ** 5
    g1 = 2 / (1 + np.sqrt(1 + a * a * 0.5625))
    expected = np.array([0.3, 0.25, 0.2]) / np.pi + 0.3 * f * g1 * g1 * d / (4 * 0.8 * 0.8)
    np.testing.assert_allclose(one, expected, rtol=1e-10)
    many = r.eval(np.tile(wi, (4, 1)), np.tile(wo, (4, 1)))
    assert many.shape == (4, 3)
    np.testing.assert_allclose(many, np.tile(expected, (4, 1)), rtol=1e-10)
    assert r.eval(wi, np.tile(wo, (2, 1))).shape == (2, 3)
    below = np.array([0.6, 0.0, -0.8])
    np.testing.assert_array_equal(r.eval(below, wo), 0.0)
    np.testing.assert_array_equal(r.eval(wi, below), 0.0)
    with pytest.raises(UsageError):
        r.eval(np.zeros((2, 2)), wo)


def test_model_eval_is_jax_fit_eval_is_numpy():
    import jax

    r = fit_result()
    wi, wo = ubo_pairs()
    assert isinstance(r.model.eval(r.params, wi[:2], wo[:2]), jax.Array)
    assert type(r.eval(wi[:2], wo[:2])) is np.ndarray


# -- defect 5: bad light directions --------------------------------------------------------------------
@pytest.mark.parametrize("lights, words", [
    ([(45, 0)], "not in radians"),
    ([(2.0, 0.0)], "below the horizon"),
    ([(0.3, 0.0, -1.0)], "below the horizon"),
])
def test_render_sphere_rejects_bad_lights(lights, words):
    with pytest.raises(UsageError, match=words) as info:
        brdffit.render_sphere(fit_result(), lights=lights, size=8)
    assert "\n" not in str(info.value)


# -- defect 10: reprs and dir ------------------------------------------------------------------------------
def test_reprs_are_short():
    ggx = models.get("ggx")
    text = repr(ggx)
    assert len(text) < 200 and "\n" not in text and "Lecture form" not in text
    assert text.startswith("Model('ggx': kd(3), ks(3), alpha, f0;")
    rows = tuple(row("ggx", f"s{k}", 1.0 + k, 0.1) for k in range(500))
    rep = repr(Report(rows, "x"))
    assert "\n" not in rep and len(rep) < 200 and "500 rows" in rep


def test_jupyter_reprs():
    r = fit_result()
    assert r._repr_png_().startswith(b"\x89PNG")
    html = r._repr_html_()
    assert "ggx" in html and "alpha" in html and "data:image/png;base64," in html
    rows = tuple(row("ggx", s, 1e-3 * (k + 1), 0.1 * (k + 1)) for k, s in enumerate(("lm", "scipy")))
    rep = Report(rows, "x")
    assert rep._repr_png_().startswith(b"\x89PNG") and "<table>" in rep._repr_html_()
    from brdffit.render.validate import Validation

    imgs = np.zeros((2, 8, 8, 3))
    v = Validation(lights=np.array([[0, 0, 1.0], [0.5, 0, np.sqrt(0.75)]]), reference=imgs, fit=imgs + 0.1,
                   table_reference=np.zeros((81, 81, 3)), table_fit=np.zeros((81, 81, 3)),
                   metrics={"overall": {"rmse": 0.1, "psnr": 20.0, "flip": 0.1},
                            "table": {"rmse": 0.1, "log_rmse": 0.01}}, files=(), seconds={})
    assert v._repr_png_().startswith(b"\x89PNG") and "PSNR" in v._repr_html_()


def test_dir_lists_public_names_only():
    names = dir(brdffit)
    for helper in ("annotations", "importlib", "jax"):
        assert helper not in names
    for public in ("fit", "load", "compare", "validate", "render_sphere", "plot", "FitResult", "models"):
        assert public in names


# -- defect 10 / docs/cli.md#the-command-line-and-set-up: models command, fit --help, ggx's Lambert term ---------------------------------
def test_models_command_lists_every_model(capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    for name in models.names():
        model = models.get(name)
        assert f"\n{name}  (" in "\n" + out
        assert model.citation.splitlines()[0] in out
    assert "alpha  1         [1e-4, inf)  [1e-4, 1]" in out  # ggx's bounds and physical range
    assert "`lambert+ggx` is the same function as `ggx`" in out


def test_lambert_plus_ggx_is_ggx(capsys):
    assert main(["models", "lambert+ggx"]) == 0
    assert "the same function as `ggx`" in capsys.readouterr().out
    wi, wo = ubo_pairs()
    plain = models.get("ggx").eval(models.get("ggx").check_params(GGX), wi, wo)
    both = models.get("lambert+ggx")
    renamed = both.check_params({"kd": GGX["kd"], "ggx1.ks": GGX["ks"], "ggx1.alpha": GGX["alpha"],
                                 "ggx1.f0": GGX["f0"]})
    np.testing.assert_allclose(both.eval(renamed, wi, wo), plain, rtol=1e-12)


def test_fit_help_lists_the_models(capsys):
    from click.testing import CliRunner

    from brdffit.cli import _load_commands, cli

    _load_commands()
    text = " ".join(CliRunner().invoke(cli, ["fit", "--help"]).output.split())
    for name in models.names():
        assert name in text
    assert "brdffit models" in text


# -- defect 6: info, tables when piped -------------------------------------------------------------------
def _console():
    from rich.console import Console

    buf = io.StringIO()
    return Console(file=buf, width=80, force_terminal=False, color_system=None), buf


def test_info_counts_negative_values_and_rounds_angles():
    from brdffit.cli.info import print_info

    wi, wo = ubo_pairs()
    values = np.full((6561, 3), 0.2)
    values[:37, 1] = -0.01  # 37 negative values, all valid samples
    m = Measurement(wi, wo, values, name="neg", grid="ubo81", extra={"max_extrapolation_deg": 20.000008571513593})
    console, buf = _console()
    print_info(m, "npz", "neg.npz", console=console)
    out = buf.getvalue()
    assert re.search(r"negative values +37 ", out), out
    assert "20.0 deg" in out and "20.00000857" not in out


def test_compare_table_is_not_cut_when_piped():
    from brdffit.cli.compare import print_report

    rows = tuple({**row("lambert+ggx+ggx", "scipy", 4.4380123e-3, 12.3456), "n_params": 13, "compile_s": 2.5,
                  "steps": 40, "status": "converged"} for _ in range(2))
    console, buf = _console()
    print_report(Report(rows, "cc_ibiza_sunset"), "log", console)
    out = buf.getvalue()
    assert "lambert+ggx+ggx" in out and "0.004438" in out and "…" not in out
    assert console.width == 80  # the console is left as it was


def test_compare_progress():
    m = Measurement(*ubo_pairs(), np.full((6561, 3), 0.1), name="flat", grid="ubo81")
    seen = []
    report = brdffit.compare(m, ["lambert"], ["lm"], progress=seen.append)
    assert seen == ["lambert / lm / log"] and len(report.rows) == 1
    # progress=True draws a rich bar (a terminal or a notebook); the fits and rows are the same
    assert len(brdffit.compare(m, ["lambert"], ["lm"], progress=True).rows) == 1


def test_compare_progress_bar_names_each_fit_and_ends_full(monkeypatch):
    """The rich bar's text is the fit running ("fitting model / solver / loss"), then "done" with
    every fit counted."""
    import rich.progress

    m = Measurement(*ubo_pairs(), np.full((6561, 3), 0.1), name="flat", grid="ubo81")
    texts, bars = [], []
    update = rich.progress.Progress.update

    def record(self, task, **kw):
        texts.append(kw.get("description"))
        bars.append(self)
        return update(self, task, **kw)

    monkeypatch.setattr(rich.progress.Progress, "update", record)
    brdffit.compare(m, ["lambert"], ["lm", "gauss_newton"], progress=True)
    assert texts == ["fitting lambert / lm / log", "fitting lambert / gauss_newton / log", "done"]
    (task,) = bars[-1].tasks
    assert task.completed == task.total == 2
