"""docs/cli.md#bad-input's reproductions, each as docs/cli.md#the-command-line-and-set-up says it must behave: RGL files verified before
Mitsuba, fit.json checked like any input, usage errors exit 2 with one line, one acceptance rule
for all readers, suspect data refused or warned about, --debug anywhere."""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.cli import main
from brdffit.errors import InputError
from brdffit.grid import ubo_pairs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import RGL_FILES  # noqa: E402
from test_malformed_corpus import SAMPLE, _good_fit_text, small_rgl  # noqa: E402


def run(capsys, argv):
    code = main([str(a) for a in argv])
    c = capsys.readouterr()
    return code, c.out, c.err


def one_line(code, err, named):
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert str(named) in err, err


# -- 1. RGL files reach Mitsuba's measured plugin only verified --------------------------------------
def rgl_variants(tmp_path: Path) -> dict[str, Path]:
    good = small_rgl()
    theta_at = struct.unpack_from("<Q", good, good.index(b"\x07\x00theta_i") + 2 + 7 + 3)[0]
    rgb_at = struct.unpack_from("<Q", good, good.index(b"\x03\x00rgb") + 2 + 3 + 3)[0]
    shape_at = good.index(b"\x04\x00vndf") + 2 + 4 + 2 + 1 + 8  # the first axis of 'vndf'
    variants = {
        "head1000": good[:1000],
        "half": good[: len(good) // 2],
        "version2": good[:12] + b"\x02\x00" + good[14:],
        "nan_data": good[:rgb_at] + np.full(16, np.nan, "<f4").tobytes() + good[rgb_at + 64:],
        "random_data": good[:theta_at] + np.random.default_rng(3).bytes(len(good) - theta_at),
        "huge_shape": good[:shape_at] + struct.pack("<Q", 2**62) + good[shape_at + 8:],
    }
    out = {}
    for name, data in variants.items():
        p = tmp_path / f"{name}.bsdf"
        p.write_bytes(data)
        out[name] = p
    return out


def test_valid_synthetic_rgl_loads_and_renders(tmp_path):
    """The corpus's own small material is a valid tensor_file: Mitsuba loads and renders it."""
    p = tmp_path / "small.bsdf"
    p.write_bytes(small_rgl())
    m = brdffit.load(p)
    assert m.n_samples == 6561 and m.valid_mask().sum() > 3000
    img = np.asarray(brdffit.render_sphere(p, [(0.3, 0.0)], size=16))
    assert np.all(np.isfinite(img)) and img.max() > 0


@pytest.mark.parametrize("variant", ["head1000", "half", "version2", "nan_data", "random_data", "huge_shape"])
def test_damaged_rgl_refused_on_load_and_render_paths(tmp_path, capsys, variant):
    p = rgl_variants(tmp_path)[variant]
    with pytest.raises(InputError, match=str(p)):
        brdffit.load(p)
    with pytest.raises(InputError, match=str(p)):
        brdffit.render_sphere(p, [(0.0, 0.0)], size=8)  # this killed Python (SIGSEGV) before
    fit_json = tmp_path / "fit.json"
    fit_json.write_text(_good_fit_text())
    code, _, err = run(capsys, ["validate", p, fit_json, "-o", tmp_path / "v", "--size", "8", "--lights", "1"])
    one_line(code, err, p)
    assert not (tmp_path / "v").exists()


@pytest.mark.skipif(not RGL_FILES, reason="real RGL files not found")
def test_first_1000_bytes_of_a_real_rgl_file(tmp_path, capsys):
    """The issue's segfault reproduction, with the real file."""
    p = tmp_path / "t.bsdf"
    p.write_bytes(RGL_FILES[-1].read_bytes()[:1000])
    with pytest.raises(InputError, match="truncated"):
        brdffit.render_sphere(p, [(0.0, 0.0)], size=8)


# -- 3. fit.json checked like any input --------------------------------------------------------------
def fit_doc(**changes):
    return {**json.loads(_good_fit_text()), **changes}


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"params": {"kd": [float("nan")] * 3}}, "not finite"),
        ({"params": {"kd": [5, -1, 0.2]}}, "outside its bounds"),
        ({"params": {"kd": [float("inf")] * 3}}, "not finite"),
        ({"channels": "abc"}, "'channels'"),
        ({"steps": "many"}, "'steps'"),
        ({"metrics": "bad"}, "'metrics'"),
        ({"params": [0.1, 0.2, 0.3]}, "'params'"),
        ({"params": {"kd": [0.3] * 3}, "bounds": {"kd": [0, 0.2]}}, "recorded bounds"),
    ],
)
def test_bad_fit_json_exit_2_before_rendering(tmp_path, capsys, changes, message):
    p = tmp_path / "fit.json"
    p.write_text(json.dumps(fit_doc(**changes)))
    code, out, err = run(capsys, ["validate", SAMPLE, p, "-o", tmp_path / "v", "--size", "8", "--lights", "1"])
    one_line(code, err, p)
    assert message in err and out == ""
    assert not (tmp_path / "v").exists()


