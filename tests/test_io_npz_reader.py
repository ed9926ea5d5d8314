"""The .npz reader on small hand-made archives (np.savez, not brdffit's writer): what it accepts,
how it normalises directions, and the exact one-line message of each refusal (docs/cli.md#bad-input: the message
names the file and the problem; the wording is part of what users see)."""

from __future__ import annotations

import warnings
import zipfile

import numpy as np
import pytest

from brdffit.errors import InputError
from brdffit.io import npz

UP = [0.0, 0.0, 1.0]
TILT = [0.6, 0.0, 0.8]  # 0.36 + 0.64 = 1 exactly in decimal, unit to rounding in float64


def archive(path, **arrays):
    np.savez(path, **arrays)
    return path


def refusal(path) -> str:
    with pytest.raises(InputError) as info:
        npz.read(path)
    assert info.value.path == str(path)
    return info.value.problem


def test_minimal_archive_reads_with_defaults(tmp_path):
    """No metadata, no weights, 1-D values: name from the file, weights 1, values as one channel."""
    p = archive(tmp_path / "plain.npz", wi=np.array([UP, TILT]), wo=np.array([TILT, UP]), values=np.array([0.5, 2.0]))
    m = npz.read(p)
    assert m.name == "plain" and m.source == str(p)
    assert np.asarray(m.values).shape == (2, 1) and np.asarray(m.values)[:, 0].tolist() == [0.5, 2.0]
    assert np.asarray(m.weights).tolist() == [1.0, 1.0]
    assert dict(m.extra)["format"] == "npz"
    assert npz.read(p, name="other").name == "other"


def test_integer_arrays_are_read_as_float64(tmp_path):
    p = archive(tmp_path / "ints.npz", wi=np.array([[0, 0, 1]]), wo=np.array([[0, 0, 1]]), values=np.array([[3, 4, 5]]),
                weights=np.array([2]))
    m = npz.read(p)
    assert np.asarray(m.wi).dtype == np.float64 and np.asarray(m.values).tolist() == [[3.0, 4.0, 5.0]]
    assert np.asarray(m.weights).tolist() == [2.0]


def test_near_unit_directions_are_normalised_in_float64(tmp_path):
    """A float32 copy of a unit vector (length 1 - 3e-8) and a row of length 1.0005 come back unit
    to float64 rounding; a row already unit to rounding is kept bit for bit."""
    d = np.array([[0.6, 0.0, 0.8], [0.0, 0.6003, 0.8004], [1 / 3, 2 / 3, 2 / 3]])
    lengths = np.linalg.norm(d.astype(np.float32).astype(np.float64), axis=1)
    assert abs(lengths[0] - 1) > 1e-9  # the float32 rounding really moved the length
    p = archive(tmp_path / "f32.npz", wi=d.astype(np.float32), wo=np.array([UP] * 3), values=np.ones(3))
    wi = np.asarray(npz.read(p).wi)
    assert np.all(np.abs(np.linalg.norm(wi, axis=1) - 1) < 4e-16)
    np.testing.assert_allclose(wi[1], np.array([0.0, 0.6003, 0.8004]) / 1.0005, rtol=1e-6)
    exact = np.array([[0.6, 0.0, 0.8], [0.48, 0.6, 0.64]])
    p = archive(tmp_path / "exact.npz", wi=exact, wo=exact, values=np.ones(2))
    assert np.array_equal(np.asarray(npz.read(p).wi), exact)


