"""Re-run mutmut's survivors against every test file of their package, one process per mutant.

Why: mutmut 3 runs, for each mutant, only the tests during which the mutated function ran in its
stats pass. Code that runs at import time (e.g. ``lafortune.lobe_params`` building a parameter
table) runs during the collection of the first test module, so mutmut credits it to one or two
tests and never tries the tests that check that table. Here each survivor gets a fresh interpreter
with the mutant active from the first import, and the package's test files run, with its module's (below: tests mutmut leaves out, e.g. subprocesses).

Mutants that ran past mutmut's CPU-time limit are rechecked too (with a wall-clock limit,
RECHECK_TIMEOUT seconds, default 900: a fresh process compiles its JAX programs anew, which can
exceed a limit derived from warm test timings; past it the mutant counts as a timeout, i.e.
detected). So are mutants mutmut ran no test for ("no tests": code whose tests mutmut's
configuration leaves out, e.g. hdr.py before it had its own fast test file), against the test
files named on the command line.
Kills are written to ``mutants/recheck.json`` (name -> "killed" or "survived"), which
scripts/mutation_report.py reads; mutmut's own result files are left alone.
Usage (from the repository root, after ``mutmut run``):
    python scripts/mutation_recheck.py GLOB... [tests/FILE.py ...]   (named test files replace the package's)
"""

from __future__ import annotations

import fnmatch
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from mutation_report import KILLED, NO_TESTS, SURVIVED, TIMEOUT, load_results  # noqa: E402

TESTS_BY_PACKAGE = {
    "brdffit.models": ["tests/test_models_*.py"],
    "brdffit.io": ["tests/test_io_*.py", "tests/test_malformed.py"],
    "brdffit.fitting": ["tests/test_fit_core.py", "tests/test_fit_status.py", "tests/test_parameter_space.py"],
}
# Modules whose tests mutmut's configuration leaves out (they run the CLI, render, or start
# subprocesses) or that have their own files: these are added to the package's.
TESTS_BY_MODULE = {
    "brdffit.fitting.lanes": ["tests/test_fit_batch_options.py", "tests/test_fit_claims.py"],
    "brdffit.fitting.stages": ["tests/test_program_cache.py", "tests/test_solver.py", "tests/test_fit_claims.py"],
    "brdffit.fitting.driver": ["tests/test_fit_batch_options.py", "tests/test_fit_status.py", "tests/test_multistart.py",
                               "tests/test_fit_claims.py"],
    "brdffit.fitting.measurements": ["tests/test_fit_batch_options.py", "tests/test_fit_status.py",
                                     "tests/test_fit_claims.py"],
    "brdffit.fitting.options": ["tests/test_fit_batch_options.py", "tests/test_cli_defaults.py"],
    "brdffit.fitting.cache": ["tests/test_program_cache_keys.py", "tests/test_program_cache.py"],
    "brdffit.fitting.compare": ["tests/test_compare_report.py", "tests/test_surfaces.py"],
    "brdffit.fitting.fitfile": ["tests/test_fit_result_doc.py", "tests/test_fitfile_bounds.py", "tests/test_reliability.py"],
    "brdffit.fitting.init": ["tests/test_init_axis.py", "tests/test_multistart.py", "tests/test_solver.py"],
    "brdffit.fitting.problem": ["tests/test_fit_result_doc.py", "tests/test_prepare_*.py"],
    "brdffit.fitting.result": ["tests/test_fit_result_doc.py", "tests/test_fitfile_bounds.py", "tests/test_surfaces.py"],
    "brdffit.fitting.solve": ["tests/test_solver.py", "tests/test_multistart.py"],
    "brdffit.fitting.solver_lm": ["tests/test_solver.py", "tests/test_multistart.py"],
    "brdffit.fitting.solver_optx": ["tests/test_solver.py", "tests/test_parameter_space.py"],
    "brdffit.fitting.solver_scipy": ["tests/test_solver.py", "tests/test_fit_status.py"],
    "brdffit.fitting.objective": ["tests/test_structure.py", "tests/test_losses_values.py", "tests/test_multistart.py"],
}
RECHECK = Path("mutants/recheck.json")


