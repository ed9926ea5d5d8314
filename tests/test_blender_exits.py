"""Exit statuses and leftovers of the Blender worker's paths (docs/cli.md#the-command-line-and-set-up and docs/materials.md#native-materials-and-exports): a worker that dies is exit
2 with one line (not 3, which README reserves for bugs); a worker that answers "ready" then hangs is
stopped within the request's budget; Ctrl-C during a ``.blend`` export leaves nothing in TMPDIR.

Most tests run a stand-in worker (a shell script in place of the Blender environment's interpreter)
that behaves as a dying or hanging Blender would, so they need no Blender; the last one sweeps Ctrl-C
over a real ``.blend`` export."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from brdffit import cycles
from brdffit.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import deliverable_sigint, interrupted_before_brdffit_ran  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}
BLENDER_FIT = {"model": "blender:principled", "converged": True, "data_name": "paint",
               "params": {"base_color": [0.5, 0.3, 0.2], "metallic": [0.1], "roughness": [0.3], "ior": [1.5],
                          "specular_tint": [1.0]}}
#: In place of `.venv-blender/bin/python -u _worker.py`: makes a folder in its TMPDIR as Blender does,
#: says it is ready, then on the first request dies (SIGKILL), hangs, or works until stopped.
FAKE_WORKER = """#!/bin/sh
mkdir -p "$TMPDIR/blender_fake"
echo '{"ready": true, "blender": "fake"}'
read request || exit 0  # end of input: the worker ends
touch "$TMPDIR/blender_fake/working"
case "$FAKE_BLENDER" in
  die) kill -9 $$ ;;
  *) exec sleep 600 ;;
esac
"""


def brdffit_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("brdffit")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]


@pytest.fixture
def fake_blender(tmp_path, monkeypatch):
    """A stand-in worker interpreter, its TMPDIR private to the test; the shared worker reset."""
    python = tmp_path / "bin" / "python"
    python.parent.mkdir()
    python.write_text(FAKE_WORKER)
    python.chmod(0o755)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv(cycles.ENV_VAR, str(python))
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(cycles, "_SHARED", None)
    yield python, tmp
    if cycles._SHARED is not None:
        cycles._SHARED.close()


def fit_file(folder: Path) -> Path:
    p = folder / "fit.json"
    p.write_text(json.dumps(BLENDER_FIT))
    return p


def test_a_worker_that_dies_during_the_export_is_exit_2(fake_blender, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FAKE_BLENDER", "die")
    src, out = fit_file(tmp_path), tmp_path / "out" / "paint.blend"
    assert main(["export", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "internal error" not in err, err
    assert "the Blender worker ended during 'blend'" in err
    assert not out.exists()


def test_a_worker_that_hangs_is_stopped_within_the_budget(fake_blender, tmp_path):
    """(Before: waited on for 600 s.) The budget is shortened to 3 s here; the command's process runs
    under a guard of 120 s."""
    python, tmp = fake_blender
    src, out = fit_file(tmp_path), tmp_path / "paint.blend"
    child = ("import sys; from brdffit import cycles; cycles.BUDGET_S = 3.0; from brdffit.cli import main; "
             f"sys.exit(main(['export', {str(src)!r}, '-o', {str(out)!r}]))")
    env = {**ENV, cycles.ENV_VAR: str(python), "TMPDIR": str(tmp), "FAKE_BLENDER": "hang"}
    p = subprocess.Popen([sys.executable, "-c", child], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env, start_new_session=True)
    try:
        code = p.wait(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        pytest.fail("the hung worker was waited on beyond the command's budget")
    err = p.stderr.read()
    assert code == 2, err
    assert err.count("\n") == 1 and "did not answer 'blend' within 3 s" in err, err
    assert not out.exists() and list(tmp.iterdir()) == []  # the worker stopped, its folder removed


def test_the_worker_runs_in_a_session_of_its_own(fake_blender):
    """A terminal's Ctrl-C reaches brdffit only, which stops the worker before removing its folder:
    a worker that died of the signal on its own could be seen ending (a second line) before brdffit
    knew of the interrupt, and leave what Blender was writing."""
    w = cycles.worker()
    assert os.getsid(w._proc.pid) == w._proc.pid != os.getsid(0)
    assert w.scratch.is_dir()
    w.close()
    assert not w.scratch.exists()


def _ctrl_c_export(tmp_path: Path, env: dict, when) -> tuple[int, str, Path, Path]:
    """``brdffit export FIT -o out/paint.blend`` in a process group of its own (as a shell runs a
    command), Ctrl-C sent to the whole group (as a terminal does) once ``when(tmp)`` is true."""
    tmp, out = tmp_path / "tmp", tmp_path / "out"
    tmp.mkdir(exist_ok=True)
    out.mkdir()
    src = fit_file(tmp_path)
    p = subprocess.Popen([*brdffit_cmd(), "export", str(src), "-o", str(out / "paint.blend")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env={**ENV, **env, "TMPDIR": str(tmp)},
                         preexec_fn=deliverable_sigint, start_new_session=True)
    deadline = time.monotonic() + 120
    while not when(tmp) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGINT)
    code = p.wait(timeout=60)
    time.sleep(0.5)  # anything that outlives the command would write now
    return code, p.stderr.read(), tmp, out


def test_ctrl_c_while_the_worker_works_leaves_nothing_in_tmpdir(fake_blender, tmp_path):
    python, _ = fake_blender
    code, err, tmp, out = _ctrl_c_export(tmp_path, {cycles.ENV_VAR: str(python), "FAKE_BLENDER": "work"},
                                         lambda tmp: any(tmp.rglob("working")))
    assert code == 130 and err == "brdffit: interrupted\n", (code, err)
    assert sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*")) == [] and list(out.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("moment", [0.1, 0.4, 0.7, 1.0, 1.3, 1.6])
def test_ctrl_c_at_a_fixed_moment_of_a_real_blend_export(blender, tmp_path, moment):
    """A real export (Blender's worker): Ctrl-C at fixed moments from the start. Before: an empty
    brdffit-cycles-* folder, sometimes Blender's blender_* folder, left in TMPDIR."""
    start = time.monotonic()
    code, err, tmp, out = _ctrl_c_export(tmp_path, {}, lambda tmp: time.monotonic() - start > moment)
    assert sorted(p.name for p in tmp.rglob("*")) == [], (code, err)
    if code == 0:  # the export ended before the signal
        assert [p.name for p in out.iterdir()] == ["paint.blend"]
    elif interrupted_before_brdffit_ran(code, err):
        assert list(out.iterdir()) == [], (code, err)
    else:
        assert code == 130 and err.endswith("brdffit: interrupted\n") and "Traceback" not in err, (code, err)
        assert list(out.iterdir()) == []
