"""Scattered samples onto UBO-81 without the shared data: coordinates by hand, extrapolation and
its weights against a brute-force nearest neighbour and scipy's Delaunay hull, and the refusals."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import ConvexHull, Delaunay

import brdffit
from brdffit.errors import InputError, UsageError
from brdffit.grid import ubo_index, ubo_pairs
from brdffit.io import resample
from brdffit.io.resampling import interpolate_scattered, isotropic_coords


def direction(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def test_isotropic_coords_by_hand():
    wi = direction(np.array([30.0, 30.0, 50.0]), np.array([0.0, 350.0, 100.0]))
    wo = direction(np.array([60.0, 10.0, 20.0]), np.array([270.0, 0.0, 300.0]))
    got = np.degrees(isotropic_coords(wi, wo))
    np.testing.assert_allclose(got, [[30, 60, 90], [30, 10, 10], [50, 20, 160]], atol=1e-9)


def scattered(theta_light_max=40.0, n=400, seed=0):
    """Samples of f = 1 + theta_light + theta_view + dphi/4 (radians): lights up to theta_light_max."""
    rng = np.random.default_rng(seed)
    wi = direction(rng.uniform(0, theta_light_max, n), rng.uniform(0, 360, n))
    wo = direction(rng.uniform(0, 40, n), rng.uniform(0, 360, n))
    x = isotropic_coords(wi, wo)
    values = (1 + x[:, 0] + x[:, 1] + x[:, 2] / 4)[:, None] * np.array([1.0, 2.0, 3.0])
    return brdffit.Measurement(wi=wi, wo=wo, values=values, name="s", source="s.npz", extra={"format": "cornell"}), x


@pytest.mark.parametrize("reciprocal", [True, False])
def test_extrapolation_is_nearest_sample_with_distance_weight(reciprocal):
    m, x = scattered()
    r = interpolate_scattered(m, reciprocal=reciprocal)
    assert r.grid == "ubo81" and r.n_samples == 6561 and r.name == "s" and r.source == "s.npz"
    pts = np.concatenate([x, x[:, [1, 0, 2]]]) if reciprocal else x
    vals = np.asarray(m.values)
    vals = np.concatenate([vals, vals]) if reciprocal else vals
    q = isotropic_coords(*ubo_pairs())
    dist = np.linalg.norm(q[:, None, :] - pts[None, :, :], axis=2)  # brute force, (6561, N)
    nearest, d = dist.argmin(axis=1), dist.min(axis=1)
    outside = Delaunay(pts).find_simplex(q) < 0
    w = np.asarray(r.weights)
    v = np.asarray(r.values)
    # (the reader rounds coordinates to 1e-9 rad to merge coincident points: distances agree to ~1e-9)
    np.testing.assert_allclose(w[outside], 1 / (1 + (d[outside] / np.radians(10)) ** 2), rtol=1e-7)
    assert np.all(w[~outside] == 1.0)
    np.testing.assert_allclose(v[outside], vals[nearest[outside]], rtol=1e-12)
    inside_exact = 1 + q[~outside, 0] + q[~outside, 1] + q[~outside, 2] / 4  # linear: reproduced inside the hull
    np.testing.assert_allclose(v[~outside, 1], 2 * inside_exact, rtol=1e-9)
    extra = dict(r.extra)
    assert extra["extrapolated"] == int(outside.sum()) > 0
    assert extra["max_extrapolation_deg"] == pytest.approx(np.degrees(d[outside].max()), rel=1e-7)
    assert extra["max_gap_deg"] == pytest.approx(np.degrees(d.max()), rel=1e-7)
    assert extra["resampled_from"] == "400 scattered samples (cornell)"
    assert extra["interpolation"] == ("piecewise linear (Delaunay) in (theta_light, theta_view, |dphi|)"
                                      + (", with reciprocity (light/view swapped)" if reciprocal else "")
                                      + "; nearest sample outside the hull")
    assert extra["extrapolated_weight"] == "1 / (1 + (d / 10 deg)^2)"


def test_refusals():
    m, _ = scattered(n=4)
    with pytest.raises(InputError) as info:
        interpolate_scattered(m)
    assert str(info.value) == "s.npz: only 4 valid samples: too few to interpolate"
    flat = brdffit.Measurement(wi=direction(np.full(8, 30.0), np.zeros(8)), wo=direction(np.full(8, 30.0), np.zeros(8)),
                               values=np.ones((8, 1)), name="flat")
    with pytest.raises(InputError) as info:
        interpolate_scattered(flat)
    assert str(info.value).startswith("flat: the 8 valid samples do not span the directions (flat or coincident in "
                                      "theta_light, theta_view, dphi): cannot interpolate them onto the UBO-81 grid (")
    with pytest.raises(UsageError) as info:
        resample(m, grid="merl")
    assert str(info.value) == "unknown grid 'merl'; supported: 'ubo81'"
    with pytest.raises(UsageError) as info:
        resample(m, wi=1)
    assert str(info.value) == "options ['wi'] apply only when resampling a path"
    with pytest.raises(UsageError) as info:
        resample(3.5)
    assert str(info.value) == "resample() takes a Measurement or a path, not float"


def test_ubo_measurement_returned_as_is():
    wi, wo = ubo_pairs()
    m = brdffit.Measurement(wi=wi, wo=wo, values=np.ones((6561, 1)), grid="ubo81")
    assert resample(m) is m


def test_reciprocity_is_the_default():
    m, _ = scattered(n=60, seed=4)
    assert "with reciprocity" in dict(interpolate_scattered(m).extra)["interpolation"]
    assert "with reciprocity" in dict(resample(m).extra)["interpolation"]


def test_five_valid_samples_are_enough_and_interpolated_against_scipy():
    """The smallest accepted input: 5 valid samples (and 2 invalid ones: weight 0, a NaN value),
    reciprocity on. Expected values by hand and from scipy directly: a function linear in
    (theta_light, theta_view, dphi) and symmetric in the two thetas is reproduced inside the hull
    whatever the tetrahedralisation; outside it the nearest of the 10 points (brute force) gives
    value and weight."""
    deg = np.array([[10.0, 25.0, 20.0], [50.0, 35.0, 100.0], [70.0, 20.0, 160.0], [35.0, 70.0, 60.0],
                    [25.0, 50.0, 130.0], [40.0, 40.0, 90.0], [20.0, 30.0, 10.0]])  # (theta_l, theta_v, dphi)
    phi_l = np.array([0.0, 30.0, 200.0, 90.0, 300.0, 0.0, 0.0])
    wi = direction(deg[:, 0], phi_l)
    wo = direction(deg[:, 1], phi_l + deg[:, 2])
    x = np.radians(deg)

    def f(p):
        g = 0.5 + 0.7 * (p[:, 0] + p[:, 1]) + 0.3 * p[:, 2]
        return np.stack([g, 3.0 - 2.0 * g], axis=1)

    values = f(x)
    values[6, 1] = np.nan  # invalid: not finite
    weights = np.array([1.0, 1, 1, 1, 1, 0, 1])  # invalid: weight 0
    m = brdffit.Measurement(wi=wi, wo=wo, values=values, weights=weights, name="five", source="five.brdf")
    r = interpolate_scattered(m)
    pts = np.concatenate([x[:5], x[:5][:, [1, 0, 2]]])
    vals = np.concatenate([values[:5], values[:5]])
    q = isotropic_coords(*ubo_pairs())
    # signed distance to the hull's faces: grid points on a face (e.g. (45, 45, 160) on the edge from a
    # sample to its swap) are left out, since rounding puts them either side
    hull = ConvexHull(pts)
    margin = (hull.equations[:, :3] @ q.T + hull.equations[:, 3:]).max(axis=0)
    inside, outside = margin < -1e-9, margin > 1e-9
    v, w = np.asarray(r.values), np.asarray(r.weights)
    assert inside.sum() > 50 and outside.sum() > 50
    # (the product rounds sample coordinates to 1e-9 rad before interpolating: agreement to ~1e-8)
    np.testing.assert_allclose(v[inside], f(q[inside]), rtol=1e-8)
    np.testing.assert_allclose(v[inside], LinearNDInterpolator(pts, vals)(q[inside]), rtol=1e-8)
    assert np.all(w[inside] == 1.0)
    d = np.linalg.norm(q[:, None, :] - pts[None, :, :], axis=2)
    dmin = d.min(axis=1)
    for i in np.flatnonzero(outside):  # the value of one of the nearest points (a grid point can have ties)
        tied = d[i] <= dmin[i] + 1e-9
        assert np.any(np.all(vals[tied] == v[i], axis=1)), i
    np.testing.assert_allclose(w[outside], 1 / (1 + (dmin[outside] / np.radians(10)) ** 2), rtol=1e-7)
    assert dict(r.extra)["extrapolated"] == int(np.sum(w < 1)) >= outside.sum()
    assert dict(r.extra)["resampled_from"] == "7 scattered samples (measurement)"
    with pytest.raises(InputError, match=f"^{re.escape('five.brdf: only 4 valid samples: too few to interpolate')}$"):
        interpolate_scattered(m.replace(weights=np.array([1.0, 1, 1, 1, 0, 0, 1])))


@pytest.mark.parametrize("offset_rad", [0.0, 1e-10])
def test_coincident_samples_are_averaged(offset_rad):
    """Two samples at one direction pair (or 1e-10 rad apart: within the 1e-9 rad merge tolerance)
    with values f - 1 and f + 1 among samples of a linear f: the grid pairs at that point get their
    mean f, as a vertex of the interpolation (not f + 1, which an unmerged pair would give, nor a sum)."""
    m, _ = scattered(theta_light_max=70.0, n=400, seed=3)
    k = ubo_index(30.0, 0.0) * 81 + ubo_index(45.0, 120.0)  # docs/conventions.md#conventions: light-major pairs
    wi, wo = ubo_pairs()
    x = isotropic_coords(wi[k:k + 1], wo[k:k + 1])[0]
    f = (1 + x[0] + x[1] + x[2] / 4) * np.array([1.0, 2.0, 3.0])
    twin_view = direction(45.0 + np.degrees(offset_rad), 120.0)  # theta_view 1e-10 rad away
    assert np.round(isotropic_coords(wi[k:k + 1], twin_view[None])[0, 1], 9) == np.round(x[1], 9)
    both = brdffit.Measurement(
        wi=np.concatenate([np.asarray(m.wi), wi[k:k + 1], wi[k:k + 1]]),
        wo=np.concatenate([np.asarray(m.wo), wo[k:k + 1], twin_view[None]]),
        values=np.concatenate([np.asarray(m.values), [f - 1.0], [f + 1.0]]), name="twins")
    r = interpolate_scattered(both, reciprocal=False)
    same_point = np.all(np.abs(isotropic_coords(wi, wo) - x) < 1e-12, axis=1)
    assert same_point.sum() >= 2  # the pair and its rotations about the normal
    np.testing.assert_allclose(np.asarray(r.values)[same_point], np.broadcast_to(f, (same_point.sum(), 3)), rtol=1e-6)


def test_samples_covering_every_grid_point_need_no_extrapolation():
    """Scattered samples at every UBO-81 pair (grid not declared) and beyond it (theta 85 degrees,
    and 0.001 degrees off the pole, so that no grid point lies on an outer edge of the hull, where the
    1e-9 rad merge rounding could leave it just outside): nothing is extrapolated, the largest
    extrapolation is 0 degrees, the values come back, and the colour space and units carry over."""
    wi, wo = ubo_pairs()
    ring = np.arange(0.0, 76.0, 15.0)
    dphi = np.arange(0.0, 181.0, 15.0)
    beyond = np.array([(a, b, d) for d in dphi for a in [*ring, 85.0] for b in [*ring, 85.0] if 85.0 in (a, b)]
                      + [(0.0, 1e-3, d) for d in dphi])  # and views just off the pole at every dphi (with
    # reciprocity, lights too): the grid's pole pairs then lie inside, not on an edge of the hull
    wi = np.concatenate([wi, direction(beyond[:, 0], np.zeros(len(beyond)))])
    wo = np.concatenate([wo, direction(beyond[:, 1], beyond[:, 2])])
    x = isotropic_coords(wi, wo)
    values = (0.5 + 0.7 * (x[:, 0] + x[:, 1]) + 0.3 * x[:, 2])[:, None]
    m = brdffit.Measurement(wi=wi, wo=wo, values=values, name="all", colour_space="acescg", units="arbitrary")
    r = interpolate_scattered(m)
    extra = dict(r.extra)
    assert extra["extrapolated"] == 0 and extra["max_extrapolation_deg"] == 0.0 and extra["max_gap_deg"] < 1e-6
    np.testing.assert_allclose(np.asarray(r.values), values[:6561], rtol=1e-8)
    assert np.all(np.asarray(r.weights) == 1.0)
    assert (r.colour_space, r.units, r.grid) == ("acescg", "arbitrary", "ubo81")  # carried over


def _samples_at(deg):
    """Measurement with one sample per (theta_light, theta_view, dphi) row of ``deg`` (degrees)."""
    deg = np.asarray(deg, np.float64)
    wi = direction(deg[:, 0], np.zeros(len(deg)))
    wo = direction(deg[:, 1], deg[:, 2])
    return brdffit.Measurement(wi=wi, wo=wo, values=np.ones((len(deg), 1)), name="few"), np.radians(deg)


def test_four_distinct_points_after_merging_are_enough_three_are_not():
    four = [[10, 20, 30], [60, 20, 30], [10, 70, 30], [10, 20, 150], [60, 20, 30]]  # 5 samples, 4 distinct
    r = interpolate_scattered(_samples_at(four)[0], reciprocal=False)
    assert np.all(np.isfinite(np.asarray(r.values)))
    three = [[10, 20, 30], [60, 20, 30], [10, 70, 30], [10, 70, 30], [60, 20, 30]]  # 5 samples, 3 distinct
    with pytest.raises(InputError) as info:
        interpolate_scattered(_samples_at(three)[0], reciprocal=False)
    assert str(info.value).endswith("cannot interpolate them onto the UBO-81 grid (fewer than 4 distinct points)")


def test_qhull_refusal_quotes_the_first_80_characters_of_scipy_message():
    """Distinct samples all in the plane dphi = 30 degrees: Qhull refuses them. The message quotes
    scipy's own error (whitespace collapsed) cut at 80 characters."""
    from scipy.spatial import QhullError

    m, x = _samples_at([[10, 20, 30], [60, 20, 30], [10, 70, 30], [40, 50, 30], [25, 35, 30], [70, 65, 30]])
    with pytest.raises(QhullError) as scipy_error:
        LinearNDInterpolator(np.round(x, 9), np.ones(len(x)))
    expected = " ".join(str(scipy_error.value).split())[:80]
    assert len(expected) == 80
    with pytest.raises(InputError) as info:
        interpolate_scattered(m, reciprocal=False)
    assert str(info.value).endswith(f"cannot interpolate them onto the UBO-81 grid ({expected})")


def test_resample_of_a_path_passes_progress_to_the_reader(tmp_path, monkeypatch):
    """``resample(path, progress=True)`` reads with the progress display on, as ``load`` does
    (the readers consult brdffit.io.PROGRESS while they read)."""
    import brdffit.io
    import brdffit.io.npz

    wi, wo = ubo_pairs()
    p = brdffit.save(brdffit.Measurement(wi=wi, wo=wo, values=np.full((6561, 1), 0.3), grid="ubo81"), tmp_path / "m.npz")
    seen = []
    read = brdffit.io.npz.read

    def spy(path, **options):
        seen.append(brdffit.io.PROGRESS.get())
        return read(path, **options)

    monkeypatch.setattr(brdffit.io.npz, "read", spy)
    resample(p, progress=True)
    resample(p)
    assert seen == [True, False]
