"""CLI `info`, `convert` and `demo` (docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit import sample
from brdffit.cli import main
from conftest import CORNELL_FILES, RGL_FILES


def run(capsys, *args):
    code = main(list(map(str, args)))
    c = capsys.readouterr()
    return code, c.out, c.err


def test_info_sample(capsys):
    code, out, err = run(capsys, "info", sample.DEFAULT_PATH)
    assert code == 0, err
    for text in ("exr", "6561", "ubo81", "invalid samples", "24", "theta light", "0.0 .. 75.0"):
        assert text in out
    m = brdffit.load(sample.DEFAULT_PATH)
    v = np.asarray(m.values)[m.valid_mask()]
    assert f"{v[:, 0].max():.4g}" in out  # per-channel range printed


@pytest.mark.skipif(not CORNELL_FILES, reason="real measurements not found")
def test_info_and_convert_cornell(capsys, tmp_path):
    code, out, _ = run(capsys, "info", CORNELL_FILES[0])
    assert code == 0 and "cornell" in out and "1439" in out and "scattered" in out and "10.0 .. 80.0" in out
    target = tmp_path / "c.npz"
    code, out, err = run(capsys, "convert", CORNELL_FILES[0], target)
    assert code == 0, err
    assert "extrapolated" in out
    m = brdffit.load(target)
    assert m.grid == "ubo81" and m.meta["extrapolated"] > 0 and "interpolation" in m.meta


@pytest.mark.skipif(not RGL_FILES, reason="real measurements not found")
def test_convert_rgl_to_exr_and_force(capsys, tmp_path):
    target = tmp_path / "r.exr"
    code, _, err = run(capsys, "convert", RGL_FILES[0], target)
    assert code == 0, err
    np.testing.assert_array_equal(brdffit.load(target).values, brdffit.load(RGL_FILES[0]).values)
    before = target.read_bytes()
    code, _, err = run(capsys, "convert", sample.DEFAULT_PATH, target)
    assert code == 2 and "already exists" in err and str(target) in err and err.count("\n") == 1
    assert target.read_bytes() == before  # untouched without --force
    code, _, err = run(capsys, "convert", sample.DEFAULT_PATH, target, "--force")
    assert code == 0, err
    assert brdffit.load(target).name == "sample_two_lobe"


def test_convert_bad_output_extension(capsys, tmp_path):
    code, _, err = run(capsys, "convert", sample.DEFAULT_PATH, tmp_path / "x.png")
    assert code == 2 and ".exr or .npz" in err
    assert list(tmp_path.iterdir()) == []


def test_demo(capsys, tmp_path):
    out = tmp_path / "demo"
    code, stdout, err = run(capsys, "demo", "-o", out)
    assert code == 0, err
    assert (out / "table.png").stat().st_size > 1000
    m = brdffit.load(out / "sample_ubo81.npz")
    np.testing.assert_array_equal(np.asarray(m.values), np.asarray(brdffit.load(sample.DEFAULT_PATH).values))
    code, _, err = run(capsys, "demo", "-o", out)
    assert code == 2 and "already exists" in err
    code, _, err = run(capsys, "demo", "-o", out, "--force")
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # no temporary folders left
