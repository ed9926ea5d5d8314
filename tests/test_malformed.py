"""Malformed inputs through the real CLI: exit 2, exactly one stderr line naming the file,
no traceback, nothing written (docs/cli.md#the-command-line-and-set-up). Hand-written cases with a reason each; the generated
corpus of several hundred is tests/test_malformed_corpus.py."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import brdffit
from brdffit.cli import main
from brdffit.grid import ubo_pairs
from brdffit.io.images import direction_name


def good_measurement(values=None):
    wi, wo = ubo_pairs()
    v = np.full((6561, 3), 0.3) if values is None else values
    return brdffit.Measurement(wi=wi, wo=wo, values=v, grid="ubo81", name="good")


def bsdf_header(n_fields=11) -> bytes:
    return b"tensor_file\0" + struct.pack("<BBI", 1, 0, n_fields)


# each builder gets a fresh folder and returns (source, path the message must name)
def truncated_exr(d):
    good = brdffit.save(good_measurement(np.random.default_rng(0).uniform(size=(6561, 3))), d / "good.exr")
    p = d / "truncated.exr"
    p.write_bytes(good.read_bytes()[:900])
    good.unlink()
    return p, p


def wrong_magic_exr(d):
    p = d / "magic.exr"
    p.write_bytes(b"P6\n81 81\n255\n" + bytes(100))
    return p, p


def garbage_exr(d):
    p = d / "garbage.exr"
    p.write_bytes(b"\x76\x2f\x31\x01" + np.random.default_rng(1).bytes(3000))
    return p, p


def truncated_npz(d):
    good = brdffit.save(good_measurement(), d / "good.npz")
    p = d / "truncated.npz"
    p.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    good.unlink()
    return p, p


def empty_npz(d):
    p = d / "empty.npz"
    p.write_bytes(b"")
    return p, p


def npz_missing_arrays(d):
    p = d / "partial.npz"
    np.savez(p, wi=np.zeros((3, 3)))
    return p, p


def nan_only_npz(d):
    p = d / "nan.npz"
    np.savez(p, wi=ubo_pairs()[0], wo=ubo_pairs()[1], values=np.full((6561, 3), np.nan), weights=np.ones(6561))
    return p, p


def nan_only_exr(d):
    import OpenEXR

    p = d / "nan.exr"
    px = {c: np.full((81, 81), np.nan, np.float32) for c in "RGB"}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, px).write(str(p))
    return p, p


def wrong_size_exr(d):
    import OpenEXR

    p = d / "small.exr"
    px = {c: np.ones((10, 20), np.float32) for c in "RGB"}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, px).write(str(p))
    return p, p


def truncated_bsdf(d):
    p = d / "truncated.bsdf"
    p.write_bytes(bsdf_header() + struct.pack("<H", 7) + b"vers")
    return p, p


def bsdf_field_past_end(d):
    p = d / "pastend.bsdf"
    name = b"rgb"
    field = struct.pack("<H", len(name)) + name + struct.pack("<HBQ", 5, 10, 64) + struct.pack("<5Q", 1, 8, 3, 32, 32)
    p.write_bytes(bsdf_header(1) + field + bytes(200))
    return p, p


def wrong_magic_bsdf(d):
    p = d / "magic.bsdf"
    p.write_bytes(b"tensor_fiel\0" + bytes(64))
    return p, p


def empty_bsdf(d):
    p = d / "empty.bsdf"
    p.write_bytes(b"")
    return p, p


def cornell_wrong_columns(d):
    p = d / "cols.brdf"
    p.write_text("# bad\n3\n500 550 600\n0.5 0 0.5 3.14 1 1 1\n0.5 0 0.5 3.14 1 1\n")
    return p, p


def cornell_binary(d):
    p = d / "binary.brdf"
    p.write_bytes(bytes(range(256)) * 4)
    return p, p


def merl_wrong_dims(d):
    p = d / "dims.binary"
    p.write_bytes(np.array([90, 90, 360], "<i4").tobytes() + bytes(80))
    return p, p


def utia_wrong_size(d):
    p = d / "short.bin"
    np.zeros(100).tofile(p)
    return p, p


def unknown_extension(d):
    p = d / "table.csv"
    p.write_text("1,2,3\n")
    return p, p


def missing_file(d):
    p = d / "does_not_exist.npz"
    return p, p


def empty_folder(d):
    p = d / "empty_btf"
    p.mkdir()
    return p, p


def partial_image_set(d):
    p = d / "partial_btf"
    p.mkdir()
    for i, j in [(0, 0), (0, 1), (5, 3)]:
        Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(p / f"{direction_name(i, j)}.png")
    return p, p


def duplicated_direction(d):
    p = d / "dup_btf"
    p.mkdir()
    for stem in ("a_tl000_pl000_tv015_pv060", "b_tl000_pl000_tv015_pv060"):
        Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(p / f"{stem}.png")
    return p, p


def unparsable_name(d):
    p = d / "names_btf"
    p.mkdir()
    bad = p / "tl15_pl0_tv0_pv0.png"
    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(bad)
    return p, bad


CASES = [
    truncated_exr, wrong_magic_exr, garbage_exr, nan_only_exr, wrong_size_exr,
    truncated_npz, empty_npz, npz_missing_arrays, nan_only_npz,
    truncated_bsdf, bsdf_field_past_end, wrong_magic_bsdf, empty_bsdf,
    cornell_wrong_columns, cornell_binary, merl_wrong_dims, utia_wrong_size,
    unknown_extension, missing_file, empty_folder, partial_image_set, duplicated_direction, unparsable_name,
]


def run_cli(capsys, args):
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def check_one_line(code, err, named: Path):
    assert code == 2, err
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert str(named) in lines[0], lines[0]


@pytest.mark.parametrize("build", CASES, ids=[c.__name__ for c in CASES])
def test_malformed_input(tmp_path, capsys, build):
    src_dir = tmp_path / "in"
    src_dir.mkdir()
    src, named = build(src_dir)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, _, err = run_cli(capsys, ["convert", str(src), str(out_dir / "table.exr")])
    check_one_line(code, err, named)
    assert list(out_dir.iterdir()) == []  # nothing written, no temporary left behind
    code, _, err = run_cli(capsys, ["info", str(src)])
    check_one_line(code, err, named)


def test_broken_image_inside_complete_folder_is_named(full_folder, tmp_path, capsys):
    broken = full_folder / f"{direction_name(40, 12)}.png"
    good = broken.read_bytes()
    try:
        broken.write_bytes(good[:20])
        code, _, err = run_cli(capsys, ["convert", str(full_folder), str(tmp_path / "t.npz")])
        check_one_line(code, err, broken)
        assert not (tmp_path / "t.npz").exists()
    finally:
        broken.write_bytes(good)
    code, out, err = run_cli(capsys, ["convert", str(full_folder), str(tmp_path / "t.npz")])
    assert code == 0 and (tmp_path / "t.npz").exists(), err


def test_real_entry_point_subprocess(tmp_path):
    """The installed console script itself: exit 2, one line, no traceback."""
    src = tmp_path / "bad.npz"
    src.write_bytes(b"PK\x03\x04 not really a zip")
    exe = Path(sys.executable).with_name("brdffit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]
    out = tmp_path / "o.exr"
    r = subprocess.run([*cmd, "convert", str(src), str(out)], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and str(src) in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
