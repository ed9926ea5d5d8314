"""MERL .binary reader on a generated table against a line-by-line scalar port of MERL's reference
``BRDFRead.cpp`` (std_coords_to_half_diff_coords, theta_half_index, theta_diff_index,
phi_diff_index, lookup_brdf_val), and the header/size checks."""

from __future__ import annotations

import math
import struct
import warnings

import numpy as np
import pytest

from brdffit.errors import InputError
from brdffit.io import merl

RES_TH, RES_TD, RES_PD = 90, 90, 360  # BRDFRead.cpp's constants (phi_d stored at half resolution)
RED_SCALE, GREEN_SCALE, BLUE_SCALE = 1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0


def rotate_vector(v, axis, angle):
    cos_a, sin_a = math.cos(angle), math.sin(angle)
    out = [v[i] * cos_a for i in range(3)]
    tmp = sum(axis[i] * v[i] for i in range(3)) * (1 - cos_a)
    out = [out[i] + axis[i] * tmp for i in range(3)]
    cross = [axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2], axis[0] * v[1] - axis[1] * v[0]]
    return [out[i] + cross[i] * sin_a for i in range(3)]


def half_diff(t_in, f_in, t_out, f_out):
    vin = [math.sin(t_in) * math.cos(f_in), math.sin(t_in) * math.sin(f_in), math.cos(t_in)]
    vout = [math.sin(t_out) * math.cos(f_out), math.sin(t_out) * math.sin(f_out), math.cos(t_out)]
    half = [(vin[i] + vout[i]) / 2 for i in range(3)]
    norm = math.sqrt(sum(x * x for x in half))
    half = [x / norm for x in half]
    theta_half, fi_half = math.acos(half[2]), math.atan2(half[1], half[0])
    temp = rotate_vector(vin, [0, 0, 1], -fi_half)
    diff = rotate_vector(temp, [0, 1, 0], -theta_half)
    return theta_half, math.acos(diff[2]), math.atan2(diff[1], diff[0])


def theta_half_index(theta_half):
    if theta_half <= 0.0:
        return 0
    ret = int(math.sqrt(theta_half / (math.pi / 2.0) * 90 * RES_TH))
    return min(max(ret, 0), RES_TH - 1)


def theta_diff_index(theta_diff):
    return min(max(int(theta_diff / (math.pi * 0.5) * RES_TD), 0), RES_TD - 1)


def phi_diff_index(phi_diff):
    if phi_diff < 0.0:
        phi_diff += math.pi
    return min(max(int(phi_diff / math.pi * RES_PD / 2), 0), RES_PD // 2 - 1)


def lookup(brdf, t_in, f_in, t_out, f_out):
    th, td, pd = half_diff(t_in, f_in, t_out, f_out)
    ind = phi_diff_index(pd) + theta_diff_index(td) * RES_PD // 2 + theta_half_index(th) * RES_PD // 2 * RES_TD
    n = RES_TH * RES_TD * RES_PD // 2
    return [brdf[ind] * RED_SCALE, brdf[ind + n] * GREEN_SCALE, brdf[ind + 2 * n] * BLUE_SCALE]


@pytest.fixture(scope="module")
def table_file(tmp_path_factory):
    brdf = np.random.default_rng(3).uniform(0.0, 1000.0, 3 * 90 * 90 * 180)
    path = tmp_path_factory.mktemp("merl") / "m.binary"
    path.write_bytes(struct.pack("<3i", 90, 90, 180) + brdf.astype("<f8").tobytes())
    return path, brdf


def test_lookup_matches_reference_code(table_file):
    path, brdf = table_file
    rng = np.random.default_rng(5)
    n = 60
    t_in, t_out = rng.uniform(0.01, 1.5, n), rng.uniform(0.01, 1.5, n)
    f_in, f_out = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    t_in[:2], t_out[:2], f_in[:2], f_out[:2] = 0.4, 0.4, 0.0, [np.pi, 0.0]  # mirror pair (theta_h = 0); a retro pair

    def vec(t, f):
        return np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], axis=1)

    m = merl.read(path, wi=vec(t_in, f_in), wo=vec(t_out, f_out))
    expected = [lookup(brdf, *a) for a in zip(t_in, f_in, t_out, f_out, strict=True)]
    np.testing.assert_allclose(np.asarray(m.values), expected, rtol=1e-12)
    assert np.asarray(m.weights).tolist() == [1.0] * n
    extra = dict(m.extra)
    assert extra["format"] == "merl" and extra["invalid_negative"] == 0
    assert extra["channel_scales"] == (RED_SCALE, GREEN_SCALE, BLUE_SCALE)
    assert m.grid is None and m.name == "m" and m.source == str(path)


