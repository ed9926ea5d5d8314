"""Model.flat: the parameter table read once into the flat vector a solver moves (brdffit.models.flat).

The expected layout is read here from the declared ``Param`` entries themselves (name, channels, bounds,
physical range, default, linear), not from the code under test; the formula of a flat vector is held against
``Model.eval`` of a params dict sliced here by hand.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from brdffit.models import get, names

MODELS = [*names(), "lambert+ggx+ggx", "lafortune", "ggx+ward"]


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("channels", [3, 1])
def test_the_flat_view_is_the_declared_table_in_its_order(name, channels):
    model = get(name).with_channels(channels)
    flat = model.flat
    start = 0
    for p, (slice_name, s) in zip(model.params, flat.slices, strict=True):
        n = channels if p.channels == 3 else 1
        assert slice_name == p.name and (s.start, s.stop) == (start, start + n)
        for column, want in ((flat.lo, p.lower), (flat.hi, p.upper), (flat.physical_lo, p.physical[0]),
                             (flat.physical_hi, p.physical[1]), (flat.defaults, p.default), (flat.linear, p.linear)):
            assert np.array_equal(column[s], np.full(n, want)), (p.name, want)
        start += n
    assert start == model.n_free
    for column in (flat.lo, flat.hi, flat.physical_lo, flat.physical_hi, flat.defaults, flat.linear):
        assert column.shape == (model.n_free,) and not column.flags.writeable  # shared by every fit of the model
    assert flat.bounds(physical=True) == (flat.physical_lo, flat.physical_hi)


@pytest.mark.parametrize("name", ["ggx", "lambert+ggx+ggx", "oren_nayar", "mitsuba:principled"])
def test_the_formula_of_a_flat_vector_is_the_formula_of_its_params(name):
    model = get(name)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(2, 200, 3))
    d[..., 2] = np.abs(d[..., 2]) + 0.05
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    lo, hi = model.flat.physical_lo, model.flat.physical_hi
    v = lo + (hi - lo) * rng.uniform(0.1, 0.9, size=lo.shape)
    params, i = {}, 0
    for p in model.params:
        n = model.size(p)
        params[p.name] = v[i : i + n]
        i += n
    want = np.asarray(model.eval(params, d[0], d[1]))
    assert np.array_equal(np.asarray(model.flat.f_r(v, d[0], d[1])), want)


def test_the_flat_view_is_no_part_of_a_models_identity():
    # A model's equality and hash (the compiled programs' cache keys) stay those of its table and formula.
    ggx = get("ggx")
    again = dataclasses.replace(ggx)  # the same table and formula, a view of its own
    assert again.flat is not ggx.flat and again == ggx and hash(again) == hash(ggx)
    assert ggx.with_channels(1) != ggx and ggx.with_channels(1).flat.lo.shape == (4,)
    assert "flat" not in repr(ggx)
