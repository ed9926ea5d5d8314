"""Helpers shared by the readers (brdffit.io._common): the direction pairs an evaluable reader
samples, the JSON form of metadata in .exr/.npz files, and the capture of native library output."""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

from brdffit.errors import UsageError
from brdffit.grid import ubo_pairs
from brdffit.io import _common


def test_query_directions_default_is_the_ubo_grid():
    wi, wo, grid = _common.query_directions()
    ref_wi, ref_wo = ubo_pairs()
    assert grid == "ubo81" and np.array_equal(wi, ref_wi) and np.array_equal(wo, ref_wo)


def test_query_directions_given_pairs():
    wi, wo, grid = _common.query_directions([0, 0, 1], [[0.6, 0, 0.8]])
    assert grid is None and wi.shape == (1, 3) and wo.shape == (1, 3) and wi.dtype == np.float64
    assert wi.tolist() == [[0.0, 0.0, 1.0]] and wo.tolist() == [[0.6, 0.0, 0.8]]


@pytest.mark.parametrize(
    "wi, wo, message",
    [
        ([0, 0, 1], None, "give both wi and wo (light and view directions), or neither for the UBO-81 grid"),
        (None, [0, 0, 1], "give both wi and wo (light and view directions), or neither for the UBO-81 grid"),
        ([[0, 0, 1]], [[0, 0, 1], [0, 0, 1]], "wi (1, 3) and wo (2, 3) must both be (N, 3)"),
        ([[0, 1]], [[0, 1]], "wi (1, 2) and wo (1, 2) must both be (N, 3)"),
        (np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), "wi (1, 1, 3) and wo (1, 1, 3) must both be (N, 3)"),
        # not unit vectors: read as given they would sample another angle (or none) silently
        ([[0, 0, 1], [0, 0, 2]], [[0, 0, 1]] * 2, "wi[1] = [0.0, 0.0, 2.0] has length 2: directions must be unit vectors"),
        ([[0, 0, 1]], [[0.6, 0, 0.8001]], "wo[0] = [0.6, 0.0, 0.8001] has length 1.00008: directions must be unit vectors"),
        ([[0, 0, 1]], [[np.nan, 0, 1]], "wo[0] = [nan, 0.0, 1.0] has length nan: directions must be unit vectors"),
        ([[0, 0, 0]], [[0, 0, 1]], "wi[0] = [0.0, 0.0, 0.0] has length 0: directions must be unit vectors"),
    ],
)
def test_query_directions_refusals(wi, wo, message):
    with pytest.raises(UsageError) as info:
        _common.query_directions(wi, wo)
    assert str(info.value) == message


class Meta:
    """The fields meta_to_json reads from a Measurement."""

    name, source, grid, colour_space, units = "n", "s.npz", "ubo81", "linear_rec709", "1/sr"
    extra = (("tuple", (1, 2.5, ("a", None))), ("np", np.float32(0.5)), ("flag", True), ("dict", {"k": [1]}),
             ("path", os.path.join("a", "b")), ("obj", complex(1, 2)), ("nan", float("nan")))


def test_metadata_json_round_trip():
    text = _common.meta_to_json(Meta())
    doc = json.loads(text)
    assert [doc[k] for k in _common.META_FIELDS] == ["n", "s.npz", "ubo81", "linear_rec709", "1/sr"]
    back = _common.meta_from_json(text)
    assert {k: back[k] for k in _common.META_FIELDS} == {k: getattr(Meta, k) for k in _common.META_FIELDS}
    extra = back["extra"]
    assert extra["tuple"] == (1, 2.5, ("a", None))
    assert extra["np"] == 0.5 and type(extra["np"]) is float
    assert extra["flag"] is True
    assert extra["dict"] == (("k", (1,)),)  # a dict comes back as (key, value) pairs, its list as a tuple
    assert extra["path"] == os.path.join("a", "b")
    assert extra["obj"] == "(1+2j)"  # anything exotic survives as its text
    assert np.isnan(extra["nan"])
    assert list(extra) == ["tuple", "np", "flag", "dict", "path", "obj", "nan"]


def test_metadata_json_wire_format():
    """The on-disk form: tuples and dicts tagged, so that a reader can tell them from lists."""
    doc = json.loads(_common.meta_to_json(Meta()))
    assert doc["extra"][0] == ["tuple", {"__tuple__": [1, 2.5, {"__tuple__": ["a", None]}]}]
    assert doc["extra"][3] == ["dict", {"__dict__": [["k", {"__tuple__": [1]}]]}]


def test_metadata_json_partial_and_refused():
    assert _common.meta_from_json('{"name": "x"}') == {"name": "x", "extra": {}}
    with pytest.raises(ValueError, match="^metadata is not a JSON object$"):
        _common.meta_from_json("[1]")


