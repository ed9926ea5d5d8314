"""``multistart=k`` (README, docs/fitting.md#fitting): k more grid starts are solved beside the best one and the
lowest loss wins. Checked after one solver step, where starts have not converged to a common
minimum yet: the result must be the best of the k + 1 one-step solves from the k + 1 best grid
points, each run on its own with ``init=``."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit
from brdffit.fitting import init as grid_init
from brdffit.fitting.objective import objective_of
from brdffit.fitting.space import parameter_space
from brdffit.fitting.problem import prepare, resolve_model
from brdffit.grid import ubo_pairs


def best_grid_starts(mdl, loss, data, space, anchor, k):
    """The k best points of the variable-projection grid (``init.vp_grid``), scored on the rows the
    grid scores (``init.subset_rows``): what a fit's start stage ranks, computed here on its own."""
    grid = jnp.asarray(grid_init.cached_grid(mdl, space.lo, space.hi, space.free, anchor))
    rows = grid_init.take_rows(data, grid_init.subset_rows(data))
    flats, values = jax.jit(grid_init.vp_grid(objective_of(mdl, loss)))(
        grid, rows, jnp.asarray(space.lo), jnp.asarray(space.hi), jnp.asarray(space.free, dtype=bool),
        jnp.asarray(anchor))
    return np.asarray(flats)[np.argsort(np.asarray(values), kind="stable")[:k]]


@pytest.fixture(scope="module")
def measurement():
    wi, wo = ubo_pairs()
    model = brdffit.models.get("ggx")
    p = model.check_params({"kd": [0.3, 0.2, 0.1], "ks": [1.2, 1.0, 0.8], "alpha": [0.2], "f0": [0.8]})
    f = np.asarray(model.eval(p, wi, wo))
    f = f * (1 + 0.02 * np.random.default_rng(7).standard_normal(f.shape))
    return brdffit.Measurement(wi, wo, f, grid="ubo81", name="ggx, 2% noise")


def test_multistart_keeps_the_best_of_k_plus_one_starts(measurement):
    k = 3
    mdl = resolve_model("ggx", 3)
    space = parameter_space(mdl)
    anchor = space.clip(mdl.default_vector())
    starts = best_grid_starts(mdl, "log", prepare(measurement).data, space, anchor, k + 1)
    one_step = [brdffit.fit(measurement, "ggx", init={n: np.asarray(v) for n, v in mdl.unflatten(s).items()},
                            max_steps=1).loss_value for s in starts]
    # The starts differ after one step, and the best grid point is not the best one-step result:
    # a fit that solved only the best grid start would fail below.
    assert min(one_step) < one_step[0] * (1 - 1e-6)
    r = brdffit.fit(measurement, "ggx", multistart=k, max_steps=1)
    assert r.options["starts"] == k + 1
    assert r.loss_value == pytest.approx(min(one_step), rel=1e-9)
    np.testing.assert_allclose(mdl.flatten(r.start), starts[int(np.argmin(one_step))], rtol=1e-12)
    single = brdffit.fit(measurement, "ggx", multistart=0, max_steps=1)
    assert single.options["starts"] == 1 and single.loss_value == pytest.approx(one_step[0], rel=1e-9)
