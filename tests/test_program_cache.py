"""The disk cache of compiled fit programs (brdffit.fitting.cache, docs/fitting.md#fitting), in new processes: a
second process loads the program ready-compiled (no tracing, no lowering, no scipy.linalg), and a
program that JAX's own cache handed back is never kept (serialised again, it lacks its machine code
and the next process would fail with "Function ... not found"): it is compiled afresh and kept."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

FIT = f"""
import json, sys
import jax
lowered = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: lowered.append(kw.get("fun_name", "?"))
    if event == "/jax/core/compile/jaxpr_to_mlir_module_duration" else None)
import brdffit
r = brdffit.fit(brdffit.load({str(REPO / 'data' / 'sample_ubo81.exr')!r}), "ggx", max_steps=int(sys.argv[1]))
print(json.dumps({{"loss": r.loss_value, "status": r.status, "lowered": lowered,
                  "scipy_linalg": "scipy.linalg" in sys.modules}}))
"""


def _fit(cache: Path, max_steps: int = 100) -> dict:
    run = subprocess.run([sys.executable, "-c", FIT, str(max_steps)], capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, BRDFFIT_CACHE=str(cache)))
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_second_process_loads_the_fit_program_without_lowering_or_scipy(tmp_path):
    first, second = _fit(tmp_path), _fit(tmp_path)
    assert first["lowered"], "the first process compiles (the cache folder was empty)"
    assert second["lowered"] == [] and not second["scipy_linalg"], second
    assert second["loss"] == first["loss"] and second["status"] == "converged"


def test_a_program_from_jax_own_cache_is_compiled_again_before_it_is_kept(tmp_path):
    """Our file gone, JAX's entry kept: the next process's compile is answered from JAX's cache, and
    that executable, serialised again, would lack its machine code. It compiles afresh instead and
    keeps that one: the process after it loads it (nothing lowered) and reaches the same loss."""
    first = _fit(tmp_path, 77)
    kept = sorted(p.name for p in (tmp_path / "brdffit-programs").iterdir())  # a fit's stages: start, solve, finish
    shutil.rmtree(tmp_path / "brdffit-programs")  # JAX's entries stay: the next compiles are JAX cache hits
    again = _fit(tmp_path, 77)
    assert sorted(p.name for p in (tmp_path / "brdffit-programs").iterdir()) == kept
    third = _fit(tmp_path, 77)
    assert third["lowered"] == [], third
    assert first["loss"] == again["loss"] == third["loss"] and third["status"] == "converged"


CLI_FIT = f"""
import json, sys
import jax
lowered = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: lowered.append(kw.get("fun_name", "?"))
    if event == "/jax/core/compile/jaxpr_to_mlir_module_duration" else None)
from brdffit.cli import main
code = main(["fit", {str(REPO / 'data' / 'sample_ubo81.exr')!r}, "--model", "ggx", "-o", sys.argv[1], "--force"])
print(json.dumps({{"code": code, "lowered": lowered,
                  "unneeded": sorted({{"equinox", "jaxtyping", "matplotlib"}} & set(sys.modules))}}))
