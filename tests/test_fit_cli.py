"""CLI `brdffit fit` / `brdffit compare`: outputs, exit codes (docs/cli.md#the-command-line-and-set-up). Small NPZ inputs."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.cli import main
from brdffit.grid import ubo_pairs

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ubo_npz(tmp_path_factory):
    wi, wo = ubo_pairs()
    m = models.get("ggx")
    p = {"kd": [0.3, 0.2, 0.1], "ks": [0.5, 0.4, 0.3], "alpha": [0.2], "f0": [0.1]}
    f = np.asarray(m.eval(m.check_params(p), wi, wo))
    f = f * (1 + 0.01 * np.random.default_rng(0).standard_normal(f.shape))
    path = tmp_path_factory.mktemp("data") / "syn.npz"
    brdffit.save(brdffit.Measurement(wi, wo, f, grid="ubo81", name="syn"), path)
    return path


def test_fit_writes_json_and_plot(ubo_npz, tmp_path):
    out = tmp_path / "fit"
    assert main(["fit", str(ubo_npz), "--model", "ggx", "-o", str(out)]) == 0
    d = json.loads((out / "fit.json").read_text())
    assert d["model"] == "ggx" and d["converged"] is True and d["channels"] == 3
    assert abs(d["params"]["alpha"][0] - 0.2) < 0.004
    assert (out / "fit.png").stat().st_size > 10_000
    r = brdffit.FitResult.from_json(out / "fit.json")
    assert r.model_name == "ggx"
    # An existing result is kept without --force (exit 2), replaced with it.
    assert main(["fit", str(ubo_npz), "--model", "ggx", "-o", str(out)]) == 2
    assert main(["fit", str(ubo_npz), "--model", "lambert", "-o", str(out), "--force"]) == 0
    assert json.loads((out / "fit.json").read_text())["model"] == "lambert"


def test_fit_not_converged_exits_1_and_still_writes(ubo_npz, tmp_path):
    out = tmp_path / "nc"
    assert main(["fit", str(ubo_npz), "--model", "ggx", "--max-steps", "1", "-o", str(out)]) == 1
    assert json.loads((out / "fit.json").read_text())["converged"] is False


@pytest.mark.parametrize(
    "args",
    [
        ["--model", "nope"],
        ["--model", "ggx", "--loss", "nope"],
        ["--model", "ggx", "--solver", "nope"],
    ],
)
def test_fit_bad_usage_exits_2_and_writes_nothing(ubo_npz, tmp_path, args, capsys):
    out = tmp_path / "bad"
    assert main(["fit", str(ubo_npz), *args, "-o", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_fit_missing_file_exits_2(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing.npz"), "--model", "ggx", "-o", str(tmp_path / "o")]) == 2
    assert "missing.npz" in capsys.readouterr().err


def test_compare_writes_report(ubo_npz, tmp_path):
    out = tmp_path / "cmp"
    code = main(["compare", str(ubo_npz), "--models", "lambert,ggx", "--solvers", "lm,scipy", "-o", str(out)])
    assert code == 0
    rows = json.loads((out / "report.json").read_text())["rows"]
    assert len(rows) == 4 and {r["model"] for r in rows} == {"lambert", "ggx"}
    assert (out / "report.csv").read_text().count("\n") == 5
    assert (out / "pareto.png").stat().st_size > 10_000
    assert main(["compare", str(ubo_npz), "--models", "ggx", "--losses", "bad", "-o", str(tmp_path / "c2")]) == 2


# A figure made of NumPy arrays only (no JAX, no fit): what FigureProcess is handed.
_FIGURE_SCRIPT = (
    "import sys\n"
    "import numpy as np\n"
    "from brdffit._figure_process import FigureProcess\n"
    "from brdffit.plot import FigureData\n"
    "ref = np.random.default_rng(0).uniform(0.01, 1.0, (200, 3))\n"
    "data = FigureData('scatter', {'ref': ref, 'fitted': ref * 1.1, 'mask': np.ones(200, bool), 'title': 't'})\n"
    "command = None if sys.argv[2] == 'worker' else [sys.argv[2], '-c', 'import sys; sys.exit(1)']\n"
    "with FigureProcess(command) as figure:\n"
    "    figure.savefig(data, sys.argv[1], dpi=50)\n"
    "print('matplotlib' in sys.modules, 'jax' in sys.modules)\n"
)


@pytest.mark.parametrize("worker", ["worker", "failing", "/nonexistent/python"])
def test_the_figure_worker_draws_the_png_and_a_failed_worker_leaves_it_to_this_process(tmp_path, worker):
    """``brdffit fit``'s figure: drawn by the worker (this process imports neither matplotlib nor
    JAX), or, when the worker fails or cannot start, here: the same PNG either way."""
    import subprocess
    import sys

    from PIL import Image

    png = tmp_path / "f.png"
    command = sys.executable if worker == "failing" else worker
    done = subprocess.run([sys.executable, "-c", _FIGURE_SCRIPT, str(png), command], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    drew_here = worker != "worker"
    assert done.stdout.split() == [str(drew_here), "False"]
    assert Image.open(png).size == (325, 300)  # 6.5 x 6.0 inches at 50 dpi


def test_an_unused_figure_worker_is_stopped_at_once():
    """A command that fails before its figure (bad input) must not wait for the worker's import."""
    import time

    from brdffit._figure_process import FigureProcess

    figure = FigureProcess()
    proc = figure._proc
    assert proc is not None and proc.poll() is None
    t0 = time.perf_counter()
    figure.close()
    assert proc.poll() is not None and time.perf_counter() - t0 < 5.0
