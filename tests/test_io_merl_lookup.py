"""MERL .binary reader on a generated table against a line-by-line scalar port of MERL's reference
``BRDFRead.cpp`` (std_coords_to_half_diff_coords, theta_half_index, theta_diff_index,
phi_diff_index, lookup_brdf_val), and the header/size checks."""

from __future__ import annotations

import math
import struct

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
