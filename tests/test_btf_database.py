"""A database in one command (docs/btf.md#at-scale, 10): ``brdffit fit-btf DIR`` where DIR holds several
BTFs (folders and zips) fits each into OUT/<name>/, with one progress bar over all texels, a summary
table (printed, CSV and JSON), resuming across materials (an interrupt, Ctrl-C included, keeps the
finished materials), and bad input named in one line before any work."""

from __future__ import annotations

import contextlib
import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.btf import database as btf_database
from brdffit.btf import generate as gen
from brdffit.btf import tile as btf_tile
from brdffit.cli import main

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from conftest import deliverable_sigint  # noqa: E402

#: material -> (rows, columns) of texels; with --tile 4: 1, 4 and 2 tiles
SIZES = {"cork": (4, 4), "felt": (8, 8), "wool": (4, 8)}


@pytest.fixture(scope="module")
def database(tmp_path_factory):
    """cork/ (per-view folders, EXR), felt/ (flat, EXR), wool.zip (PNG named with spaces, as the
    Bonn archives), and a README.txt that is not a BTF."""
    root = tmp_path_factory.mktemp("db") / "materials"
    root.mkdir()
    for seed, (name, (h, w)) in enumerate(SIZES.items()):
        maps = gen.smooth_maps("lambert", h, w, seed=seed)
        if name == "wool":
            gen.write_model_btf(root / "wool.zip", "lambert", maps, format="png", spaces=True, archive=True, seed=seed)
        else:
            gen.write_model_btf(root / name, "lambert", maps, noise=0.01, per_view=name == "cork", seed=seed)
    (root / "README.txt").write_text("three materials\n")
    return root


@pytest.fixture(scope="module")
def singles(database):
    """Each material fitted on its own by fit_btf: what the database run must give."""
    sources = {"cork": database / "cork", "felt": database / "felt", "wool": database / "wool.zip"}
    return {name: brdffit.fit_btf(brdffit.load_btf(src, tile=4), "lambert", progress=False)
            for name, src in sources.items()}


def _assert_written_maps(folder: Path, single) -> None:
    back = brdffit.ParameterMaps.load(folder / "params.exr")
    np.testing.assert_array_equal(back.params["kd"], single.params["kd"].astype(np.float32))
    np.testing.assert_array_equal(back.loss, single.loss.astype(np.float32))


