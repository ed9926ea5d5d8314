"""MERL .binary and UTIA .bin readers, on small files written here following each published layout."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.errors import InputError
from brdffit.grid import cartesian_to_spherical, spherical_to_cartesian

MERL_SCALES = np.array([1.0, 1.15, 1.66]) / 1500.0


def write_merl(path, physical):
    """physical: (3, 90, 90, 180) f_r values -> MERL file (int32 dims, then R, G, B float64 blocks)."""
    stored = physical / MERL_SCALES[:, None, None, None]
    with open(path, "wb") as fh:
        fh.write(np.array([90, 90, 180], dtype="<i4").tobytes())
        fh.write(np.ascontiguousarray(stored, dtype="<f8").tobytes())  # phi_d fastest, theta_h slowest


def rot_z(v, a):
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], axis=1)


def rot_y(v, a):
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[:, 0] + s * v[:, 2], v[:, 1], -s * v[:, 0] + c * v[:, 2]], axis=1)


def from_half_diff(th, td, pd, ph):
    """Light and view from Rusinkiewicz coordinates (the inverse of MERL's conversion)."""
    d = spherical_to_cartesian(td, pd)
    d_out = d * np.array([-1.0, -1.0, 1.0])
    return rot_z(rot_y(d, th), ph), rot_z(rot_y(d_out, th), ph)


@pytest.fixture(scope="module")
def merl_random(tmp_path_factory):
    rng = np.random.default_rng(5)
    phys = rng.uniform(0.01, 2.0, size=(3, 90, 90, 180))
    phys[:, 80:, 85:, :] = -1.0 * MERL_SCALES[:, None, None, None]  # unmeasured corner (negative)
    path = tmp_path_factory.mktemp("merl") / "random.binary"
    write_merl(path, phys)
    return path, phys


def test_merl_cell_centres_exact(merl_random):
    path, phys = merl_random
    rng = np.random.default_rng(6)
    n = 4000
    ih, id_, ip = rng.integers(0, 90, n), rng.integers(0, 90, n), rng.integers(0, 180, n)
    th = ((ih + 0.5) / 90) ** 2 * (np.pi / 2)
    td = (id_ + 0.5) / 90 * (np.pi / 2)
    pd = (ip + 0.5) / 180 * np.pi
    wi, wo = from_half_diff(th, td, pd, rng.uniform(0, 2 * np.pi, n))
    up = (wi[:, 2] > 1e-3) & (wo[:, 2] > 1e-3) & (phys[0, ih, id_, ip] > 0)
    assert up.sum() > 500
    m = brdffit.load(path, wi=wi[up], wo=wo[up])
    expected = phys[:, ih[up], id_[up], ip[up]].T
    np.testing.assert_allclose(np.asarray(m.values), expected, rtol=1e-12)
    # light and view swapped: the same cell (MERL tables are reciprocal by construction)
    m2 = brdffit.load(path, wi=wo[up], wo=wi[up])
    np.testing.assert_allclose(np.asarray(m2.values), expected, rtol=1e-12)


def test_merl_negative_is_invalid(merl_random):
    path, phys = merl_random
    th = np.full(10, ((85 + 0.5) / 90) ** 2 * np.pi / 2)
    td = np.full(10, (87 + 0.5) / 90 * np.pi / 2)
    wi, wo = from_half_diff(th, td, np.linspace(0.1, 3.0, 10), np.zeros(10))
    keep = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    wi, wo = wi[keep], wo[keep]
    good_i, good_o = from_half_diff(np.array([0.2]), np.array([0.3]), np.array([0.5]), np.array([0.0]))
    m = brdffit.load(path, wi=np.vstack([wi, good_i]), wo=np.vstack([wo, good_o]))
    w = np.asarray(m.weights)
    assert np.all(w[:-1] == 0) and w[-1] == 1
    assert m.meta["invalid_negative"] == len(wi)


def test_merl_smooth_on_ubo81(tmp_path):
    # known analytic content g(theta_h, theta_d) at cell centres; UBO-81 lookup follows it within a cell
    th = ((np.arange(90) + 0.5) / 90) ** 2 * (np.pi / 2)
    td = (np.arange(90) + 0.5) / 90 * (np.pi / 2)

    def g(theta_h, theta_d):
        return 0.1 + 0.5 * np.cos(theta_h) ** 4 * (1 + 0.2 * np.cos(theta_d))

    cell = g(th[:, None], td[None, :])[None, :, :, None] * np.array([1.0, 0.8, 0.6])[:, None, None, None]
    phys = np.broadcast_to(cell, (3, 90, 90, 180))
    p = tmp_path / "smooth.binary"
    write_merl(p, phys)
    m = brdffit.load(p)
    assert m.grid == "ubo81" and m.n_samples == 6561
    wi, wo = np.asarray(m.wi), np.asarray(m.wo)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    theta_h = np.arccos(np.clip(h[:, 2], -1, 1))
    theta_d = np.arccos(np.clip(np.sum(wi * h, axis=1), -1, 1))
    expected = g(theta_h, theta_d)[:, None] * np.array([1.0, 0.8, 0.6])
    assert np.max(np.abs(np.asarray(m.values) - expected)) < 0.02


def test_merl_bad_header_and_size(tmp_path):
    p = tmp_path / "dims.binary"
    p.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + b"\0" * 64)
    with pytest.raises(InputError, match="resolution"):
        brdffit.load(p)
    q = tmp_path / "short.binary"
    q.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + b"\0" * 800)
    with pytest.raises(InputError, match="truncated"):
        brdffit.load(q)


