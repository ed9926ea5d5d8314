"""UTIA .bin reader on a generated table: the lookup equals scipy's RegularGridInterpolator (linear,
periodic in phi, linear extrapolation above 75 degrees) on the published layout, and the size
checks say what is wrong."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from brdffit.errors import InputError
from brdffit.io import utia

SHAPE = (3, 6, 48, 6, 48)  # [channel, theta_i, phi_i, theta_v, phi_v], C order, float64 little-endian


@pytest.fixture(scope="module")
def table_file(tmp_path_factory):
    table = np.random.default_rng(7).uniform(0.0, 2.0, SHAPE)
    path = tmp_path_factory.mktemp("utia") / "t.bin"
    table.astype("<f8").tofile(path)
    return path, table


def direction(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def reference(table, ti, pi_, tv, pv):
    """Linear interpolation on the grid theta 0..75 step 15, phi 0..360 step 7.5 (phi 360 = phi 0)."""
    wrapped = np.concatenate([table, table[:, :, :1]], axis=2)
    wrapped = np.concatenate([wrapped, wrapped[:, :, :, :, :1]], axis=4)
    theta, phi = np.arange(6) * 15.0, np.arange(49) * 7.5
    pts = np.stack([ti, np.mod(pi_, 360), tv, np.mod(pv, 360)], axis=1)
    return np.stack([RegularGridInterpolator((theta, phi, theta, phi), wrapped[c], bounds_error=False, fill_value=None)(pts)
                     for c in range(3)], axis=1)


def test_lookup_matches_scipy(table_file):
    path, table = table_file
    rng = np.random.default_rng(1)
    n = 40
    ti, tv = rng.uniform(0, 85, n), rng.uniform(0, 85, n)  # above 75: extrapolated from the last two rows
    pi_, pv = rng.uniform(-30, 400, n), rng.uniform(0, 360, n)
    ti[:3], pi_[:3] = [15.0, 30.0, 75.0], [7.5, 352.5, 0.0]  # on grid nodes
    m = utia.read(path, wi=direction(ti, pi_), wo=direction(tv, pv))
    np.testing.assert_allclose(np.asarray(m.values), reference(table, ti, pi_, tv, pv), rtol=1e-9, atol=1e-12)
    assert np.asarray(m.weights).tolist() == [1.0] * n
    assert m.grid is None and m.name == "t" and m.source == str(path) and dict(m.extra)["format"] == "utia"


def test_pole_uses_the_phi_zero_row(table_file):
    path, table = table_file
    m = utia.read(path, wi=[[0.0, 0.0, 1.0], [0.0, -0.0, 1.0]], wo=[direction(30.0, 97.5)] * 2)
    np.testing.assert_allclose(np.asarray(m.values), [table[:, 0, 0, 2, 13]] * 2, rtol=1e-12)


def test_default_grid_and_directions_below_the_horizon(table_file):
    path, _ = table_file
    m = utia.read(path, name="x")
    assert m.grid == "ubo81" and m.n_samples == 6561 and m.name == "x"
    below = utia.read(path, wi=[[0.6, 0.0, -0.8], [0.0, 0.0, 1.0]], wo=[[0.0, 0.0, 1.0], [0.6, 0.0, -0.8]])
    assert np.asarray(below.weights).tolist() == [0.0, 0.0]
    assert np.asarray(below.values).tolist() == [[0.0] * 3] * 2


@pytest.mark.parametrize(
    "size, problem",
    [
        (0, "empty file (expected a UTIA BRDF .bin)"),
        (8, "truncated: 8 bytes, a UTIA BRDF .bin (3x6x48x6x48 float64) has 1990656"),
        (1990657, "too long: 1990657 bytes, a UTIA BRDF .bin (3x6x48x6x48 float64) has 1990656"),
    ],
)
def test_size_refusals(tmp_path, size, problem):
    p = tmp_path / "bad.bin"
    p.write_bytes(b"\0" * size)
    with pytest.raises(InputError) as info:
        utia.read(p)
    assert info.value.path == str(p) and info.value.problem == problem


def test_all_nan_table_refused(tmp_path):
    p = tmp_path / "nan.bin"
    np.full(SHAPE, np.nan).astype("<f8").tofile(p)
    with pytest.raises(InputError) as info:
        utia.read(p)
    assert info.value.path == str(p) and info.value.problem == "no finite value in the table"


def test_near_pole_azimuth_is_kept_and_grazing_or_nan_cells_get_weight_zero(tmp_path, table_file):
    path, table = table_file
    light = direction(np.array([0.5]), np.array([90.0]))  # 0.5 degrees from the pole: its azimuth still counts
    m = utia.read(path, wi=light, wo=direction(np.array([30.0]), np.array([0.0])))
    np.testing.assert_allclose(np.asarray(m.values), reference(table, [0.5], [90.0], [30.0], [0.0]), rtol=1e-9)
    grazing = utia.read(path, wi=[[1.0, 0, 0], [0, 0, 1.0], [0, 0, 1.0]], wo=[[0, 0, 1.0], [0, 1.0, 0], [0, 0, 1.0]])
    assert np.asarray(grazing.weights).tolist() == [0.0, 0.0, 1.0]
    holed = table.copy()
    holed[1, 2] = np.nan  # green channel, light theta 30 degrees: unmeasured
    p = tmp_path / "holed.bin"
    holed.astype("<f8").tofile(p)
    w = np.asarray(utia.read(p, wi=direction(np.array([30.0, 0.0]), np.array([0.0, 0.0])), wo=[[0, 0, 1.0]] * 2).weights)
    assert w.tolist() == [0.0, 1.0]
    extra = dict(m.extra)
    assert extra["lookup"] == "multilinear in (theta_i, phi_i, theta_v, phi_v), 15 / 7.5 degree steps (UTIA reference loader)"
    assert extra["light_directions"] == "nominal (the .bin table is on a regular grid)"