def test_the_command_fits_every_material_and_writes_the_summary(database, singles, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    args = ["fit-btf", str(database), "--model", "lambert", "--tile", "4", "-o", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].split() == ["material", "texels", "texels/s", "median", "loss", "converged"]
    assert [line.split()[0] for line in printed[1:]] == ["cork", "felt", "wool"]
    for name, single in singles.items():
        _assert_written_maps(out / name, single)
        assert not (out / name / "tiles").exists()
    with open(out / "summary.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["material"] for r in rows] == ["cork", "felt", "wool"]
    for r in rows:
        single = singles[r["material"]]
        assert int(r["texels"]) == np.prod(SIZES[r["material"]])
        assert float(r["median_loss"]) == float(np.median(single.loss))  # median of the float64 loss map
        assert float(r["converged_share"]) == single.converged.mean()
        assert float(r["texels_per_second"]) > 0 and r["status"] == "fitted"
    assert json.loads((out / "summary.json").read_text())["materials"][1]["material"] == "felt"
    # run again: every material is finished, nothing is fitted
    monkeypatch.setattr(btf_tile, "fit_tiles", lambda *a, **k: pytest.fail("a finished material was fitted again"))
    assert main(args) == 0
    assert {r["status"] for r in json.loads((out / "summary.json").read_text())["materials"]} == {"done before"}
    # another model into the same folder: refused, nothing touched
    assert main([*args[:3], "ggx", *args[4:]]) == 2
    assert "holds a database run of another model or options" in capsys.readouterr().err


class _Bar:
    """Stands in for brdffit's progress bar: records what the run tells it."""

    def __init__(self, total):
        self.total, self.advanced, self.skipped = total, 0, 0

    def advance(self, n=1):
        self.advanced += n

    def skip(self, n):
        self.skipped += n

    def describe(self, text):
        pass


def _recording(bars: list):
    @contextlib.contextmanager
    def progress_bar(label, total, **kwargs):
        bars.append(_Bar(total))
        yield bars[-1]

    return progress_bar


def test_an_interrupted_run_resumes_the_unfinished_material_with_one_bar(database, singles, tmp_path, monkeypatch):
    bars: list = []
    monkeypatch.setattr(btf_database, "progress_bar", _recording(bars))
    monkeypatch.setitem(btf_tile.GROUP_TEXELS, "cpu", 16)  # a group of one 4 x 4 tile: the unit of a resume
    real = btf_tile.fit_tiles
    calls = []

    def interrupted(b, tiles, *args, **kwargs):
        if len(calls) == 2:  # cork's one tile and felt's first are done
            raise KeyboardInterrupt
        calls.extend((b.name, t) for t in tiles)
        return real(b, tiles, *args, **kwargs)

    monkeypatch.setattr(btf_tile, "fit_tiles", interrupted)
    out, cache = tmp_path / "out", tmp_path / "cache"
    with pytest.raises(KeyboardInterrupt):
        brdffit.fit_btf_database(database, "lambert", out=out, tile=4, cache_dir=cache)
    assert calls == [("cork", 0), ("felt", 0)]
    assert len(list(cache.glob("*.f32"))) == 1  # felt's, for the next run; cork's went with its maps
    assert (out / "cork" / "params.exr").is_file() and not (out / "felt" / "params.exr").exists()
    assert sorted(p.name for p in (out / "felt" / "tiles").glob("tile_*")) == ["tile_00000.npz"]
    cork_written = (out / "cork" / "params.exr").stat().st_mtime_ns
    assert len(bars) == 1 and bars[0].total == 16 + 64 + 32  # one bar over every texel

    calls.clear()

    def counted(b, tiles, *args, **kwargs):
        calls.extend((b.name, t) for t in tiles)
        return real(b, tiles, *args, **kwargs)

    monkeypatch.setattr(btf_tile, "fit_tiles", counted)
    result = brdffit.fit_btf_database(database, "lambert", out=out, tile=4, cache_dir=cache)
    assert calls == [("felt", 1), ("felt", 2), ("felt", 3), ("wool", 0), ("wool", 1)]
    assert list(cache.iterdir()) == []
    assert (out / "cork" / "params.exr").stat().st_mtime_ns == cork_written
    assert [r["status"] for r in result.rows] == ["done before", "fitted", "fitted"]
    # the second run's bar: felt and wool's texels, felt's finished tile taken out of the total
    assert bars[1].total == 64 + 32 and bars[1].skipped == 16 and bars[1].advanced == 80
    for name, single in singles.items():
        _assert_written_maps(out / name, single)
    assert result.not_converged == sum(int((~s.converged).sum()) for s in singles.values())


def test_bad_input_is_one_line_naming_the_file_before_any_work(database, tmp_path, capsys):
    db = tmp_path / "db"
    db.mkdir()
    (db / "felt").symlink_to(database / "felt")
    (db / "broken.zip").write_bytes(b"not a zip")
    out = tmp_path / "out"
    assert main(["fit-btf", str(db), "--model", "lambert", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"brdffit: {db / 'broken.zip'}: not a readable zip archive") and "\n" not in err
    (db / "broken.zip").unlink()
    (db / "half").mkdir()
    (db / "half" / "tl000_pl000_tv000_pv000.png").write_bytes((database / "felt" / "tl000_pl000_tv000_pv000.exr").read_bytes())
    assert main(["fit-btf", str(db), "--model", "lambert", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"brdffit: {db / 'half'}: incomplete image set") and "\n" not in err
    assert not out.exists()  # nothing written, not even the folder


# preexec_fn makes subprocess fork; the child only resets its SIGINT handling, then execs
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_ctrl_c_keeps_the_finished_materials_and_the_next_run_goes_on(database, singles, tmp_path):
    out = tmp_path / "out"
    exe = Path(sys.executable).with_name("brdffit")
    args = [*([str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]),
            "fit-btf", str(database), "--model", "lambert", "--tile", "4", "-o", str(out)]
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                         preexec_fn=deliverable_sigint)
    deadline = time.monotonic() + 300
    while not (out / "cork" / "params.exr").exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert p.poll() is None, p.stderr.read()
    p.send_signal(signal.SIGINT)
    assert p.wait(timeout=120) == 130
    assert "interrupted" in p.stderr.read()
    # cork was finished before the interrupt: it stays, whole; felt was not: nothing of it is a result
    _assert_written_maps(out / "cork", singles["cork"])
    assert not (out / "felt" / "params.exr").exists() and (out / "database.json").is_file()
    run = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    rows = json.loads((out / "summary.json").read_text())["materials"]
    assert [r["status"] for r in rows] == ["done before", "fitted", "fitted"]
    for name, single in singles.items():
        _assert_written_maps(out / name, single)


def test_the_bar_s_skip_takes_work_found_done_out_of_the_total():
    from brdffit._progress import progress_bar

    with progress_bar("texels", 100, rate="texels") as bar:
        bar.skip(30)
        bar.advance(10)
        (task,) = bar._bar.tasks
        assert (task.total, task.completed) == (70, 10)


@pytest.mark.skipif(len(__import__("brdffit.btf.processes").btf.processes.cores()) < 2,
                    reason="worker processes need a system with two cores a process can be confined to")
def test_one_set_of_worker_processes_serves_every_material(database, singles, tmp_path, monkeypatch):
    from brdffit.btf import processes

    processes.close()
    made = []
    real = processes._Pool.__init__

    def counted(self, cores):
        made.append(tuple(cores))
        real(self, cores)

    monkeypatch.setattr(processes._Pool, "__init__", counted)
    out = tmp_path / "out"
    result = brdffit.fit_btf_database(database, "lambert", out=out, tile=4, processes=2, progress=False)
    assert [r["status"] for r in result.rows] == ["fitted"] * 3
    assert made == [tuple(processes.cores()[:2])]  # started once (felt), kept for wool; cork's one tile here
    for name, single in singles.items():
        back = brdffit.ParameterMaps.load(out / name / "params.exr")
        np.testing.assert_allclose(back.params["kd"], single.params["kd"], rtol=1e-6)
        np.testing.assert_allclose(back.loss, single.loss, rtol=1e-6)
        summary = json.loads((out / name / "summary.json").read_text())
        assert summary["converged"] == single.converged.sum()
        assert summary["worker_processes"] == (None if name == "cork" else 2)
