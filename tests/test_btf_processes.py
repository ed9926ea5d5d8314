"""``fit_btf`` in worker processes of one core each (docs/btf.md#at-scale, ``brdffit.btf.processes``):
the maps of a run in one process, workers confined to a core each, resuming, a worker that dies and
an error of the input in a worker as one error of the run, Ctrl-C of the command."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.btf import generate as gen
from brdffit.btf import processes

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from conftest import deliverable_sigint  # noqa: E402

pytestmark = pytest.mark.skipif(len(processes.cores()) < 2,
                                reason="worker processes need a system with two cores a process can be confined to")


@pytest.fixture(scope="module")
def ggx_btf(tmp_path_factory):
    """16 x 16 texels of ggx in 16 tiles of 4 x 4 (its tile cache written straight)."""
    model = brdffit.models.get("ggx")
    truth = gen.smooth_maps(model, 16, 16, seed=5)
    return gen.model_btf(model, truth, tmp_path_factory.mktemp("btf"), noise=0.01, seed=6, tile=4, name="ggx16")


@pytest.fixture(scope="module")
def one_process(ggx_btf):
    return brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=1)


def _cpus_allowed(pid: int) -> str:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("Cpus_allowed_list:"):
            return line.split(":", 1)[1].strip()
    raise AssertionError(f"no Cpus_allowed_list for {pid}")


def _assert_same_maps(a, b):
    """Equal to rounding: XLA may split a sum over its thread pool (a worker's has one thread), so the last
    bit of a texel's loss or parameters can differ (seen: 4e-16 relative); the same steps and statuses."""
    for k in a.params:
        np.testing.assert_allclose(a.params[k], b.params[k], rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.loss, b.loss, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(a.converged, b.converged)
    np.testing.assert_array_equal(a.steps, b.steps)


def test_workers_confined_to_a_core_each_give_the_maps_of_one_process(ggx_btf, one_process):
    maps = brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2)
    _assert_same_maps(maps, one_process)
    assert maps.converged.all() and maps.info["worker_processes"] == 2 and one_process.info["worker_processes"] is None
    pids = processes.worker_pids()
    assert len(pids) == 2 and os.getpid() not in pids
    assert sorted(_cpus_allowed(p) for p in pids) == [str(c) for c in processes.cores()[:2]]


def test_two_threads_runs_at_once_share_the_workers_in_turn(ggx_btf, one_process):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        runs = [pool.submit(brdffit.fit_btf, ggx_btf, "ggx", progress=False, processes=2) for _ in range(2)]
        maps = [run.result(timeout=300) for run in runs]
    for m in maps:
        _assert_same_maps(m, one_process)
    for k in maps[0].params:  # runs in workers equal each other to the bit
        np.testing.assert_array_equal(maps[0].params[k], maps[1].params[k])
    np.testing.assert_array_equal(maps[0].loss, maps[1].loss)


def test_a_run_in_workers_resumes_from_its_tile_files(ggx_btf, one_process, tmp_path):
    out = tmp_path / "run"
    assert brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2, out=out, max_tiles=5) is None
    assert len(list((out / "tiles").glob("tile_*.npz"))) == 5
    maps = brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2, out=out)
    assert maps.info["resumed_tiles"] == 5
    _assert_same_maps(maps, one_process)
    assert (out / "params.exr").is_file() and not (out / "tiles").exists()


def test_a_dead_worker_is_one_error_and_the_next_run_starts_new_ones(ggx_btf, one_process, tmp_path):
    brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2)
    dead = processes.worker_pids()[0]
    os.kill(dead, signal.SIGKILL)
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match=r"the worker process on core \d+ ended \(exit status -9\)"):
        brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2, out=out)
    assert processes.worker_pids() == []  # the pool was ended with the run, its other worker too
    assert not (out / "params.exr").exists()
    maps = brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2, out=out)  # resumed, new workers
    _assert_same_maps(maps, one_process)
    assert dead not in processes.worker_pids()


def test_an_input_error_in_a_worker_is_the_run_s_input_error(tmp_path):
    model = brdffit.models.get("lambert")
    btf = gen.model_btf(model, gen.smooth_maps(model, 8, 8, seed=1), tmp_path, noise=0.0, seed=2, tile=4, name="l8")
    with open(btf.cache, "r+b") as f:  # the last tile cut short
        f.truncate(btf.cache.stat().st_size - 100)
    errors = []
    for n in (1, 2):
        with pytest.raises(brdffit.InputError) as info:
            brdffit.fit_btf(btf, "lambert", progress=False, processes=n)
        errors.append(str(info.value))
    assert errors[0] == errors[1] == f"{btf.cache}: truncated cache file (tile 3)"


def test_the_default_starts_no_more_workers_than_memory_has_room_for(monkeypatch):
    many = 10**6  # texels and tiles enough for a worker per core
    monkeypatch.setattr(processes, "available_memory", lambda: None)
    assert processes.count(None, many, many) == len(processes.cores())
    monkeypatch.setattr(processes, "available_memory", lambda: int(2.5 * processes.WORKER_BYTES))
    assert processes.count(None, many, many) == 2
    monkeypatch.setattr(processes, "available_memory", lambda: int(1.5 * processes.WORKER_BYTES))
    assert processes.count(None, many, many) == 1  # room for one: the run's own process fits
    assert processes.count(2, many, many) == 2  # asked for: as asked
    assert processes.count(None, many, processes.AUTO_MIN_TEXELS - 1) == 1


def test_processes_is_checked(ggx_btf):
    for bad in (0, -1, 1.5, True):
        with pytest.raises(brdffit.UsageError, match="processes must be a whole number"):
            brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=bad)
    with pytest.raises(brdffit.UsageError, match="without a Dask client"):
        brdffit.fit_btf(ggx_btf, "ggx", progress=False, processes=2, client=object())


def _children(pid: int) -> set[int]:
    kids = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.add(int(entry.name))
    return kids


# preexec_fn makes subprocess fork; the child only resets its SIGINT handling, then execs
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_ctrl_c_of_the_command_ends_its_workers_without_a_word_from_them(ggx_btf, tmp_path):
    """SIGINT to the command's whole process group, as a terminal sends it: one line, 130, the workers
    gone, no tile run's leftovers beyond resumable tile files."""
    out = tmp_path / "out"
    exe = Path(sys.executable).with_name("brdffit")
    src = tmp_path / "btf"
    model = brdffit.models.get("ggx")
    gen.write_model_btf(src, model, gen.smooth_maps(model, 16, 16, seed=5), noise=0.01, seed=6)
    args = [*([str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]),
            "fit-btf", str(src), "--model", "ggx", "--tile", "4", "--processes", "2", "-o", str(out)]
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                         preexec_fn=deliverable_sigint, start_new_session=True)
    deadline = time.monotonic() + 300
    workers: set[int] = set()
    while p.poll() is None and time.monotonic() < deadline and not list((out / "tiles").glob("tile_*.npz")):
        workers |= {k for k in _children(p.pid)}
        time.sleep(0.02)
    assert p.poll() is None, p.stderr.read()
    workers |= _children(p.pid)
    assert len(workers) >= 2
    os.killpg(p.pid, signal.SIGINT)
    assert p.wait(timeout=120) == 130
    err = p.stderr.read()
    assert "interrupted" in err and "Traceback" not in err, err
    for pid in workers:  # ended, not orphaned
        assert not Path(f"/proc/{pid}").exists() or "Z" in (Path(f"/proc/{pid}/stat").read_text().split()[2])
    assert not (out / "params.exr").exists()