def test_files(name: str) -> list[str]:
    pkg = ".".join(name.split(".")[:2])
    module = name.rsplit(".", 1)[0]
    files = []
    for pattern in TESTS_BY_MODULE.get(module, []) + TESTS_BY_PACKAGE[pkg]:
        files += sorted(str(p) for p in Path("mutants").glob(pattern))
    return [f.removeprefix("mutants/") for f in files]


def main(argv: list[str]) -> int:
    globs = [a for a in argv if not a.startswith("tests/")]
    only = [a for a in argv if a.startswith("tests/")]  # test files named: those instead of the package's
    shutil.copytree("tests", "mutants/tests", dirs_exist_ok=True)  # the tests as they are now
    done = json.loads(RECHECK.read_text()) if RECHECK.exists() else {}
    todo = [n for n, s in load_results(Path(".")).items()
            if s in (SURVIVED, TIMEOUT, NO_TESTS) and done.get(n) not in (KILLED, TIMEOUT)
            and any(fnmatch.fnmatch(n, g) for g in globs)]
    clean_runs = set()
    for name in todo:
        files = only or test_files(name)
        if tuple(files) not in clean_runs:  # a test failing without any mutant would "kill" every one
            clean = _pytest("", files)
            if clean is None:
                print(f"the tests {' '.join(files)} ran past RECHECK_TIMEOUT without a mutant; nothing "
                      "rechecked (raise RECHECK_TIMEOUT or name fewer test files)", file=sys.stderr)
                return 1
            if clean.returncode != 0:
                print(f"the tests {' '.join(files)} fail without a mutant; nothing rechecked", file=sys.stderr)
                return 1
            clean_runs.add(tuple(files))
        r = _pytest(name, files)
        done[name] = TIMEOUT if r is None else KILLED if _detected(r) else SURVIVED
        print(f"{done[name]:<9} {name}", flush=True)
        RECHECK.write_text(json.dumps(done, indent=1))
    return 0


def _detected(r: subprocess.CompletedProcess) -> bool:
    """A test failed (exit 1), or the mutated code raised while the test modules were imported
    (pytest exits 2, "error during collection": e.g. a parameter table that no longer builds; mutmut
    itself sees such a child die, exit 255, and calls it a timeout)."""
    return r.returncode == 1 or (r.returncode == 2 and " during collection" in r.stdout)


def mutant_env(mutant: str) -> dict[str, str]:
    """The environment a mutant's tests run in: without the shared data, and without brdffit's disk
    cache of compiled programs (it keys them by the source, one file for every mutant here, so a
    mutant would load another's program: see scripts/mutation_run.sh); JAX's own cache, keyed by
    the compiled code, in mutants/.jax-cache."""
    return {**os.environ, "MUTANT_UNDER_TEST": mutant, "BRDFFIT_DATA": "/nonexistent", "PY_IGNORE_IMPORTMISMATCH": "1",
            "BRDFFIT_CACHE": "off", "JAX_COMPILATION_CACHE_DIR": str(Path("mutants/.jax-cache").resolve()),
            "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0", "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0"}


def _pytest(mutant: str, files: list[str]) -> subprocess.CompletedProcess | None:
    """The test files' run with ``mutant`` active (None: past RECHECK_TIMEOUT, e.g. an endless loop)."""
    env = mutant_env(mutant)
    env.pop("PYTHONPATH", None)  # the mutated copy in mutants/ must be what the tests import
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m", "not slow", *files]
    try:
        return subprocess.run(cmd, cwd="mutants", env=env, capture_output=True, text=True,
                              timeout=float(os.environ.get("RECHECK_TIMEOUT", 900)))
    except subprocess.TimeoutExpired:
        return None


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