def test_negative_cells_and_lower_hemisphere_get_weight_zero(tmp_path):
    brdf = np.full(3 * 90 * 90 * 180, 150.0)
    brdf[90 * 90 * 180 + 1 :: 7] = -1.0  # some green cells unmeasured (not the first: normal incidence)
    path = tmp_path / "neg.binary"
    path.write_bytes(struct.pack("<3i", 90, 90, 180) + brdf.astype("<f8").tobytes())
    m = merl.read(path)
    v, w = np.asarray(m.values), np.asarray(m.weights)
    assert m.grid == "ubo81" and set(w.tolist()) == {0.0, 1.0} and dict(m.extra)["invalid_negative"] == int((w == 0).sum())
    np.testing.assert_allclose(v[w == 1], [[0.1, 0.115, 0.166]] * int(w.sum()), rtol=1e-12)
    assert np.all(v[w == 0] == 0.0)
    below = merl.read(path, wi=[[0.6, 0, 0.8], [0.6, 0, -0.8], [0, 0, 1.0]], wo=[[0.0, 0.6, -0.8], [0, 0, 1.0], [0, 0, 1.0]])
    assert np.asarray(below.weights).tolist() == [0.0, 0.0, 1.0]
    assert dict(below.extra)["invalid_negative"] == 0  # below the horizon is not "unmeasured"
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # opposite grazing directions have no half vector: no 0/0 warning
        grazing = merl.read(path, wi=[[1.0, 0, 0], [0, 0, 1.0]], wo=[[-1.0, 0, 0], [0, 0, 1.0]])
    assert np.asarray(grazing.weights).tolist() == [0.0, 1.0]


def header(dims=(90, 90, 180)):
    return struct.pack("<3i", *dims)


FULL = 12 + 8 * 3 * 90 * 90 * 180


@pytest.mark.parametrize(
    "content, problem",
    [
        (b"", "empty file (expected a MERL .binary)"),
        (b"\x5a\0\0\0\x5a", "truncated: 5 bytes, not even the 12-byte header"),
        (header((90, 90, 360)), "header says resolution (90, 90, 360); a MERL table is (90, 90, 180) (theta_h, theta_d, phi_d)"),
        (header() + b"\0" * 16, f"truncated: 28 bytes, a MERL .binary has {FULL}"),
        (header() + b"\0" * (FULL - 12 + 8), f"trailing data: {FULL + 8} bytes, a MERL .binary has {FULL}"),
        (header() + np.full(3 * 90 * 90 * 180, -1.0).tobytes(),
         "no valid sample at the requested directions (all negative = unmeasured, or NaN)"),
    ],
    ids=["empty", "short", "dims", "truncated", "trailing", "all_negative"],
)
def test_refusals(tmp_path, content, problem):
    p = tmp_path / "bad.binary"
    p.write_bytes(content)
    with pytest.raises(InputError) as info:
        merl.read(p)
    assert info.value.path == str(p) and info.value.problem == problem


