"""No lost results (docs/cli.md#the-command-line-and-set-up): concurrent writers, kills at every point of a --force replacement,
Ctrl-C, and usage problems with the output found before the work."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from brdffit._files import atomic_dir, reserve
from brdffit.cli import main
from brdffit.errors import UsageError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import deliverable_sigint, interrupted_before_brdffit_ran  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "sample_ubo81.exr"
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}


def brdffit_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("brdffit")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]


def hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.mark.slow
def test_three_concurrent_fits_one_wins_others_exit_2(tmp_path):
    """The issue's reproduction: three fits into one folder at once. One exits 0 and its result is
    the one on disk; the two others exit 2 with one line; nothing else remains beside it."""
    out = tmp_path / "C"
    procs = {loss: subprocess.Popen([*brdffit_cmd(), "fit", str(SAMPLE), "--model", "lambert", "--loss", loss,
                                     "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
             for loss in ("log", "l2", "cbrt")}
    results = {loss: (p.wait(timeout=600), p.stderr.read()) for loss, p in procs.items()}
    winners = [loss for loss, (code, _) in results.items() if code == 0]
    assert len(winners) == 1, results
    for loss, (code, err) in results.items():
        if loss != winners[0]:
            assert code == 2, (loss, code, err)
            assert err.count("\n") == 1 and str(out) in err and "Traceback" not in err, err
    assert json.loads((out / "fit.json").read_text())["loss"] == winners[0]
    assert hidden(tmp_path) == []


def test_lock_refuses_a_second_writer_while_the_first_works(tmp_path):
    """Deterministic version of the race: while this process holds the output, a real run exits 2
    ("another brdffit run"), even with --force, and writes nothing."""
    out, table = tmp_path / "held", tmp_path / "held.npz"
    with reserve(out, force=False, folder=True), reserve(table, force=False, folder=False):
        r = subprocess.run([*brdffit_cmd(), "convert", str(SAMPLE), str(table), "--force"], capture_output=True,
                           text=True, env=ENV, timeout=300)
        r2 = subprocess.run([*brdffit_cmd(), "fit", str(SAMPLE), "--model", "lambert", "-o", str(out), "--force"],
                            capture_output=True, text=True, env=ENV, timeout=300)
    for run in (r, r2):
        assert run.returncode == 2, run.stderr
        assert run.stderr.count("\n") == 1 and "another brdffit run" in run.stderr, run.stderr
    assert not out.exists() and not table.exists() and hidden(tmp_path) == []


# -- kills at every line of a --force replacement -----------------------------------------------------
KILL_CHILD = r"""
import os, signal, sys, types
from pathlib import Path

# brdffit._files without the package's __init__ (which imports JAX): a child starts in ~50 ms
package = types.ModuleType("brdffit")
package.__path__ = [os.path.join(os.environ["PYTHONPATH"], "brdffit")]
sys.modules["brdffit"] = package
import brdffit._files as files

target, kill_at, label = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
source = files.__file__
count = 0

def tracer(frame, event, arg):
    global count
    if frame.f_code.co_filename != source:
        return tracer
    if event == "line":
        count += 1
        if count == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
    return tracer

sys.settrace(tracer)
with files.atomic_dir(target, force=True) as tmp:
    for k in range(3):
        (tmp / f"part{k}.txt").write_text(label * 1000)