def test_native_output_is_captured_and_restored(capfd):
    with _common.native_stderr_captured() as captured:
        os.write(1, b"from C on fd 1\n")
        os.write(2, b"from C on fd 2\n")
        print("python stdout")
        print("python stderr", file=sys.stderr)
    assert captured == ["python stdout\npython stderr\n", "from C on fd 1\n", "from C on fd 2\n"]
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"


def test_query_directions_integers_become_float64():
    wi, wo, _ = _common.query_directions([[0, 0, 1]], [[0, 0, 1]])
    assert wi.dtype == np.float64 and wo.dtype == np.float64


def _direction(theta_deg: float) -> list[float]:
    t = np.radians(theta_deg)
    return [float(np.sin(t)), 0.0, float(np.cos(t))]


def test_summary_of_a_hand_made_table():
    """What ``brdffit info`` prints, worked out by hand for five samples: two valid, one non-finite,
    one with weight 0 and one with the light below the horizon (ranges over the valid ones only;
    the angle ranges over all samples)."""
    from brdffit.io import summary
    from brdffit.measurement import Measurement

    thetas = [(0, 30), (60, 0), (45, 75), (10, 20), (100, 80)]
    m = Measurement(
        [_direction(a) for a, _ in thetas], [_direction(b) for _, b in thetas],
        [[0.5, -0.1, 2.0], [1.5, 0.0, 4.0], [np.nan, 0.0, 0.0], [9.0, 9.0, 9.0], [7.0, 7.0, 7.0]],
        [1.0, 1.0, 1.0, 0.0, 1.0], name="five", source="five.npz", colour_space="linear_rec709", units="1/sr",
        extra={"format": "npz"},
    )
    s = summary(m)
    ranges = s.pop("ranges")
    assert s.pop("theta_light_deg") == pytest.approx((0.0, 100.0))
    assert s.pop("theta_view_deg") == pytest.approx((0.0, 80.0))
    assert s == {"name": "five", "format": "npz", "source": "five.npz", "samples": 5, "grid": None, "channels": 3,
                 "colour_space": "linear_rec709", "units": "1/sr", "invalid": 3, "zero_weight": 1, "non_finite": 1}
    assert [r.pop("channel") for r in ranges] == ["R", "G", "B"]
    assert ranges == [
        pytest.approx({"min": 0.5, "max": 1.5, "mean": 1.0, "negative": 0}),
        pytest.approx({"min": -0.1, "max": 0.0, "mean": -0.05, "negative": 1}),  # a zero is not negative
        pytest.approx({"min": 2.0, "max": 4.0, "mean": 3.0, "negative": 0}),
    ]


def test_summary_without_valid_samples_or_format():
    from brdffit.io import summary
    from brdffit.measurement import Measurement

    s = summary(Measurement([_direction(20)] * 2, [_direction(40)] * 2, [[1.0, 2.0], [3.0, 4.0]], [0.0, 0.0]))
    assert s["format"] == "?" and s["channels"] == 2 and s["invalid"] == 2 and s["zero_weight"] == 2
    assert [r["channel"] for r in s["ranges"]] == ["c0", "c1"]
    for r in s["ranges"]:
        assert np.isnan(r["min"]) and np.isnan(r["max"]) and np.isnan(r["mean"]) and r["negative"] == 0


def test_device_copy_is_a_private_float64_copy():
    """device_put may share a NumPy array's memory on the CPU (it does for 64-byte aligned arrays:
    seen with JAX 0.10): a reader's Measurement must not change when the reader's buffer does."""
    buf = np.zeros(1000 + 8)
    start = (-buf.ctypes.data % 64) // 8
    a = buf[start:start + 1000]  # 64-byte aligned
    a[:] = np.arange(1000.0)
    out = _common.device_copy(a)
    a[:] = -1.0
    assert out.dtype == np.float64
    np.testing.assert_array_equal(np.asarray(out), np.arange(1000.0))
    assert _common.device_copy([1, 2]).dtype == np.float64


def test_a_readers_type_error_is_named_as_a_bad_input(tmp_path, monkeypatch):
    """A TypeError inside a reader (not one about its keyword options) is the file's problem: one
    line naming the format, the exception's type and text."""
    import brdffit
    from brdffit.errors import InputError
    from brdffit.io import npz

    path = tmp_path / "t.npz"
    path.write_bytes(b"anything")

    def broken(p, **options):
        raise TypeError("unsupported operand type(s) for +: 'int' and\n'str'")

    monkeypatch.setattr(npz, "read", broken)
    with pytest.raises(InputError) as err:
        brdffit.load(path)
    assert str(err.value) == f"{path}: cannot read as npz: TypeError: unsupported operand type(s) for +: 'int' and 'str'"


def test_save_names_a_path_without_extension(tmp_path):
    import brdffit

    m = brdffit.Measurement(*ubo_pairs(), np.full((6561, 3), 0.1))
    target = tmp_path / "table"
    with pytest.raises(UsageError) as err:
        brdffit.save(m, target)
    assert str(err.value) == f"{target}: cannot write 'files without extension'; use .exr or .npz"
    assert not target.exists()
