"""The tabulated BSDF of a UBO-81 measurement: exact at the grid, linear between, renders right."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit import Measurement, models
from brdffit.grid import spherical_to_cartesian, ubo_directions, ubo_index, ubo_pairs
from brdffit.render import render_sphere
from brdffit.render.bsdf import as_source
from brdffit.render.tabulated import UboInterpolator, direction_weights


def ubo_measurement(values, weights=None) -> Measurement:
    wi, wo = ubo_pairs()
    return Measurement(wi, wo, values, weights, name="synthetic", grid="ubo81")


def random_table(seed=0) -> np.ndarray:
    return np.random.default_rng(seed).lognormal(0.0, 1.0, (6561, 3))


def test_reproduces_table_at_grid_pairs():
    values = random_table()
    src = as_source(ubo_measurement(values))
    wi, wo = ubo_pairs()
    got = src.brdf(wi, wo)
    np.testing.assert_allclose(got, values, rtol=1e-6, atol=0)
    # also from directions recomputed from integer-degree angles (round-off in theta, phi)
    ang = np.deg2rad(brdffit.grid.ubo_angles_deg())
    d = spherical_to_cartesian(ang[:, 0], ang[:, 1])
    got2 = src.brdf(np.repeat(d, 81, 0), np.tile(d, (81, 1)))
    np.testing.assert_allclose(got2, values, rtol=1e-6, atol=0)


def test_interpolation_scheme():
    d = ubo_directions()
    # halfway in phi within the 30-degree ring: the mean of the two neighbours, nothing else
    mid = spherical_to_cartesian(np.deg2rad(30), np.deg2rad(15))
    idx, w = direction_weights(mid[None])
    pairs = {int(i): float(x) for i, x in zip(idx[0], w[0]) if x > 1e-12}
    assert pairs.keys() == {ubo_index(30, 0), ubo_index(30, 30)}
    np.testing.assert_allclose(list(pairs.values()), [0.5, 0.5])
    # between rings 15 and 30 at phi = 0: 2/3 and 1/3 by theta
    between = spherical_to_cartesian(np.deg2rad(20), 0.0)
    idx, w = direction_weights(between[None])
    pairs = {int(i): float(x) for i, x in zip(idx[0], w[0]) if x > 1e-12}
    np.testing.assert_allclose([pairs[ubo_index(15, 0)], pairs[ubo_index(30, 0)]], [2 / 3, 1 / 3])
    # wrap-around in phi: 355 degrees on the 75-degree ring lies between 345 and 0
    wrap = spherical_to_cartesian(np.deg2rad(75), np.deg2rad(352.5))
    idx, w = direction_weights(wrap[None])
    pairs = {int(i): float(x) for i, x in zip(idx[0], w[0]) if x > 1e-12}
    assert set(pairs) == {ubo_index(75, 345), ubo_index(75, 0)}
    # beyond 75 degrees: the 75 ring as is; weights always sum to 1
    low = spherical_to_cartesian(np.deg2rad([80, 89.9, 5]), np.deg2rad([10, 200, 77]))
    _, w = direction_weights(low)
    np.testing.assert_allclose(w.sum(1), 1.0)
    # a table linear in the light's cos(theta) along phi = 0 is reproduced at 22.5 degrees as the
    # linear blend of its two rings
    values = np.zeros((81, 81, 1))
    values[:, 0, 0] = np.cos(np.arccos(d[:, 2]))
    interp = UboInterpolator(values)
    got = interp(spherical_to_cartesian(np.deg2rad(22.5), 0.0)[None], d[:1])[0, 0]
    np.testing.assert_allclose(got, 0.5 * (np.cos(np.deg2rad(15)) + np.cos(np.deg2rad(30))), rtol=1e-12)


def test_invalid_entries_are_skipped():
    values = random_table(1)
    weights = np.ones(6561)
    bad = 3 * 81 + 5
    weights[bad] = 0.0
    values[bad + 1] = np.nan
    interp = UboInterpolator.from_measurement(ubo_measurement(values, weights))
    wi, wo = ubo_pairs()
    got = interp(wi, wo)
    assert np.all(np.isfinite(got))
    ok = np.ones(6561, bool)
    ok[[bad, bad + 1]] = False
    np.testing.assert_allclose(got[ok], values[ok], rtol=1e-6)


def test_scattered_measurement_is_refused():
    wi, wo = ubo_pairs()
    m = Measurement(wi[:10], wo[:10], np.ones((10, 3)))
    with pytest.raises(ValueError, match="UBO-81"):
        as_source(m)


def test_table_of_a_smooth_model_renders_close_to_the_model():
    """A UBO table sampled from a broad model renders close to the model itself (interpolation
    error only), and renders finite, non-negative images."""
    params = {"kd": [0.4, 0.3, 0.2], "ks": 0.2, "alpha": 0.6, "f0": 0.05}
    model = models.get("ggx")
    wi, wo = ubo_pairs()
    values = np.asarray(model.eval(model.check_params(params), wi, wo))
    lights = np.deg2rad([[0, 0], [40, 60]])
    table = render_sphere(ubo_measurement(values), lights, size=32, spp=4)
    exact = render_sphere(("ggx", params), lights, size=32, spp=4)
    assert np.all(np.isfinite(table)) and np.all(table >= 0)
    c = (np.arange(32) + 0.5) / 16 - 1
    x, y = np.meshgrid(c, -c)
    m = np.broadcast_to((x * x + y * y < 0.7**2)[None, ..., None], table.shape)
    assert np.abs(table - exact)[m].sum() / exact[m].sum() < 0.05
