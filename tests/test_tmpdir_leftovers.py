"""Ctrl-C of the ``brdffit`` executable leaves nothing in the system's temporary folder (docs/cli.md#the-command-line-and-set-up):
what brdffit makes there is a scratch folder of the run (``brdffit._files.scratch_dir``), which the handler
removes; and Python's own first look at that folder (a probe file, written and removed) is made where an
interrupt waits for it."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import deliverable_sigint  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}

#: A child that sends itself Ctrl-C while tempfile's probe file exists (tempfile writes b"blat" into it
#: between making and removing it), holding the probe open for 2 s: the handler ends the process then.
PROBE_HIT_BY_CTRL_C = """
import os, signal, sys, tempfile, time
from brdffit import _interrupt

real_write = os.write

def write(fd, data):
    n = real_write(fd, data)
    if data == b"blat":  # tempfile's probe of the temporary folder, made and about to be removed
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(2)
    return n

tempfile.tempdir = None  # not looked at yet, as in a new process
os.write = write
_interrupt.end_process_on_interrupt()
tempfile.gettempdir()  # as the run's first temporary file would
time.sleep(30)  # the run goes on: the handler ends it
"""


def test_ctrl_c_during_pythons_probe_of_the_temporary_folder_leaves_nothing(tmp_path):
    """Seen in CI: a file of 8 random characters left in TMPDIR by a Ctrl-C during a ``.blend`` export.
    Python's first ``tempfile`` call of a process writes a probe file there and removes it; the handler
    ended the process in between."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    r = subprocess.run([sys.executable, "-c", PROBE_HIT_BY_CTRL_C], capture_output=True, text=True,
                       env={**ENV, "TMPDIR": str(tmp)}, timeout=120, preexec_fn=deliverable_sigint)
    assert (r.returncode, r.stderr) == (130, "brdffit: interrupted\n"), r
    assert sorted(p.name for p in tmp.iterdir()) == []


def _ctrl_c_fit_btf_once(folder: Path, tmp_path: Path, appeared, *options: str) -> None:
    """``brdffit fit-btf FOLDER`` with TMPDIR of its own, Ctrl-C as soon as ``appeared(tmp)``; it ends 130."""
    tmp, out = tmp_path / "tmp", tmp_path / "out"
    tmp.mkdir()
    p = subprocess.Popen([sys.executable, "-m", "brdffit", "fit-btf", str(folder), "-m", "lambert", "-o", str(out),
                          *options], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env={**ENV, "TMPDIR": str(tmp)}, preexec_fn=deliverable_sigint)
    deadline = time.monotonic() + 120
    while not appeared(tmp) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert p.poll() is None, "the run ended before the moment awaited"
    p.send_signal(signal.SIGINT)
    code = p.wait(timeout=60)
    err = p.stderr.read()
    assert (code, err) == (130, "brdffit: interrupted\n")
    assert sorted(str(x.relative_to(tmp)) for x in tmp.rglob("*")) == []


def test_ctrl_c_while_fit_btf_reads_leaves_no_btf_cache(full_folder, tmp_path):
    """``brdffit fit-btf`` without ``--cache-dir`` keeps the BTF's tiles in a folder of TMPDIR (a 400 x 400 BTF's
    takes 12 GB): an interrupt while it is read left it there (before: ``brdffit-btf-*`` with the cache file)."""
    _ctrl_c_fit_btf_once(full_folder, tmp_path, lambda tmp: any(tmp.glob("brdffit-btf-*")))


def test_ctrl_c_while_fit_btf_reads_into_a_cache_dir_leaves_no_part_file(full_folder, tmp_path):
    """With ``--cache-dir`` the cache is written beside its final name (``btf-*.partPID``, renamed when whole): an
    interrupt while it is read left that file (a whole BTF's size) for good, as the next run writes its own."""
    cache = tmp_path / "cache"
    _ctrl_c_fit_btf_once(full_folder, tmp_path, lambda tmp: any(cache.glob("*.part*")), "--cache-dir", str(cache))
    assert sorted(p.name for p in cache.iterdir()) == []


#: tempfile's calls that make a named entry; ``dir=`` inside a scratch folder is the caller's to remove with it.
MAKERS = {"mkdtemp", "mkstemp", "TemporaryDirectory", "NamedTemporaryFile", "SpooledTemporaryFile"}


def test_only_the_files_module_makes_entries_in_the_temporary_folder():
    """A named entry in TMPDIR made by ``tempfile`` directly is not the run's to remove on Ctrl-C (the handler
    ends the process at once: no ``with`` block or finaliser runs). So outside ``brdffit/_files.py`` such
    entries are made inside a scratch folder (``dir=``) or not at all; ``TemporaryFile`` has no name on Linux."""
    found = []
    for path in sorted((REPO / "brdffit").rglob("*.py")):
        if path.name == "_files.py" and path.parent.name == "brdffit":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call):
                name = getattr(node.func, "attr", getattr(node.func, "id", None))
                if name in MAKERS and not any(k.arg == "dir" for k in node.keywords):
                    found.append(f"{path.relative_to(REPO)}:{node.lineno} {name}")
    assert found == []


@pytest.mark.parametrize("what", ["tile", "run.json"])
def test_the_interrupt_handler_removes_a_tile_file_being_written(tmp_path, monkeypatch, what,
                                                                  handler_sees_this_test_alone):
    """The executable's Ctrl-C handler (``remove_this_runs_outputs``, then the process ends at once) while a run writes
    a tile's file or its ``run.json`` under a hidden temporary name: that file is removed too (before, it stayed in
    ``DIR/tiles`` for good: a resumed run writes its own)."""
    import numpy as np

    from brdffit import _files
    from brdffit.btf import run

    def handler_runs_here():
        _files.remove_this_runs_outputs(timeout=1.0)
        _files._GUARD.release()  # the handler would end the process here, holding it
        raise SystemExit(130)

    if what == "tile":
        real_savez = np.savez

        def savez(f, **arrays):
            real_savez(f, **arrays)
            f.flush()
            handler_runs_here()

        monkeypatch.setattr(run.np, "savez", savez)
    else:
        real_replace = os.replace
        monkeypatch.setattr(run.os, "replace", lambda a, b: handler_runs_here() if a.name.startswith(".run.json")
                            else real_replace(a, b))
    with pytest.raises(SystemExit):
        if what == "tile":
            run.save_tile(tmp_path, 3, {"loss": np.zeros((4, 4))})
        else:
            run.write_run(tmp_path, {"model": "lambert"})
    assert sorted(p.name for p in tmp_path.iterdir()) == []

