"""CLI `brdffit fit` / `brdffit compare`: outputs, exit codes (SPEC 7). Small NPZ inputs."""

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


def test_background_import_returns_the_module_and_raises_its_failure_in_the_caller():
    from brdffit.cli import BackgroundImport

    assert BackgroundImport("brdffit.plot").module().fit_figure.__name__ == "fit_figure"
    broken = BackgroundImport("brdffit._no_such_module")
    with pytest.raises(ModuleNotFoundError, match="brdffit._no_such_module"):
        broken.module()


def test_background_import_is_not_waited_for_after_an_interrupt():
    """Ctrl-C can land inside the import system and leave its lock held by the main thread; the
    background import then waits for ever, so after an interrupt the command must not wait for it
    (seen: ``brdffit fit`` hung after Ctrl-C). In a child process, since the old behaviour hangs."""
    import subprocess
    import sys

    script = (
        "import _imp, time\n"
        "from brdffit.cli import BackgroundImport, Interrupted\n"
        "from brdffit._files import STOP_REQUESTED\n"
        "_imp.acquire_lock()  # left held, as an interrupt inside the import system can leave it\n"
        "pending = BackgroundImport('brdffit._not_imported_yet')\n"
        "STOP_REQUESTED.set()\n"
        "try:\n"
        "    pending.module()\n"
        "except Interrupted:\n"
        "    print('interrupted')\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0 and done.stdout.strip() == "interrupted", done.stderr
