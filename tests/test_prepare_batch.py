"""``problem.prepare_values`` (the texels of a BTF at once) equals ``stack`` of ``prepare`` of each
texel's Measurement: excluded samples, per-texel weight normalisation and floors included, the
directions and weights the texels share held once."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.errors import UsageError
from brdffit.fitting.problem import prepare, prepare_values, stack_data
from brdffit.grid import ubo_pairs


def test_equals_prepare_of_each_texel():
    wi, wo = ubo_pairs()
    rng = np.random.default_rng(5)
    n, N = 5, len(wi)
    values = rng.uniform(0.0, 2.0, (n, N, 3))
    values[4] = 0.0  # a black texel: its floor is the tiny positive stand-in, not 0
    values[1, 10] = np.nan  # one texel with a non-finite sample
    values[2, :, 1] *= 1e-6  # another with a dim channel (its own floor)
    values[3, 5:2000] = np.inf  # many excluded: its weights sum differs from the others
    weights = rng.uniform(0.5, 1.5, N)
    weights[:20] = 0.0
    wo = wo.copy()
    wo[30, 2] = -0.1  # a view below the horizon
    wi = wi.copy()
    wi[40] = (1.0, 0.0, 0.0)  # a light exactly on the horizon: excluded, as below it
    wi[60] = (np.sqrt(1.0 - 1e-18), 0.0, 1e-9)  # a grazing light: used, its cosine clipped to 1e-7
    wo[50] = (0.0, 1.0, 0.0)  # a view exactly on the horizon
    got = prepare_values(values, wi, wo, weights)
    want = stack_data([prepare(brdffit.Measurement(wi, wo, values[k], weights=weights, name=f"t{k}")).data for k in range(n)])
    for field, a, b in zip(got._fields, got, want):
        assert a.shape == b.shape, field
        np.testing.assert_allclose(a, b, rtol=1e-15, atol=0)
    assert got.wi.shape == (N, 3) and got.sqrt_w.shape == (n, N, 1)  # directions once; weights per texel here
    assert np.all(got.sqrt_w[:, [30, 40, 50]] == 0.0)  # excluded samples weigh nothing


def test_texels_with_every_sample_share_their_weights():
    wi, wo = ubo_pairs()
    values = np.random.default_rng(1).uniform(0.0, 2.0, (3, len(wi), 3))
    got = prepare_values(values, wi, wo, np.ones(len(wi)))
    assert got.sqrt_w.shape == (len(wi), 1) and got.ref.shape == values.shape and got.floor.shape == (3, 3)


def test_float32_values_are_kept_and_the_rest_is_the_float64_of_prepare():
    """A BTF tile arrives as float32 (its cache): the values stay so (half the memory; the solve converts
    them exactly), everything else is prepare's float64."""
    wi, wo = ubo_pairs()
    values = np.random.default_rng(2).uniform(0.0, 2.0, (2, len(wi), 3))
    f32 = [np.asarray(a, np.float32) for a in (values, wi, wo, np.ones(len(wi)))]
    got = prepare_values(*f32)
    want = prepare(brdffit.Measurement(*(np.asarray(a, np.float64) for a in f32[1:3]), np.asarray(f32[0][1], np.float64),
                                       name="t1")).data
    for field, a, b in zip(got._fields, got, want):
        assert a.dtype == (np.float32 if field == "ref" else np.float64), field
        np.testing.assert_allclose(a[1] if field in ("ref", "floor") else a, np.asarray(b), rtol=1e-15, atol=0)


def test_a_texel_without_valid_samples_is_a_usage_error():
    wi, wo = ubo_pairs()
    values = np.ones((2, len(wi), 3))
    values[1] = np.nan
    with pytest.raises(UsageError) as caught:
        prepare_values(values, wi, wo, np.ones(len(wi)), name="tile")
    assert str(caught.value) == ("tile[1]: no valid samples to fit (all have weight 0, non-finite values or lie "
                                 "below the horizon)")


def test_the_default_name_is_batch():
    wi, wo = ubo_pairs()
    values = np.full((2, len(wi), 3), np.nan)
    with pytest.raises(UsageError, match=r"^batch\[0\]: no valid samples"):
        prepare_values(values, wi, wo, np.ones(len(wi)))


def test_the_accelerator_s_preparation_equals_the_host_s():
    """``prepare_values_device`` (masks and floors computed where the values are, for an accelerator)
    gives prepare_values' arrays: the same masks and values, the floors to rounding (their sums in
    another order)."""
    import jax.numpy as jnp

    from brdffit.fitting.problem import prepare_values_device

    wi, wo = ubo_pairs()
    rng = np.random.default_rng(7)
    values = rng.uniform(0.0, 2.0, (4, len(wi), 3)).astype(np.float32)
    for case in ("all", "masked"):
        v = values.copy()
        if case == "masked":
            v[2, 100] = np.nan  # one texel leaves out a sample the others use: weights per texel
        want = prepare_values(v, wi, wo, np.ones(len(wi)))
        got = prepare_values_device(jnp.asarray(v), wi, wo, np.ones(len(wi)))
        for field, a, b in zip(want._fields, got, want):
            assert np.shape(a) == np.shape(b), (case, field)
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-13, atol=0, err_msg=f"{case} {field}")
    v = values.copy()
    v[1] = np.nan
    with pytest.raises(UsageError, match=r"^tile\[1\]: no valid samples"):
        prepare_values_device(jnp.asarray(v), wi, wo, np.ones(len(wi)), name="tile")


def test_without_floors_everything_else_is_the_same():
    """``floors=False`` (a BTF fitted under a loss that does not read the floors): the floors NaN, every other
    field as with them."""
    wi, wo = ubo_pairs()
    values = np.random.default_rng(2).uniform(0.0, 2.0, (3, len(wi), 3))
    values[1, 10] = np.nan
    with_floors = prepare_values(values.copy(), wi, wo, np.ones(len(wi)))
    without = prepare_values(values.copy(), wi, wo, np.ones(len(wi)), floors=False)
    assert np.isnan(without.floor).all() and np.isfinite(with_floors.floor).all()
    for field, a, b in zip(with_floors._fields[:-1], with_floors[:-1], without[:-1]):
        np.testing.assert_array_equal(a, b, err_msg=field)


@pytest.mark.parametrize("loss", ["l2", "cosine_l2", "log", "cbrt", "relative"])
def test_the_losses_that_read_the_floor_are_those_declared(loss):
    """``losses.READS_FLOOR`` holds exactly the losses whose residual, reference transform or linearised row weights
    change with the floor: the others' are the same with a NaN floor (what ``prepare_values(floors=False)`` leaves)."""
    import jax.numpy as jnp

    from brdffit.fitting import losses as L

    rng = np.random.default_rng(3)
    f, ref = rng.uniform(0.0, 2.0, (50, 3)), rng.uniform(0.0, 2.0, (50, 3))
    cos_i, sqrt_w = rng.uniform(0.1, 1.0, (50, 1)), np.full((50, 1), 0.1)

    def terms(floor):
        floor = jnp.full((3,), floor)
        g = L.reference_transform(loss, ref, cos_i, floor)
        return [np.asarray(L.residual(loss, f, ref, cos_i, sqrt_w, floor)),
                np.asarray(L.linearised_row_weights(loss, ref, cos_i, floor)), None if g is None else np.asarray(g)]

    same = all(a is None and b is None or np.array_equal(a, b) for a, b in zip(terms(0.01), terms(np.nan)))
    assert same == (loss not in L.READS_FLOOR)