def test_huge_direction_is_refused_without_numpy_warnings(tmp_path):
    p = archive(tmp_path / "huge.npz", wi=np.array([[1e200, 1e200, 1e200]]), wo=np.array([UP]), values=np.ones(1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert refusal(p) == "1 of 1 directions in 'wi' are not unit vectors (e.g. sample 0: length inf)"


def test_pickled_object_array_is_not_unpickled(tmp_path):
    p = archive(tmp_path / "obj.npz", wi=np.array([UP]), wo=np.array([UP]), values=np.array([[{"a": 1}]], dtype=object))
    assert refusal(p).startswith("corrupt .npz archive: Object arrays cannot be loaded when allow_pickle=False")


@pytest.mark.parametrize(
    "case, expected",
    [
        ("empty", "empty file (expected a .npz archive)"),
        ("one_byte", "not a .npz archive (no zip structure; truncated or another format)"),
        ("missing", "missing array(s) wo, values (a measurement .npz holds wi, wo, values)"),
        ("bad_metadata", "unreadable metadata: metadata is not a JSON object"),
        ("complex_values", "array 'values' holds complex values; a measurement holds real numbers"),
        ("text_weights", "array 'weights' holds <U1 values; a measurement holds real numbers"),
        ("wi_shape", "inconsistent shapes: wi (2, 2), wo (2, 3), values (2, 1)"),
        ("wo_shape", "inconsistent shapes: wi (2, 3), wo (1, 3), values (2, 1)"),
        ("values_3d", "inconsistent shapes: wi (2, 3), wo (2, 3), values (2, 1, 1)"),
        ("weights_shape", "weights (3,) do not match 2 samples"),
        ("no_samples", "no samples"),
        ("short_wo", "2 of 3 directions in 'wo' are not unit vectors (e.g. sample 1: length 0.5)"),
        ("nan_only", "no usable sample: every value is NaN/inf or has weight 0"),
        ("ubo81_count", "metadata says grid ubo81 but there are 2 samples"),
    ],
)
def test_refusals_name_file_and_problem(tmp_path, case, expected):
    p = tmp_path / f"{case}.npz"
    two = dict(wi=np.array([UP, TILT]), wo=np.array([UP, TILT]), values=np.array([[0.1], [0.2]]))
    if case == "empty":
        p.write_bytes(b"")
    elif case == "one_byte":
        p.write_bytes(b"P")
    elif case == "missing":
        archive(p, wi=two["wi"])
    elif case == "bad_metadata":
        archive(p, **two, metadata=np.array("[1, 2]"))
    elif case == "complex_values":
        archive(p, wi=two["wi"], wo=two["wo"], values=np.array([[1 + 2j], [0j]]))
    elif case == "text_weights":
        archive(p, **two, weights=np.array(["a", "b"]))
    elif case == "wi_shape":
        archive(p, wi=np.ones((2, 2)), wo=two["wo"], values=two["values"])
    elif case == "wo_shape":
        archive(p, wi=two["wi"], wo=np.array([UP]), values=two["values"])
    elif case == "values_3d":
        archive(p, wi=two["wi"], wo=two["wo"], values=np.ones((2, 1, 1)))
    elif case == "weights_shape":
        archive(p, **two, weights=np.ones(3))
    elif case == "no_samples":
        archive(p, wi=np.zeros((0, 3)), wo=np.zeros((0, 3)), values=np.zeros((0, 1)))
    elif case == "short_wo":
        archive(p, wi=np.array([UP] * 3), wo=np.array([UP, [0, 0, 0.5], [0, 0.25, 0]]), values=np.ones(3))
    elif case == "nan_only":
        archive(p, **{**two, "values": np.array([[np.nan], [np.inf]])})
    elif case == "ubo81_count":
        archive(p, **two, metadata=np.array('{"grid": "ubo81"}'))
    assert refusal(p) == expected


def test_truncated_archive_message_is_one_line(tmp_path):
    good = archive(tmp_path / "good.npz", wi=np.array([UP]), wo=np.array([UP]), values=np.ones(1))
    with zipfile.ZipFile(good) as z:
        member = z.namelist()[0]
    bad = tmp_path / "bad.npz"
    data = good.read_bytes()
    bad.write_bytes(data.replace(b"\x93NUMPY", b"\x93NUMPX", 1))  # stored member changed: its CRC no longer matches
    with pytest.raises(zipfile.BadZipFile) as zip_error:  # zipfile's own words, whitespace folded to one line
        with np.load(bad, allow_pickle=False) as z:
            z[member.removesuffix(".npy")]
    assert refusal(bad) == "corrupt .npz archive: " + " ".join(str(zip_error.value).split())


def test_writer_does_not_overwrite_unless_forced(tmp_path):
    m = npz.read(archive(tmp_path / "src.npz", wi=np.array([UP]), wo=np.array([UP]), values=np.ones(1)))
    target = tmp_path / "out.npz"
    npz.write(m, target)
    before = target.read_bytes()
    with pytest.raises(Exception) as info:
        npz.write(m, target)
    assert "exists" in str(info.value) and target.read_bytes() == before
    npz.write(m, target, force=True)
    assert np.array_equal(np.asarray(npz.read(target).values), [[1.0]])


def test_usable_rows_are_judged_one_by_one(tmp_path):
    """One NaN row does not spoil the table; weight 0 everywhere does."""
    two = dict(wi=np.array([UP, TILT]), wo=np.array([UP, TILT]))
    m = npz.read(archive(tmp_path / "one_nan.npz", **two, values=np.array([[np.nan], [0.5]])))
    assert np.isnan(np.asarray(m.values)[0, 0]) and np.asarray(m.values)[1, 0] == 0.5
    zero = archive(tmp_path / "zero_w.npz", **two, values=np.array([[0.1], [0.5]]), weights=np.zeros(2))
    assert refusal(zero) == "no usable sample: every value is NaN/inf or has weight 0"
