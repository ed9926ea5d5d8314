"""brdffit.io.exr.write checked from outside: the file is read back with the OpenEXR library itself
(header keys and values, channel names, types and pixels), the ``brdffit.f64`` side copies are
decoded by hand, and the expectations are literals (module docstring, docs/formats.md#readers-and-writers) or NumPy arithmetic
on the input. No shared data needed."""

from __future__ import annotations

import base64
import json
import re
import zlib

import numpy as np
import pytest

import brdffit
from brdffit.errors import InputError, UsageError
from brdffit.grid import ubo_pairs
from brdffit.io import exr

# what every file written by exr.write holds in its header: the OpenEXR required attributes plus
# brdffit's own (module docstring)
HEADER_KEYS = {
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
    "screenWindowCenter", "screenWindowWidth", "type",
    "brdffit.format", "brdffit.grid", "brdffit.layout", "brdffit.directions", "brdffit.meta", "brdffit.f64",
}


def ubo(values, weights=None, wi=None, **kw):
    gwi, gwo = ubo_pairs()
    return brdffit.Measurement(wi=gwi if wi is None else wi, wo=gwo, values=values, weights=weights, grid="ubo81",
                               name="t", source="mem", **kw)


def f32_exact_values(channels, seed=0):
    """float64 values that are exactly float32 numbers (k / 1024)."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, 4096, size=(6561, channels)).astype(np.float64) / 1024.0


def open_exr(path):
    import OpenEXR

    f = OpenEXR.File(str(path), separate_channels=True)
    return dict(f.header()), dict(f.channels())


def unpack_by_hand(text, shape):
    return np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype="<f8").reshape(shape)


@pytest.mark.parametrize("channels", [1, 3])
def test_header_and_channels_as_openexr_reads_them(tmp_path, channels):
    import OpenEXR

    values = f32_exact_values(channels)
    weights = np.tile([1.0, 0.5, 0.0, 0.25], 6561 // 4 + 1)[:6561]
    p = tmp_path / "t.exr"
    exr.write(ubo(values, weights), p)
    header, chans = open_exr(p)
    assert set(header) == HEADER_KEYS
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert header["type"] == OpenEXR.scanlineimage
    assert header["brdffit.format"] == "ubo81-table/1"
    assert header["brdffit.grid"] == "ubo81"
    assert header["brdffit.layout"] == "rows = light index, columns = view index (UBO-81 order)"
    assert header["brdffit.directions"] == "ubo81"
    assert json.loads(header["brdffit.f64"]) == {}  # everything is float32-exact and on the grid
    meta = json.loads(header["brdffit.meta"])
    assert (meta["name"], meta["source"], meta["grid"]) == ("t", "mem", "ubo81")
    names = ["R", "G", "B"] if channels == 3 else ["Y"]
    assert sorted(chans) == sorted(names + ["weight"])
    for k, n in enumerate(names):
        px = chans[n].pixels
        assert chans[n].type() == OpenEXR.FLOAT and px.dtype == np.float32 and px.shape == (81, 81)
        np.testing.assert_array_equal(px, values[:, k].reshape(81, 81))  # row = light, column = view
    assert chans["weight"].type() == OpenEXR.FLOAT and chans["weight"].pixels.dtype == np.float32
    np.testing.assert_array_equal(chans["weight"].pixels, weights.reshape(81, 81))


@pytest.mark.parametrize("nan_in", ["values", "weights", "both"])
def test_float32_exact_arrays_with_nan_need_no_float64_copy(tmp_path, nan_in):
    values = f32_exact_values(3, seed=1)
    weights = np.full(6561, 0.5)
    if nan_in in ("values", "both"):
        values[::5, 1] = np.nan
    if nan_in in ("weights", "both"):
        weights[::9] = np.nan
    p = tmp_path / "n.exr"
    exr.write(ubo(values, weights), p)
    header, chans = open_exr(p)
    assert json.loads(header["brdffit.f64"]) == {}
    np.testing.assert_array_equal(chans["G"].pixels, values[:, 1].reshape(81, 81))  # NaN where NaN
    np.testing.assert_array_equal(chans["weight"].pixels, weights.reshape(81, 81))


def test_values_not_float32_exact_are_stored_as_float64_with_their_nans(tmp_path):
    values = f32_exact_values(3, seed=2) + 0.1  # k/1024 + 0.1: not float32 numbers
    values[::11, 0] = np.nan
    weights = np.full(6561, 0.75)  # float32-exact: no copy
    p = tmp_path / "v.exr"
    exr.write(ubo(values, weights), p)
    header, chans = open_exr(p)
    f64 = json.loads(header["brdffit.f64"])
    assert sorted(f64) == ["values"]
    np.testing.assert_array_equal(unpack_by_hand(f64["values"], (6561, 3)), values)
    np.testing.assert_array_equal(chans["R"].pixels, values[:, 0].astype(np.float32).reshape(81, 81))
    assert header["brdffit.directions"] == "ubo81"


def test_weights_not_float32_exact_are_stored_as_float64_with_their_nans(tmp_path):
    values = f32_exact_values(1, seed=3)
    weights = np.linspace(0.0, 1.0, 6561)  # mostly not float32 numbers
    weights[::13] = np.nan
    p = tmp_path / "w.exr"
    exr.write(ubo(values, weights), p)
    header, chans = open_exr(p)
    f64 = json.loads(header["brdffit.f64"])
    assert sorted(f64) == ["weights"]
    np.testing.assert_array_equal(unpack_by_hand(f64["weights"], (6561,)), weights)
    np.testing.assert_array_equal(chans["weight"].pixels, weights.astype(np.float32).reshape(81, 81))
    np.testing.assert_array_equal(np.asarray(brdffit.load(p).weights), weights)  # read back exactly, NaNs too


def test_a_given_name_replaces_the_stored_one(tmp_path):
    p = tmp_path / "n.exr"
    exr.write(ubo(f32_exact_values(1)), p)
    assert brdffit.load(p).name == "t" and brdffit.load(p, name="given").name == "given"


def test_directions_off_the_grid_are_stored(tmp_path):
    gwi, gwo = ubo_pairs()
    wi = np.asarray(gwi) + 1e-3 * np.array([1.0, -0.5, 0.0])
    wi = wi / np.linalg.norm(wi, axis=1, keepdims=True)
    values = f32_exact_values(3, seed=4)
    p = tmp_path / "d.exr"
    exr.write(ubo(values, wi=wi), p)
    header, _ = open_exr(p)
    assert header["brdffit.directions"] == "stored"
    assert header["brdffit.grid"] == "ubo81"
    f64 = json.loads(header["brdffit.f64"])
    assert sorted(f64) == ["wi", "wo"]
    np.testing.assert_array_equal(unpack_by_hand(f64["wi"], (6561, 3)), wi)
    np.testing.assert_array_equal(unpack_by_hand(f64["wo"], (6561, 3)), np.asarray(gwo))


def test_refusals_in_full(tmp_path):
    p = tmp_path / "s.exr"
    scattered = brdffit.Measurement(wi=np.eye(3)[[2]], wo=np.eye(3)[[2]], values=[[1.0, 1, 1]])
    msg = (f"{p}: EXR holds UBO-81 tables only; this measurement has grid=None "
           "(resample it first, e.g. `brdffit convert`, or save as .npz)")
    with pytest.raises(UsageError, match=f"^{re.escape(msg)}$"):
        exr.write(scattered, p)
    two = ubo(np.ones((6561, 2)))
    with pytest.raises(UsageError, match=f"^{re.escape(f'{p}: EXR tables hold 1 (Y) or 3 (RGB) channels, not 2')}$"):
        exr.write(two, p)
    assert list(tmp_path.iterdir()) == []


def test_existing_file_refused_without_force_replaced_with_force(tmp_path):
    p = tmp_path / "f.exr"
    first, second = np.full((6561, 1), 0.25), np.full((6561, 1), 2.0)
    exr.write(ubo(first), p)
    msg = f"{p}: already exists (use --force to replace it)"
    with pytest.raises(UsageError, match=f"^{re.escape(msg)}$"):
        exr.write(ubo(second), p)  # force defaults to False
    _, chans = open_exr(p)
    np.testing.assert_array_equal(chans["Y"].pixels, np.full((81, 81), 0.25, np.float32))
    exr.write(ubo(second), p, force=True)
    _, chans = open_exr(p)
    np.testing.assert_array_equal(chans["Y"].pixels, np.full((81, 81), 2.0, np.float32))
    assert [x.name for x in tmp_path.iterdir()] == ["f.exr"]  # no temporary files left


def test_values_beyond_float32_are_written_silently_and_kept_exactly(tmp_path):
    """A value beyond float32's range becomes inf in the float32 channel (the float64 copy keeps it)
    and neither writing nor reading warns: the cast overflows by design."""
    import warnings

    import OpenEXR

    values = f32_exact_values(3)
    values[7, 1] = 1e39
    path = tmp_path / "big.exr"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exr.write(ubo(values), path)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert np.isinf(f.channels()["G"].pixels.reshape(-1)[7])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert brdffit.load(path).values[7, 1] == 1e39


@pytest.mark.parametrize("names", [("R", "G", "B"), ("Y",), ("A", "B", "G", "R"), ("Y", "weight")])
def test_a_table_written_by_another_tool_is_read_on_the_nominal_grid(tmp_path, names):
    """Module docstring: any other 81 x 81 RGB (or Y) EXR is a UBO-81 table, rows light, columns view.
    Written here with the OpenEXR library alone (no brdffit header): exactly R, G, B; Y alone; RGB
    with alpha (not a colour channel); Y with a weight channel (used as the weights)."""
    import OpenEXR

    rng = np.random.default_rng(5)
    px = {n: rng.uniform(0.0, 4.0, (81, 81)).astype(np.float32) for n in names}
    path = tmp_path / "foreign.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, dict(px)).write(str(path))  # (it turns the dict's arrays into Channels)
    m = brdffit.load(path)
    colour = ["R", "G", "B"] if "R" in names else ["Y"]
    want = np.stack([px[n].astype(np.float64).reshape(-1) for n in colour], axis=-1)
    np.testing.assert_array_equal(np.asarray(m.values), want)
    weights = px["weight"].astype(np.float64).reshape(-1) if "weight" in names else np.ones(6561)
    np.testing.assert_array_equal(np.asarray(m.weights), weights)
    gwi, gwo = ubo_pairs()
    assert m.grid == "ubo81" and np.array_equal(np.asarray(m.wi), gwi) and np.array_equal(np.asarray(m.wo), gwo)


def test_colour_channels():
    assert exr.colour_channels(["B", "weight", "R", "G", "Y"]) == ("R", "G", "B")
    assert exr.colour_channels({"R", "G", "Y"}) == ("Y",)
    assert exr.colour_channels(["R", "G", "A"]) is None and exr.colour_channels([]) is None


def test_read_refusals_in_full(tmp_path):
    """Each file the EXR reader refuses, named with its whole message (no shared data)."""
    import OpenEXR

    def exr_file(name, px):
        p = tmp_path / name
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, px).write(str(p))
        return p

    good = brdffit.save(ubo(f32_exact_values(3)), tmp_path / "good.exr")
    (tmp_path / "empty.exr").write_bytes(b"")
    (tmp_path / "text.exr").write_bytes(b"81 81\n" * 10)
    (tmp_path / "cut.exr").write_bytes(good.read_bytes()[:400])
    cases = {
        tmp_path / "empty.exr": "empty file (expected an OpenEXR image)",
        tmp_path / "text.exr": "not an OpenEXR file (wrong magic number)",
        exr_file("alpha.exr", {"A": np.ones((81, 81), np.float32)}): "no R,G,B or Y channels (has A)",
        exr_file("small.exr", {"Y": np.ones((10, 20), np.float32)}):
            "image is 20x10 pixels; a UBO-81 table is 81x81 (rows light, columns view)",
    }
    for path, problem in cases.items():
        with pytest.raises(InputError) as err:
            exr.read(path)
        assert str(err.value) == f"{path}: {problem}"
    with pytest.raises(InputError) as err:
        exr.read(tmp_path / "cut.exr")
    assert str(err.value).startswith(f"{tmp_path / 'cut.exr'}: unreadable OpenEXR (truncated or corrupt): ")
    assert "\n" not in str(err.value)