def test_fit_json_unknown_fields_and_recorded_bounds_accepted(tmp_path):
    from brdffit.fitting.result import FitResult

    p = tmp_path / "fit.json"
    p.write_text(json.dumps(fit_doc(at_bound={"kd": [False] * 3}, warnings=[], future_field={"x": 1})))
    assert FitResult.from_json(p).model_name == "lambert"
    # a file that records wider bounds (e.g. physical=False) is checked against those
    p.write_text(json.dumps(fit_doc(params={"kd": [1.5, 0.2, 0.1]}, bounds={"kd": [0, 2]})))
    assert FitResult.from_json(p).params["kd"][0] == 1.5


def test_non_json_fit_file_says_so(tmp_path, capsys):
    p = tmp_path / "fit.txt"
    p.write_text("model = lambert\n")
    code, _, err = run(capsys, ["validate", SAMPLE, p, "-o", tmp_path / "v"])
    one_line(code, err, p)
    assert "not a fit file (JSON)" in err and "unknown format" not in err


# -- 4. usage errors exit 2, never 3 -----------------------------------------------------------------
@pytest.mark.parametrize("model", ["lafortune0", "lafortune100000", "lambert+lambert", "nosuch"])
def test_impossible_model_names_exit_2(tmp_path, capsys, model):
    code, _, err = run(capsys, ["fit", SAMPLE, "--model", model, "-o", tmp_path / "o"])
    assert code == 2 and err.count("\n") == 1 and model in err, err
    code, _, err = run(capsys, ["compare", SAMPLE, "--models", model, "-o", tmp_path / "c"])
    assert code == 2 and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_scattered_npz_on_one_direction_pair_exit_2(tmp_path, capsys):
    wi, wo = ubo_pairs()
    p = tmp_path / "one.npz"
    np.savez(p, wi=np.tile(wi[7], (50, 1)), wo=np.tile(wo[7], (50, 1)), values=np.full((50, 3), 0.2))
    code, _, err = run(capsys, ["convert", p, tmp_path / "t.exr"])
    one_line(code, err, p)
    assert not (tmp_path / "t.exr").exists()


@pytest.mark.parametrize("argv", [["fit", SAMPLE, "--model", "lambert", "--multistart", "-3"],
                                  ["fit", SAMPLE, "--model", "lambert", "--max-steps", "0"],
                                  ["compare", SAMPLE, "--models", ",,"],
                                  ["compare", SAMPLE, "--solvers", " , "]])
def test_bad_options_exit_2(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, argv)
    assert code == 2 and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_debug_accepted_anywhere(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"")
    assert run(capsys, ["info", bad])[0] == 2
    for argv in (["--debug", "info", str(bad)], ["info", "--debug", str(bad)], ["info", str(bad), "--debug"]):
        with pytest.raises(InputError):  # --debug shows the traceback: the error propagates
            main(argv)


# -- 6. one acceptance rule for all readers ----------------------------------------------------------
def all_invalid_sources(d: Path) -> list[Path]:
    import OpenEXR

    wi, wo = ubo_pairs()
    npz = d / "nan.npz"
    np.savez(npz, wi=wi, wo=wo, values=np.full((6561, 3), np.nan))
    w0 = d / "w0.npz"
    np.savez(w0, wi=wi, wo=wo, values=np.ones((6561, 3)), weights=np.zeros(6561))
    below = d / "below.npz"
    np.savez(below, wi=wi * np.array([1, 1, -1]), wo=wo, values=np.ones((6561, 3)))
    exr = d / "nan.exr"
    px = {c: np.full((81, 81), np.nan, np.float32) for c in "RGB"}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, px).write(str(exr))
    utia = d / "nan.bin"
    np.full(3 * 6 * 48 * 6 * 48, np.nan, "<f8").tofile(utia)
    cornell = d / "below.brdf"
    cornell.write_text("3\n450 550 650\n" + "".join(f"0.5 0 {t} 3.1 0.3 0.3 0.3\n" for t in (1.6, 1.7, 1.8, 2.0, 2.5)))
    return [npz, w0, below, exr, utia, cornell]