"""


def test_a_second_brdffit_fit_lowers_nothing_for_the_fit_or_its_figure(tmp_path):
    """``brdffit fit`` in a second process: the fit, ``FitResult.eval`` of the fitted table and the
    figure's log residual all come compiled from the disk cache (each program traced and lowered
    costs ~0.1-0.2 s of a command whose target is 2.5 s), and neither equinox (~0.2 s; a fit that
    is loaded, not compiled, needs no optimistix), jaxtyping (~45 ms; annotations only) nor
    matplotlib (~0.7 s; the figure's worker process draws fit.png) is imported."""
    env = dict(os.environ, BRDFFIT_CACHE=str(tmp_path / "cache"))
    runs = []
    for _ in range(2):
        run = subprocess.run([sys.executable, "-c", CLI_FIT, str(tmp_path / "out")], capture_output=True, text=True,
                             timeout=600, env=env)
        assert run.returncode == 0, run.stderr[-3000:]
        runs.append(json.loads(run.stdout.strip().splitlines()[-1]))
    first, second = runs
    assert first["code"] == second["code"] == 0 and (tmp_path / "out" / "fit.png").stat().st_size > 0
    assert first["lowered"], "the first process compiles (the cache folder was empty)"
    assert second["lowered"] == [] and second["unneeded"] == [], second


def test_the_machine_key_names_the_cpu_flags_without_asking_platform(monkeypatch):
    """The disk cache's machine key holds /proc/cpuinfo's flags line (a program compiled for
    AVX-512 is not handed to a CPU without it); where that file exists, platform.processor()
    (which runs ``uname -p`` in a subprocess on Linux) is not consulted."""
    import platform

    from brdffit.fitting import cache

    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            flags = next(line for line in fh if line.startswith(("flags", "Features")))
    except (OSError, StopIteration):
        import pytest

        pytest.skip("no /proc/cpuinfo flags line on this machine")
    asked = []
    monkeypatch.setattr(platform, "processor", lambda: asked.append(1) or "asked")
    monkeypatch.delitem(cache._STATE, "machine", raising=False)
    key = cache._machine()
    assert flags.strip() in key and asked == []


def test_a_program_is_kept_per_xla_flags(tmp_path, monkeypatch):
    """XLA_FLAGS change the code XLA generates (fast math, instruction sets): a program compiled
    under other flags is not loaded; each setting gets its own file."""
    import numpy as np

    from brdffit.fitting import cache

    monkeypatch.setitem(cache._STATE, "dir", tmp_path)
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    example = (np.arange(3.0),)
    for flags in (None, "--xla_cpu_enable_fast_math=false", None):
        if flags is not None:
            monkeypatch.setenv("XLA_FLAGS", flags)
        else:
            monkeypatch.delenv("XLA_FLAGS", raising=False)
        program = cache.load_or_compile(("xla_flags_test",), lambda: (lambda x: 2.0 * x + 1.0), example)
        np.testing.assert_allclose(program(*example), [1.0, 3.0, 5.0])
    assert len(list((tmp_path / "brdffit-programs").glob("*.bin"))) == 2


def test_a_run_loads_ahead_the_programs_its_kind_used_last_time(tmp_path, monkeypatch):
    """``cache.ahead(kind)``: a block records the programs it used; the next block of that kind (here, after
    the process's own programs are let go, as in a new process) has them loaded by its thread, so that
    asking for one loads nothing more; and a program this process holds already is not loaded again. (One asked
    for before the thread reached it is loaded at once, as without a block.)"""
    import numpy as np

    import concurrent.futures

    from brdffit.fitting import cache

    monkeypatch.setitem(cache._STATE, "dir", tmp_path)
    monkeypatch.setattr(cache, "_CACHE", type(cache._CACHE)())
    example = (np.arange(3.0),)
    programs = [(("ahead_test", k), (lambda k: lambda: (lambda x: k * x + 1.0))(k)) for k in (2.0, 3.0)]
    with cache.ahead("test kind"):
        for key, build in programs:
            cache.compiled(key, build, *example)
    assert len(list((tmp_path / "brdffit-programs").glob("ahead-*.json"))) == 1

    monkeypatch.setattr(cache, "_CACHE", type(cache._CACHE)())  # as a new process: nothing loaded

    def refuse(*args):
        raise AssertionError("loaded on demand, not ahead")

    monkeypatch.setattr(cache, "load_or_compile", refuse)
    loads = []
    real_load = cache._load
    monkeypatch.setattr(cache, "_load", lambda *a: loads.append(a[1].name) or real_load(*a))
    with cache.ahead("test kind"):
        concurrent.futures.wait(list(cache._AHEAD.values()), timeout=120)  # the run's first work meanwhile
        for (key, build), k in zip(programs, (2.0, 3.0)):
            fn, _ = cache.compiled(key, build, *example)
            np.testing.assert_allclose(fn(*example), k * example[0] + 1.0)
    assert len(loads) == 2
    with cache.ahead("test kind"):  # both held in this process now: none is loaded again
        pass
    with cache.ahead("another kind"):  # nothing recorded for it
        pass
    assert len(loads) == 2


def test_programs_on_disk_are_pruned_least_recently_used_first(tmp_path, monkeypatch):
    """Past ``PROGRAMS_MAX_BYTES`` the programs least recently written or loaded go first; the one
    just written stays (every brdffit version keys its own programs: without a limit they pile up)."""
    import numpy as np

    from brdffit.fitting import cache

    monkeypatch.setitem(cache._STATE, "dir", tmp_path)
    folder = tmp_path / "brdffit-programs"
    example = (np.arange(3.0),)
    files = {}
    for name, scale in (("a", 2.0), ("b", 3.0)):
        before = set(folder.glob("*.bin"))
        cache.load_or_compile((f"prune_test_{name}",), lambda s=scale: (lambda x: s * x), example)
        (files[name],) = set(folder.glob("*.bin")) - before
    os.utime(files["a"], (1_000_000, 1_000_000))  # a written long before b ...
    os.utime(files["b"], (2_000_000, 2_000_000))
    program = cache.load_or_compile(("prune_test_a",), lambda: (lambda x: 2.0 * x), example)  # ... and loaded now
    np.testing.assert_allclose(program(*example), [0.0, 2.0, 4.0])
    monkeypatch.setattr(cache, "PROGRAMS_MAX_BYTES", files["a"].stat().st_size + files["b"].stat().st_size + 1024)
    before = set(folder.glob("*.bin"))
    cache.load_or_compile(("prune_test_c",), lambda: (lambda x: 5.0 * x), example)
    (c,) = set(folder.glob("*.bin")) - before
    assert sorted(folder.glob("*.bin")) == sorted([files["a"], c])


def test_prune_stops_at_the_limit_and_never_deletes_the_program_just_written(tmp_path, monkeypatch):
    """Files of known sizes and use times: the oldest go until the rest fit the limit exactly; the
    one just written stays even when it is the oldest; other files are not programs."""
    from brdffit.fitting import cache

    for name, when in (("x", 1), ("y", 2), ("z", 3), ("kept", 0)):
        p = tmp_path / f"{name}.bin"
        p.write_bytes(b"\0" * 100)
        os.utime(p, (when, when))
    (tmp_path / "notes.txt").write_bytes(b"\0" * 1000)
    monkeypatch.setattr(cache, "PROGRAMS_MAX_BYTES", 300)
    cache._prune(tmp_path, keep=tmp_path / "kept.bin")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.bin", "notes.txt", "y.bin", "z.bin"]


def test_a_vector_width_in_xla_flags_rules_and_keys_its_own_programs(tmp_path):
    """brdffit's 512-bit vectors (cache.compiler_options, where the CPU has AVX-512) give way to a width the
    user sets in XLA_FLAGS; a program kept under one is not loaded under the other (it is compiled)."""
    probe = "from brdffit.fitting import cache; import json; print(json.dumps(cache.compiler_options()))"

    def options(flags):
        env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"} | ({"XLA_FLAGS": flags} if flags else {})
        run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, env=env)
        assert run.returncode == 0, run.stderr[-2000:]
        return json.loads(run.stdout.strip().splitlines()[-1])

    avx512 = " avx512f " in f" {Path('/proc/cpuinfo').read_text()} ".replace("\n", " ") \
        if Path("/proc/cpuinfo").exists() else False
    assert options(None) == ({"xla_cpu_prefer_vector_width": 512} if avx512 else {})
    assert options("--xla_cpu_prefer_vector_width=256") == {}
    first = _fit(tmp_path)
    env = dict(os.environ, XLA_FLAGS="--xla_cpu_prefer_vector_width=256")
    run = subprocess.run([sys.executable, "-c", FIT, "100"], capture_output=True, text=True, timeout=600,
                         env=dict(env, BRDFFIT_CACHE=str(tmp_path)))
    assert run.returncode == 0, run.stderr[-3000:]
    other = json.loads(run.stdout.strip().splitlines()[-1])
    assert other["lowered"], "a program kept under other options was loaded"
    assert abs(other["loss"] - first["loss"]) <= 1e-12 * first["loss"]