sys.settrace(None)
print(count)
"""


def complete(folder: Path) -> str | None:
    """The label a result folder holds when it is complete (three identical parts), else None."""
    parts = [folder / f"part{k}.txt" for k in range(3)]
    if not all(p.is_file() for p in parts):
        return None
    texts = {p.read_text() for p in parts}
    return texts.pop()[0] if len(texts) == 1 else None


def run_child(target: Path, kill_at: int, label: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", KILL_CHILD, str(target), str(kill_at), label], capture_output=True,
                          text=True, env=ENV, timeout=60)


def test_sigkill_at_every_line_of_a_forced_replacement(tmp_path):
    """SIGKILL at each line the replacement executes in brdffit._files: the target always holds the
    complete old ("a") or new ("b") result; the next run leaves no hidden entry behind."""
    target = tmp_path / "result"
    first = run_child(target, 0, "a")
    assert first.returncode == 0 and complete(target) == "a", first.stderr
    total = int(run_child(target, 0, "a").stdout)  # lines executed by a whole forced replacement
    assert total > 20
    killed = 0
    for kill_at in range(1, total + 1):
        r = run_child(target, kill_at, "b")
        killed += r.returncode == -signal.SIGKILL
        state = complete(target)
        assert state in ("a", "b"), (kill_at, r.returncode, sorted(p.name for p in tmp_path.iterdir()))
        # the next run (here, in this process) cleans what the killed one left
        with atomic_dir(target, force=True) as tmp:
            for k in range(3):
                (tmp / f"part{k}.txt").write_text("a" * 1000)
        assert complete(target) == "a"
        assert hidden(tmp_path) == [], (kill_at, hidden(tmp_path))
    assert killed >= total - 2  # (the last lines may come after the tracer's final count)


@pytest.mark.slow
def test_sigkill_during_a_real_fit_leaves_the_old_result(tmp_path):
    """A real ``fit --force`` killed while it works: the old fit.json stays complete; the next run
    replaces it and leaves no hidden entry."""
    out = tmp_path / "F"
    args = [*brdffit_cmd(), "fit", str(SAMPLE), "--model", "lambert", "-o", str(out), "--force"]
    assert subprocess.run(args, capture_output=True, env=ENV, timeout=600).returncode == 0
    old = (out / "fit.json").read_text()
    p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    lock = tmp_path / ".F.brdffit-lock"
    deadline = time.monotonic() + 300
    while not lock.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=60)
    assert (out / "fit.json").read_text() == old and (out / "fit.png").is_file()
    assert subprocess.run(args, capture_output=True, env=ENV, timeout=600).returncode == 0
    assert json.loads((out / "fit.json").read_text())["model"] == "lambert"
    assert hidden(tmp_path) == []


def test_ctrl_c_exits_130_with_nothing_written(tmp_path):
    out = tmp_path / "I"
    # No compile cache: the fit then takes seconds (compiling), so the interrupt lands mid-work
    # (with a warm cache the whole fit can end before the signal arrives).
    p = subprocess.Popen([*brdffit_cmd(), "fit", str(SAMPLE), "--model", "lambert+ggx", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**ENV, "BRDFFIT_CACHE": "off"},
                         preexec_fn=deliverable_sigint)
    lock = tmp_path / ".I.brdffit-lock"
    deadline = time.monotonic() + 300
    while not lock.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert p.poll() is None, p.stderr.read()
    # At once, while the output is being reserved and the EXR read: an interrupt there was once lost
    # (its exception raised inside JAX's garbage-collection callback, which swallows it).
    p.send_signal(signal.SIGINT)
    code = p.wait(timeout=120)
    err = p.stderr.read()
    assert code == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # no result, no temporary folder, no lock file


@pytest.mark.slow
@pytest.mark.parametrize("moment", [0.3, 0.7, 1.5, 3.0])
def test_ctrl_c_at_a_fixed_moment_ends_at_once_with_nothing_written(tmp_path, moment):
    """docs/fitting.md#hostile-but-valid-data: SIGINT at fixed moments of a ``brdffit fit`` (the full sweep is
    benchmarks/bench_interrupt.py). During the interpreter's own start-up the signal is Python's (see
    conftest.interrupted_before_brdffit_ran); from brdffit's first line on, brdffit ends it (130); never an abort, a crash or a hang (the old handler
    raised into whatever ran: -11 at 0.3 s in the sweep), and nothing is left in the folder."""
    out = tmp_path / "fit"
    p = subprocess.Popen([*brdffit_cmd(), "fit", str(SAMPLE), "--model", "lambert+ggx+ggx", "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**ENV, "BRDFFIT_CACHE": "off"},
                         preexec_fn=deliverable_sigint)
    time.sleep(moment)
    assert p.poll() is None, "the fit ended before the signal: the moment is too late for this test"
    p.send_signal(signal.SIGINT)
    sent = time.monotonic()
    code = p.wait(timeout=60)
    assert time.monotonic() - sent < 5.0
    err = p.stderr.read()
    if not interrupted_before_brdffit_ran(code, err):
        assert code == 130 and err.strip().endswith("brdffit: interrupted") and "Traceback" not in err, (code, err)
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_after_the_commit_takes_the_result_back(tmp_path, handler_sees_this_test_alone):
    """The executable's Ctrl-C handler removes what this command wrote, a committed result too (the
    old handler reported 130 with the result written when the signal came after the commit)."""
    from brdffit import _files

    _files.forget_committed()
    with atomic_dir(tmp_path / "done") as tmp:
        (tmp / "fit.json").write_text("{}")
    with reserve(tmp_path / "pending", folder=True):
        (tmp_path / ".pending.brdffit-new-x").mkdir()  # a temporary result being built
        _files.remove_this_runs_outputs(timeout=1.0)
        assert list(tmp_path.iterdir()) == []
    _files._GUARD.release()  # the watcher would end the process here, holding it
    _files.forget_committed()


def test_an_interrupt_keeps_a_result_completed_by_its_last_file(tmp_path, handler_sees_this_test_alone):
    """A result of several files (a BTF material: previews, summary, then params.exr) is kept from the
    moment its last file is committed, in the same step: an interrupt right after took the finished
    material back (CI: the database run's Ctrl-C once cork/params.exr existed)."""
    from brdffit import _files
    from brdffit._files import atomic_file

    _files.forget_committed()
    material, next_one = tmp_path / "cork", tmp_path / "felt"
    material.mkdir()
    next_one.mkdir()
    _files.complete_with(material / "params.exr")
    for name in ("preview.png", "summary.json", "params.exr"):
        with atomic_file(material / name) as tmp:
            tmp.write_text(name)
    with atomic_file(next_one / "preview.png") as tmp:  # the next material, not complete
        tmp.write_text("x")
    _files.remove_this_runs_outputs(timeout=1.0)
    _files._GUARD.release()  # the watcher would end the process here, holding it
    _files.forget_committed()
    assert sorted(p.name for p in material.iterdir()) == ["params.exr", "preview.png", "summary.json"]
    assert list(next_one.iterdir()) == []


@pytest.mark.parametrize("moment", ["before the lock is taken", "after it is taken"])
def test_the_interrupt_handler_removes_a_lock_file_made_a_moment_ago(tmp_path, monkeypatch, moment,
                                                                    handler_sees_this_test_alone):
    """The executable's Ctrl-C handler (``remove_this_runs_outputs``, then the process ends at once) while the
    run is taking its lock: the lock file it has made is removed too (CI, once: Ctrl-C as soon as the lock
    file appeared left it behind; the handler knew only the targets listed after the lock was taken)."""
    import fcntl

    from brdffit import _files

    seen = []

    def handler_runs_here():
        _files.remove_this_runs_outputs(timeout=1.0)
        seen.append(sorted(p.name for p in tmp_path.iterdir()))
        _files._GUARD.release()  # the handler would end the process here, holding it
        raise SystemExit(130)

    if moment == "before the lock is taken":
        real_flock, calls = fcntl.flock, []

        def flock(fd, op):
            calls.append(op)
            if len(calls) == 1:  # the run's own; the handler's is the second
                handler_runs_here()
            return real_flock(fd, op)

        monkeypatch.setattr(_files.fcntl, "flock", flock)
    else:
        monkeypatch.setattr(_files, "_clean_leftovers", lambda path: handler_runs_here())
    _files.forget_committed()
    with pytest.raises(SystemExit), reserve(tmp_path / "out", folder=True):
        pass
    assert seen == [[]]


def test_a_mark_of_an_earlier_command_completes_nothing_of_the_next(tmp_path, handler_sees_this_test_alone):
    """``complete_with`` belongs to the command that said it: a command that ended before its last file
    (an in-process run interrupted, a database stopped by bad input) leaves no mark that would keep the
    next command's files from an interrupt."""
    from brdffit import _files
    from brdffit._files import atomic_file

    _files.forget_committed()
    _files.complete_with(tmp_path / "params.exr")  # the earlier command never got there
    _files.forget_committed()  # the next command starts
    for name in ("preview.png", "params.exr"):
        with atomic_file(tmp_path / name) as tmp:
            tmp.write_text(name)
    _files.remove_this_runs_outputs(timeout=1.0)
    _files._GUARD.release()  # the watcher would end the process here, holding it
    _files.forget_committed()
    assert list(tmp_path.iterdir()) == []


def test_keyboard_interrupt_in_process_is_130(tmp_path, monkeypatch, capsys):
    """In-process: an interrupt during the work unwinds the temporary result."""
    import brdffit.cli.convert as convert_module
    import brdffit.io as io

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(io, "resample", interrupted)
    assert convert_module  # the command imports resample from brdffit.io at call time
    code = main(["convert", str(SAMPLE), str(tmp_path / "t.npz")])
    assert code == 130
    assert "interrupted" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_swallowed_in_a_destructor_still_stops_the_run(tmp_path, monkeypatch, capsys):
    """A signal's handler runs wherever the interpreter is; in a ``__del__`` or a garbage-collection
    callback (JAX has one) Python prints its exception and goes on. Seen in CI: the fit then ran to
    its end, wrote its result and exited 0. The interrupt must still stop the run: exit 130, no
    result, and no "Exception ignored" traceback on the terminal."""
    import brdffit.io as io

    real_resample = io.resample

    class SignalsOnCollection:
        def __del__(self):
            signal.raise_signal(signal.SIGINT)  # the handler runs here; its exception is swallowed

    def resample_hit_by_ctrl_c(*a, **k):
        SignalsOnCollection()  # collected at once
        return real_resample(*a, **k)

    monkeypatch.setattr(io, "resample", resample_hit_by_ctrl_c)
    hook_before, handler_before = sys.unraisablehook, signal.getsignal(signal.SIGINT)
    code = main(["convert", str(SAMPLE), str(tmp_path / "t.npz")])
    err = capsys.readouterr().err
    assert code == 130, err
    assert "interrupted" in err and "Exception ignored" not in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
    assert sys.unraisablehook is hook_before and signal.getsignal(signal.SIGINT) is handler_before  # both given back


def test_ctrl_c_turned_into_another_error_is_still_an_interrupt(tmp_path, monkeypatch, capsys):
    """A library may turn the interrupt's exception into its own (an extension module interrupted
    in its initialisation raises "ImportError: initialization failed", which the EXR reader reports
    as an unreadable file: seen as exit 2). After Ctrl-C any failure is the interrupt: exit 130."""
    import brdffit.io as io
    from brdffit.errors import InputError

    def resample_that_wraps_errors(*a, **k):
        try:
            signal.raise_signal(signal.SIGINT)
        except BaseException as exc:  # as OpenEXR's import did
            raise InputError(SAMPLE, f"cannot read as exr: ImportError: initialization failed ({exc!r})") from None
        raise AssertionError("the interrupt was not raised")

    monkeypatch.setattr(io, "resample", resample_that_wraps_errors)
    code = main(["convert", str(SAMPLE), str(tmp_path / "t.npz")])
    err = capsys.readouterr().err
    assert code == 130, err
    assert err.strip() == "brdffit: interrupted"
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_before_the_lock_is_taken_leaves_no_lock_file(tmp_path, monkeypatch):
    """Ctrl-C between creating the lock file and locking it (seen once in 7 interrupted fits):
    the run must still remove the file it created."""
    import fcntl

    import brdffit._files as files

    real_flock, calls = fcntl.flock, []

    def interrupted_first(fd, op):
        calls.append(op)
        if len(calls) == 1:
            raise KeyboardInterrupt  # the signal's handler ran just before the lock was taken
        return real_flock(fd, op)

    monkeypatch.setattr(files.fcntl, "flock", interrupted_first)
    with pytest.raises(KeyboardInterrupt), reserve(tmp_path / "out", folder=True):
        pass
    assert list(tmp_path.iterdir()) == []


# -- the output checked before the work ---------------------------------------------------------------
@pytest.mark.parametrize("case", ["parent_is_file", "unwritable", "folder_for_file", "file_for_folder", "exists", "cwd"])
def test_output_problems_exit_2_before_any_work(tmp_path, capsys, monkeypatch, case):
    import brdffit.fitting as fitting

    def must_not_run(*a, **k):
        raise AssertionError("the work ran before the output was checked")

    monkeypatch.setattr(fitting, "fit", must_not_run)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.exr").mkdir()
    (tmp_path / "done").mkdir()
    argv = {
        "parent_is_file": ["fit", str(SAMPLE), "--model", "lambert", "-o", str(tmp_path / "afile" / "out")],
        "unwritable": ["fit", str(SAMPLE), "--model", "lambert", "-o", "/proc/brdffit-no/out"],
        "folder_for_file": ["convert", str(SAMPLE), str(tmp_path / "adir.exr"), "--force"],
        "file_for_folder": ["fit", str(SAMPLE), "--model", "lambert", "-o", str(tmp_path / "afile"), "--force"],
        "exists": ["fit", str(SAMPLE), "--model", "lambert", "-o", str(tmp_path / "done")],
        "cwd": ["fit", str(SAMPLE), "--model", "lambert", "-o", ".", "--force"],  # never swap the folder we are in
    }[case]
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_reserve_is_reentrant_and_atomic_dir_without_force_refuses_existing(tmp_path):
    out = tmp_path / "r"
    with reserve(out, folder=True):
        with atomic_dir(out) as tmp:  # nested: shares the lock
            (tmp / "a").write_text("1")
    assert (out / "a").read_text() == "1"
    with pytest.raises(UsageError, match="already exists"):
        with atomic_dir(out):
            pass
    assert hidden(tmp_path) == []


# -- Ctrl-C before the command runs, export's output taken before its work ----------------------------
CTRL_C_IN_THE_PACKAGES_IMPORTS = r"""
import runpy, signal, sys, time

exe, sample, at = sys.argv[1], sys.argv[2], sys.argv[3]


class CtrlCDuringImport:  # Ctrl-C while `brdffit` imports its package (NumPy, ...), before any command
    def find_spec(self, name, path=None, target=None):
        if name == at:
            signal.raise_signal(signal.SIGINT)
            time.sleep(30)  # the import goes on
        return None


sys.meta_path.insert(0, CtrlCDuringImport())
sys.argv = [exe, "info", sample]
runpy.run_path(exe, run_name="__main__")  # the console script, as the shell runs it
"""


@pytest.mark.parametrize("at", ["brdffit._interrupt", "brdffit.grid"])
def test_ctrl_c_in_the_first_moments_is_one_line_and_130(tmp_path, at):
    """Ctrl-C in the executable's first 0.2 s, while its package imports: one line and 130 (it was a
    KeyboardInterrupt traceback and -2). ``brdffit._interrupt``: before the package's first lines have
    put brdffit's handler in place (the executable's own module, brdffit_main.py, answers; before it,
    under load, CI saw the traceback); ``brdffit.grid``: after."""
    exe = Path(sys.executable).with_name("brdffit")
    if not exe.exists():
        pytest.skip("needs the installed brdffit executable")
    r = subprocess.run([sys.executable, "-c", CTRL_C_IN_THE_PACKAGES_IMPORTS, str(exe), str(SAMPLE), at],
                       capture_output=True, text=True, env=ENV, timeout=120, preexec_fn=deliverable_sigint)
    assert (r.returncode, r.stderr) == (130, "brdffit: interrupted\n")
    assert r.stdout == ""


CTRL_C_AT_THE_END = r"""
import atexit, runpy, signal, sys, time

exe, sample = sys.argv[1], sys.argv[2]


def ctrl_c_while_the_process_ends():  # atexit runs it last: the interpreter's teardown has begun
    signal.raise_signal(signal.SIGINT)
    time.sleep(0.5)


atexit.register(ctrl_c_while_the_process_ends)
sys.argv = [exe, "info", sample]
runpy.run_path(exe, run_name="__main__")
"""


def test_ctrl_c_after_the_command_has_ended_changes_nothing(tmp_path):
    """A Ctrl-C once the command has said what it did (the interpreter's teardown, the Blender worker's
    shutdown) leaves its exit status and output as they are: it ended the process with -2 after
    "wrote ..." (CI, the fixed-moment .blend export at 1.6 s)."""
    exe = Path(sys.executable).with_name("brdffit")
    if not exe.exists():
        pytest.skip("needs the installed brdffit executable")
    r = subprocess.run([sys.executable, "-c", CTRL_C_AT_THE_END, str(exe), str(SAMPLE)],
                       capture_output=True, text=True, env=ENV, timeout=120, preexec_fn=deliverable_sigint)
    assert (r.returncode, r.stderr) == (0, ""), r.stderr
    assert str(SAMPLE.name) in r.stdout or "81" in r.stdout


def _export_fits(tmp_path: Path) -> tuple[Path, Path]:
    """A ggx fit.json (exported to glTF through a conversion: seconds of work) and a glTF one (none)."""
    ggx, gltf = tmp_path / "ggx", tmp_path / "gltf"
    ggx.mkdir()
    gltf.mkdir()
    (ggx / "fit.json").write_text(json.dumps({"model": "ggx", "converged": True, "loss": "log", "params": {
        "kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.3], "f0": [0.1]}}))
    (gltf / "fit.json").write_text(json.dumps({"model": "gltf:metallic_roughness", "converged": True, "params": {
        "base_color": [0.8, 0.4, 0.2], "metallic": [0.3], "roughness": [0.45]}}))
    return ggx / "fit.json", gltf / "fit.json"


def test_a_second_export_to_a_file_being_written_exits_2(tmp_path, monkeypatch, capsys):
    """Of two ``export --force`` to one file at once, one proceeds and the other exits 2 (README).
    Before, the output was locked only while the finished file was moved in place, so every run
    exited 0 (four concurrent exports: four exit 0, the last one's file kept)."""
    import brdffit.materials as materials

    ggx, gltf = _export_fits(tmp_path)
    out = tmp_path / "paint.gltf"
    real_convert, second = materials.convert, {}

    def convert_while_another_export_runs(*args, **kwargs):
        r = subprocess.run([*brdffit_cmd(), "export", str(gltf), "-o", str(out), "--force"], capture_output=True,
                           text=True, env=ENV, timeout=300)
        second.update(code=r.returncode, err=r.stderr)
        return real_convert(*args, **kwargs)

    monkeypatch.setattr(materials, "convert", convert_while_another_export_runs)
    assert main(["export", str(ggx), "--to", "gltf:metallic_roughness", "-o", str(out), "--force"]) == 0
    assert second["code"] == 2, second
    assert second["err"].count("\n") == 1 and "another brdffit run is writing it now" in second["err"]
    kept = json.loads(out.read_text())["materials"][0]["extras"]["brdffit"]
    assert kept["converted_from"]["model"] == "ggx"  # the run that proceeded wrote it
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("api", [False, True])
def test_export_takes_its_output_before_converting(tmp_path, monkeypatch, capsys, api):
    """An output that cannot be written is refused before the conversion's seconds of work (it was
    found after them)."""
    import brdffit.materials as materials
    from brdffit.fitting.result import FitResult

    def must_not_run(*a, **k):
        raise AssertionError("the conversion ran before the output was checked")

    monkeypatch.setattr(materials, "convert", must_not_run)
    ggx, _ = _export_fits(tmp_path)
    out = "/proc/brdffit-no/paint.gltf"
    if api:
        with pytest.raises(UsageError, match="cannot write here"):
            materials.export(FitResult.from_json(ggx), out, to="gltf:metallic_roughness")
        return
    assert main(["export", str(ggx), "--to", "gltf:metallic_roughness", "-o", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write here" in err and "Traceback" not in err


#: A child that sends itself Ctrl-C while a reader captures what C libraries write to descriptors 1 and 2.
CTRL_C_WHILE_NATIVE_OUTPUT_IS_CAPTURED = """
import os, signal, time
from brdffit import _interrupt
from brdffit.io._common import native_stderr_captured

_interrupt.end_process_on_interrupt()
with native_stderr_captured():
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(30)  # the read goes on: the handler ends the process
"""


def test_the_interrupt_line_is_not_lost_in_a_capture_of_native_output():
    """Seen in a stress run of test_output_safety: exit 130 with nothing on standard error, the Ctrl-C having come
    while the EXR reader captured descriptor 2 (the handler's line went into the capture, lost with the process)."""
    r = subprocess.run([sys.executable, "-c", CTRL_C_WHILE_NATIVE_OUTPUT_IS_CAPTURED], capture_output=True, text=True,
                       env=ENV, timeout=120, preexec_fn=deliverable_sigint)
    assert (r.returncode, r.stderr, r.stdout) == (130, "brdffit: interrupted\n", "")