def test_all_invalid_data_rejected_by_info_convert_and_fit_alike(tmp_path, capsys):
    for src in all_invalid_sources(tmp_path):
        for argv in (["info", src], ["convert", src, tmp_path / "o.exr"], ["fit", src, "--model", "lambert", "-o",
                                                                             tmp_path / "f"]):
            code, _, err = run(capsys, argv)
            one_line(code, err, src)
        assert not (tmp_path / "o.exr").exists() and not (tmp_path / "f").exists()


# -- 8. suspect data: refuse what is wrong, warn about what is odd -----------------------------------
def test_all_negative_values_fit_with_one_warning_line(tmp_path, capsys):
    wi, wo = ubo_pairs()
    p = tmp_path / "neg.npz"
    np.savez(p, wi=wi, wo=wo, values=-np.ones((6561, 3)))
    code, _, err = run(capsys, ["info", p])
    assert code == 0
    lines = err.strip().split("\n")
    assert len(lines) == 1 and "warning" in lines[0] and "negative" in lines[0] and str(p) in lines[0], err


def test_non_unit_directions_refused_nearly_unit_normalised(tmp_path, capsys):
    wi, wo = ubo_pairs()
    far = tmp_path / "far.npz"
    np.savez(far, wi=wi * 1.01, wo=wo, values=np.ones((6561, 3)))
    code, _, err = run(capsys, ["info", far])
    one_line(code, err, far)
    assert "not unit vectors" in err
    near = tmp_path / "near.npz"
    np.savez(near, wi=wi * (1 + 1e-5), wo=wo, values=np.ones((6561, 3)))
    m = brdffit.load(near)
    assert np.allclose(np.linalg.norm(np.asarray(m.wi), axis=1), 1.0, atol=1e-12)


def test_complex_values_refused(tmp_path, capsys):
    wi, wo = ubo_pairs()
    p = tmp_path / "c.npz"
    np.savez(p, wi=wi, wo=wo, values=np.ones((6561, 3)) * (1 + 0.5j))
    code, _, err = run(capsys, ["fit", p, "--model", "lambert", "-o", tmp_path / "f"])
    one_line(code, err, p)
    assert "complex" in err and "ComplexWarning" not in err
    with pytest.raises(ValueError, match="complex"):
        brdffit.Measurement(wi=wi, wo=wo, values=np.ones((6561, 3)) * 1j)


def test_rgl_files_that_pass_verification_never_crash_mitsuba(tmp_path):
    """Fuzz: finite but wild values (huge, tiny, zero, negative) written at random places of the data
    of a valid file, some files truncated. Those the verifier accepts are loaded and rendered, all in one child
    process: it must end normally, never by a signal (the plugin has no bounds checks of its own)."""
    import subprocess

    from brdffit.io.rgl import check_tensor_file

    good = small_rgl()
    first_data = struct.unpack_from("<Q", good, good.index(b"\x05\x00phi_i") + 2 + 5 + 3)[0]
    rng = np.random.default_rng(9)
    accepted = []
    for k in range(60):
        b = bytearray(good)
        for _ in range(1 + k % 5):
            at = int(rng.integers(first_data, len(good) - 4)) // 4 * 4
            b[at:at + 4] = np.float32(rng.choice([3e38, 1e-38, 0.0, 7.0, -0.5, 1e10, -3e38])).tobytes()
        if k % 6 == 5:  # and some truncated: the plugin maps the file and would read past its end
            b = b[: int(rng.integers(100, len(b)))]
        p = tmp_path / f"m{k}.bsdf"
        p.write_bytes(bytes(b))
        try:
            check_tensor_file(p)
            accepted.append(str(p))
        except InputError:
            pass
    assert len(accepted) >= 10  # enough of them reach the plugin
    child = (
        "import sys, brdffit\n"
        "from brdffit.errors import InputError\n"
        "for p in sys.argv[1:]:\n"
        "    try:\n"
        "        brdffit.load(p)\n"
        "        brdffit.render_sphere(p, [(0.4, 0.0)], size=8)\n"
        "    except InputError:\n"
        "        pass\n"
        "print('done', len(sys.argv) - 1)\n"
    )
    import os

    r = subprocess.run([sys.executable, "-c", child, *accepted], capture_output=True, text=True, timeout=600,
                       env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])  # negative: killed by a signal
    assert f"done {len(accepted)}" in r.stdout