def test_indices_where_the_reference_clamps_and_folds():
    """indices() against BRDFRead.cpp's index functions (above) at the edges of the table: theta_h just
    inside its last cell and beyond pi/2, theta_d at pi/2 and beyond, negative angles, phi_d folded."""
    last_h = (89 / 90) ** 2 * (math.pi / 2)  # first theta_h of the last (89th) sqrt-spaced cell
    theta_h = [0.0, -0.1, 1e-12, last_h - 1e-9, last_h + 1e-9, math.pi / 2, 2.0, math.pi]
    theta_d = [-0.1, 0.0, 89 / 90 * (math.pi / 2) + 1e-9, math.pi / 2 - 1e-9, math.pi / 2, 2.0, math.pi, 0.5]
    phi_d = [-4.0, -1e-9, -math.pi, 0.0, math.pi - 1e-9, math.pi, 3.5, -math.pi / 2]
    ih, idd, ip = merl.indices(np.array(theta_h), np.array(theta_d), np.array(phi_d))
    assert ih.tolist() == [theta_half_index(t) for t in theta_h] == [0, 0, 0, 88, 89, 89, 89, 89]
    assert idd.tolist() == [theta_diff_index(t) for t in theta_d] == [0, 0, 89, 89, 89, 89, 89, 28]
    assert ip.tolist() == [phi_diff_index(p) for p in phi_d] == [0, 179, 0, 0, 179, 179, 179, 90]


def test_half_diff_of_retro_pairs_has_theta_d_zero_without_warnings():
    """Light = view (retro-reflection): theta_h = theta, theta_d = 0 (Rusinkiewicz 1998). At these
    directions the rotated difference vector's z rounds to 1 + 2**-52: acos must still give 0."""
    t = np.deg2rad([15.0, 15.0, 75.0, 5.0])
    f = np.deg2rad([120.0, 150.0, 15.0, 270.0])
    w = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        theta_h, theta_d, _ = merl.half_diff(w, w.copy())
    np.testing.assert_allclose(theta_h, t, rtol=0, atol=1e-12)
    assert np.all(np.isfinite(theta_d)) and np.all(np.abs(theta_d) < 1e-7)


def test_opposite_directions_are_an_invalid_sample_not_a_crash(table_file):
    """Light and view opposite on the horizon have no half vector (0/0): that pair gets weight 0 and
    the others are read as usual (normal incidence and view: cell (0, 0, 0))."""
    path, brdf = table_file
    n = 90 * 90 * 180
    with np.errstate(invalid="ignore", divide="ignore"):
        m = merl.read(path, wi=[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], wo=[[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.asarray(m.weights).tolist() == [0.0, 1.0]
    np.testing.assert_array_equal(np.asarray(m.values)[0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(
        np.asarray(m.values)[1], [brdf[0] * RED_SCALE, brdf[n] * GREEN_SCALE, brdf[2 * n] * BLUE_SCALE], rtol=1e-12
    )


def test_zero_small_and_nan_cells_and_the_horizon(tmp_path):
    """Stored 0 and values below 1 are measurements (only negative = unmeasured); a NaN in one channel
    invalidates that sample only; a light or view on the horizon (z = 0) gets weight 0. The table is
    150 everywhere but in three theta_h rows; for light = view = (sin t, 0, cos t), theta_h = t, so
    index_h = floor(sqrt(t / (pi/2)) * 90): t = 0 -> 0, 0.3 -> 39 (39.3), 0.6 -> 55 (55.6), 0.9 -> 68 (68.1);
    light (1, 0, 0) or view (0, 1, 0) with the other at the normal: theta_h = pi/4 -> 63 (63.6)."""
    brdf = np.full((3, 90, 90, 180), 150.0)
    brdf[:, 0] = 0.0
    brdf[:, 39] = 0.5
    brdf[2, 55] = np.nan
    path = tmp_path / "edge.binary"
    path.write_bytes(struct.pack("<3i", 90, 90, 180) + brdf.astype("<f8").tobytes())
    t = np.array([0.0, 0.3, 0.6, 0.9])
    w = np.stack([np.sin(t), np.zeros(4), np.cos(t)], axis=1)
    light = np.concatenate([w, [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    view = np.concatenate([w, [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]])
    m = merl.read(path, wi=light, wo=view)
    scales = np.array([RED_SCALE, GREEN_SCALE, BLUE_SCALE])
    assert np.asarray(m.weights).tolist() == [1.0, 1.0, 0.0, 1.0, 0.0, 0.0]
    np.testing.assert_allclose(
        np.asarray(m.values), [[0.0] * 3, 0.5 * scales, [0.0] * 3, 150.0 * scales, [0.0] * 3, [0.0] * 3], rtol=1e-15
    )
    assert dict(m.extra)["lookup"] == "nearest cell, sqrt(theta_h) indexing (MERL reference code)"
