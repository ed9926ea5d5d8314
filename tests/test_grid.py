import numpy as np
import pytest

import brdffit
from brdffit.grid import cartesian_to_spherical, ubo_angles_deg, ubo_index


def test_ubo_angles_follow_spec_rings():
    a = ubo_angles_deg()
    assert a.shape == (81, 2)
    counts = {t: int(np.sum(a[:, 0] == t)) for t in (0, 15, 30, 45, 60, 75)}
    assert counts == {0: 1, 15: 6, 30: 12, 45: 18, 60: 20, 75: 24}
    # ordered by theta then phi, phi starts at 0 in every ring
    assert np.all(np.diff(a[:, 0]) >= 0)
    for t, step in zip((15, 30, 45, 60, 75), (60, 30, 20, 18, 15)):
        ring = a[a[:, 0] == t, 1]
        np.testing.assert_array_equal(ring, np.arange(0, 360, step))
    np.testing.assert_allclose(brdffit.ubo_angles(), np.deg2rad(a))


def test_ubo_directions_are_unit_and_match_angles():
    d = brdffit.ubo_directions()
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-15)
    theta, phi = cartesian_to_spherical(d)
    a = brdffit.ubo_angles()
    np.testing.assert_allclose(theta, a[:, 0], atol=1e-12)
    np.testing.assert_allclose(np.where(a[:, 0] > 0, phi, 0.0), a[:, 1], atol=1e-12)
    # phi counter-clockwise from x seen from above: phi = 90 deg points along +y
    i = ubo_index(45, 80)
    assert d[i, 1] > 0.69 and abs(d[i, 0]) < 0.13


def test_ubo_pairs_order_light_major():
    wi, wo = brdffit.ubo_pairs()
    d = brdffit.ubo_directions()
    assert wi.shape == wo.shape == (6561, 3)
    for light, view in [(0, 0), (3, 77), (80, 1), (45, 45)]:
        k = light * 81 + view
        np.testing.assert_array_equal(wi[k], d[light])
        np.testing.assert_array_equal(wo[k], d[view])


def test_ubo_index_rejects_off_grid_direction():
    assert ubo_index(0, 123) == 0
    with pytest.raises(KeyError):
        ubo_index(15, 30)


def test_measurement_is_a_pytree_with_static_metadata():
    import jax

    wi, wo = brdffit.ubo_pairs()
    m = brdffit.Measurement(wi=wi, wo=wo, values=np.ones((6561, 3)), grid="ubo81", name="ones", extra={"a": 1})
    leaves = jax.tree_util.tree_leaves(m)
    assert len(leaves) == 4  # wi, wo, values, weights
    assert m.table().shape == (81, 81, 3)
    assert m.meta["a"] == 1 and m.meta["grid"] == "ubo81"
    assert m.valid_mask().all()
    with pytest.raises(ValueError):
        brdffit.Measurement(wi=wi[:10], wo=wo, values=np.ones((6561, 3)))
    with pytest.raises(ValueError):
        m.replace(grid=None).table()
