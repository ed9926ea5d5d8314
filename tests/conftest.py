"""Shared fixtures. Real measurements come from $BRDFFIT_DATA when it is set (and only from there:
``BRDFFIT_DATA=/nonexistent`` runs the suite as without the data, to check that nothing relies on
them), else from ../shared/data; tests that need them skip with a reason when they are absent."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def data_dir() -> Path | None:
    env = os.environ.get("BRDFFIT_DATA")
    candidates = [Path(env)] if env else [REPO.parent / "shared" / "data"]
    for c in candidates:
        if (c / "measured").is_dir():
            return c
    return None


def _files(sub: str, pattern: str) -> list[Path]:
    d = data_dir()
    return sorted((d / "measured" / sub).glob(pattern)) if d else []


RGL_FILES = _files("rgl", "*.bsdf")
CORNELL_FILES = _files("cornell", "*.brdf")
NO_DATA = "real measurements not found: set BRDFFIT_DATA or place them in ../shared/data"


def rgl_params():
    return [pytest.param(p, id=p.stem) for p in RGL_FILES] or [pytest.param(None, marks=pytest.mark.skip(reason=NO_DATA))]


def cornell_params():
    return [pytest.param(p, id=p.stem) for p in CORNELL_FILES] or [
        pytest.param(None, marks=pytest.mark.skip(reason=NO_DATA))
    ]


@pytest.fixture(scope="module")
def full_folder(tmp_path_factory):
    """A complete UBO-81 image folder of 1x1 grey PNGs (the malformed-input tests break one image
    of it at a time and restore it)."""
    import numpy as np
    from PIL import Image

    from brdffit.io.images import direction_name

    root = tmp_path_factory.mktemp("full") / "btf"
    root.mkdir()
    img = Image.fromarray(np.full((1, 1, 3), 128, np.uint8))
    for i in range(81):
        for j in range(81):
            img.save(root / f"{direction_name(i, j)}.png")
    return root


def deliverable_sigint() -> None:
    """``preexec_fn`` of a child that a test sends Ctrl-C: a terminal's default SIGINT disposition. A test
    runner's worker (pytest-xdist) may run with SIGINT ignored or blocked, which a child inherits."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupted_before_brdffit_ran(code: int, err: str) -> bool:
    """A Ctrl-C that reached the ``brdffit`` executable during the interpreter's own start-up, before
    any of brdffit's code (``brdffit_main``) ran. Python then dies of the signal (-2, at most with a
    traceback of the console script's import line) or exits 1 ("Fatal Python error" while importing
    ``site``, or a bare ``KeyboardInterrupt``); some moments it swallows the signal and runs on (exit 0,
    the command's whole result). Only the interpreter ran, so only "nothing written" can be asked of
    it; a loaded machine stretches this window past 0.1 s. Output naming a file of brdffit's own (or
    brdffit's one line) is not this case."""
    package = Path(__file__).resolve().parents[1] / "brdffit"
    ours = "brdffit: " in err or 'brdffit_main.py"' in err or f"{package}{os.sep}" in err
    return code in (-2, 1) and (err == "" or err.rstrip().endswith("KeyboardInterrupt")) and not ours


@pytest.fixture
def handler_sees_this_test_alone(monkeypatch):
    """The executable's Ctrl-C handler (``_files.remove_this_runs_outputs``), called in this test process, sees only
    what the test lists itself: it kills every helper process and removes every scratch folder and result this
    process listed, so a BTF's worker processes kept by a test that ran before in this process died with it (the
    next run in them failed: "the worker process on core 0 ended (exit status -9)")."""
    from brdffit import _files

    for name, empty in (("_RESERVED", set()), ("_LOCKS", {}), ("_COMMITTED", []), ("_COMPLETING", set()),
                        ("_SCRATCH", []), ("_PROCESSES", [])):
        monkeypatch.setattr(_files, name, empty)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    d = data_dir()
    if d is None:
        pytest.skip(NO_DATA)
    return d


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The malformed-input corpus tally (tests/test_malformed_corpus.py), shown even with -q."""
    tally = getattr(config, "brdffit_corpus_tally", None)
    if tally:
        cases, passed, runs = tally
        terminalreporter.write_line(f"malformed-input corpus: {passed}/{cases} cases passed ({runs} CLI runs)")


@pytest.fixture(scope="session")
def blender():
    """``brdffit.cycles`` where a Blender environment is there (``make test`` creates .venv-blender);
    else the test is skipped with the one line that says what is missing."""
    from brdffit import cycles

    missing = cycles.available()
    if missing:
        pytest.skip(f"needs Blender (bpy 5.0 in .venv-blender): {missing}")
    return cycles


@pytest.fixture(scope="module", autouse=True)
def _let_go_of_compiled_programs():
    """After each test file, the compiled programs it loaded are let go: a loaded XLA program holds
    about 300 memory mappings, a process may have 65 530 (vm.max_map_count), and a worker runs a
    third of the suite (brdffit keeps at most ``fitting.cache.MAX_LOADED`` of its own; JAX's jit
    caches keep theirs until cleared). The next file loads what it needs from the disk caches."""
    yield
    import gc
    import sys

    jax = sys.modules.get("jax")
    if jax is not None:
        jax.clear_caches()
    cache = sys.modules.get("brdffit.fitting.cache")
    if cache is not None:
        cache._CACHE.clear()
    gc.collect()