# -- UTIA ------------------------------------------------------------------------------------------
def utia_flat_index(c, ti, pi_, tv, pv):
    """The published index formula of the UTIA reference loader."""
    nti, npi, ntv, npv = 6, 48, 6, 48
    nc, nr = npv * ntv, npi * nti
    return c * nr * nc + nc * (npi * ti + pi_) + npv * tv + pv


def test_utia_layout_on_nodes(tmp_path):
    rng = np.random.default_rng(7)
    flat = rng.uniform(0, 1, 3 * 6 * 48 * 6 * 48)
    p = tmp_path / "m.bin"
    flat.astype("<f8").tofile(p)
    n = 500
    ti, tv = rng.integers(0, 6, n), rng.integers(0, 6, n)
    pi_, pv = rng.integers(0, 48, n), rng.integers(0, 48, n)
    wi = spherical_to_cartesian(np.radians(15.0 * ti), np.radians(7.5 * pi_))
    wo = spherical_to_cartesian(np.radians(15.0 * tv), np.radians(7.5 * pv))
    m = brdffit.load(p, wi=wi, wo=wo)
    # at the pole the azimuth is 0 whatever was asked
    pi_eff, pv_eff = np.where(ti == 0, 0, pi_), np.where(tv == 0, 0, pv)
    expected = np.stack([flat[utia_flat_index(c, ti, pi_eff, tv, pv_eff)] for c in range(3)], axis=1)
    np.testing.assert_allclose(np.asarray(m.values), expected, rtol=1e-9)


def test_utia_analytic_on_ubo81(tmp_path):
    T = np.radians(np.arange(6) * 15.0)
    P = np.radians(np.arange(48) * 7.5)

    def F(ti, pi_, tv, pv):
        return 0.2 + 0.3 * np.cos(ti) * np.cos(tv) + 0.1 * np.cos(pi_ - pv) * np.sin(ti) * np.sin(tv)

    grid = F(T[:, None, None, None], P[None, :, None, None], T[None, None, :, None], P[None, None, None, :])
    table = np.stack([grid, 0.5 * grid, 2 * grid])
    p = tmp_path / "analytic.bin"
    np.ascontiguousarray(table, "<f8").tofile(p)
    m = brdffit.load(p)
    assert m.grid == "ubo81"
    ti, pi_ = cartesian_to_spherical(np.asarray(m.wi))
    tv, pv = cartesian_to_spherical(np.asarray(m.wo))
    exp = F(ti, pi_, tv, pv)[:, None] * np.array([1.0, 0.5, 2.0])
    # thetas lie on the table grid; the azimuths are linearly interpolated over 7.5 degrees
    assert np.max(np.abs(np.asarray(m.values) - exp)) < 0.1 * (np.radians(7.5) ** 2) * 2
    on_node = (np.mod(np.degrees(pi_) + 1e-9, 7.5) < 1e-6) & (np.mod(np.degrees(pv) + 1e-9, 7.5) < 1e-6)
    np.testing.assert_allclose(np.asarray(m.values)[on_node], exp[on_node], rtol=1e-9)


def test_utia_wrong_size(tmp_path):
    p = tmp_path / "short.bin"
    np.zeros(1000).tofile(p)
    with pytest.raises(InputError, match="truncated"):
        brdffit.load(p)
