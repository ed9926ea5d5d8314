"""Every loss of ``brdffit.fitting.losses`` against values written out with Python's ``math``
(docs/fitting.md#fitting's table: l2, cosine_l2, log, cbrt, relative), sample by sample: the weights, the clamp of
``log`` below -1, the cube root's smoothing width (1e-4 of the per-channel floor), the
linearised row weights (dg/df at the reference, squared), and ``log_rmse`` over the used samples."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from brdffit.errors import UsageError
from brdffit.fitting import losses as L

# two samples x two channels; cosines per sample; floors per channel
F = np.array([[0.5, 3.0], [2.0, -0.2]])
REF = np.array([[0.25, 1.0], [-0.1, 0.4]])
COS = np.array([[0.5], [0.8]])
SQRT_W = np.array([[2.0], [3.0]])
FLOOR = np.array([0.01, 0.5])


def _each(fn):
    """fn(i, c) for every sample i and channel c, as an array."""
    return np.array([[fn(i, c) for c in range(2)] for i in range(2)])


def _cbrt(x, eps):
    return x * (x * x + eps * eps) ** (-1.0 / 3.0)


WANT = {
    "l2": lambda i, c: F[i, c] - REF[i, c],
    "cosine_l2": lambda i, c: (F[i, c] - REF[i, c]) * COS[i, 0],
    "log": lambda i, c: math.log1p(F[i, c] * COS[i, 0]) - math.log1p(REF[i, c] * COS[i, 0]),
    "cbrt": lambda i, c: _cbrt(F[i, c] * COS[i, 0], 1e-4 * FLOOR[c]) - _cbrt(REF[i, c] * COS[i, 0], 1e-4 * FLOOR[c]),
    "relative": lambda i, c: (F[i, c] - REF[i, c]) / (abs(REF[i, c]) + FLOOR[c]),
}


@pytest.mark.parametrize("loss", sorted(WANT))
def test_residual_is_the_weighted_difference_of_the_transforms(loss):
    got = np.asarray(L.residual(loss, F, REF, COS, SQRT_W, FLOOR))
    np.testing.assert_allclose(got, _each(lambda i, c: SQRT_W[i, 0] * WANT[loss](i, c)), rtol=1e-13, atol=0)
    g_ref = L.reference_transform(loss, REF, COS, FLOOR)
    if loss == "relative":
        assert g_ref is None
    else:  # the solver's once-per-fit g(f_ref) gives the same residual
        np.testing.assert_allclose(np.asarray(L.residual(loss, F, REF, COS, SQRT_W, FLOOR, g_ref)), got, rtol=1e-15)
        # and it is what the residual subtracts: a different g_ref moves every residual by it
        moved = np.asarray(L.residual(loss, F, REF, COS, SQRT_W, FLOOR, np.asarray(g_ref) + 1.0))
        np.testing.assert_allclose(moved, got - SQRT_W, rtol=1e-12)


def test_log_clamps_below_minus_one():
    """f cos < -1 is not a reflectance: ln(1 + x) is taken at x = -1 + 1e-12, finite."""
    f = np.array([[-5.0]])
    got = float(np.asarray(L.transform("log", f, np.array([[1.0]]), None))[0, 0])
    assert got == pytest.approx(math.log1p(-1.0 + 1e-12), rel=1e-12)
    assert got == pytest.approx(math.log(1e-12), rel=1e-4)


def test_cube_root_smoothing_scales_with_the_floor():
    """Slope at 0: eps^(-2/3), eps = 1e-4 x floor; far from 0, the plain signed cube root."""
    for floor in (1.0, 1e-12):
        slope = jax.grad(lambda x: L.transform("cbrt", x, 1.0, floor))(0.0)
        assert float(slope) == pytest.approx((1e-4 * floor) ** (-2.0 / 3.0), rel=1e-12)
    far = np.asarray(L.transform("cbrt", np.array([[-8.0, 27.0]]), np.array([[1.0]]), np.array([1e-6, 1e-6])))
    np.testing.assert_allclose(far, [[-2.0, 3.0]], rtol=1e-12)


def test_linearised_row_weights_are_the_squared_slopes_at_the_reference():
    def slope(loss, i, c):
        x, cos = REF[i, c] * COS[i, 0], COS[i, 0]
        if loss == "l2":
            return 1.0
        if loss == "cosine_l2":
            return cos
        if loss == "log":
            return cos / (1.0 + x)
        if loss == "relative":
            return 1.0 / (abs(REF[i, c]) + FLOOR[c])
        e = 1e-4 * FLOOR[c]
        return cos * ((x * x + e * e) ** (-1.0 / 3.0) - (2.0 / 3.0) * x * x * (x * x + e * e) ** (-4.0 / 3.0))

    for loss in WANT:
        got = np.asarray(L.linearised_row_weights(loss, REF, COS, FLOOR))
        np.testing.assert_allclose(got, _each(lambda i, c: slope(loss, i, c) ** 2), rtol=1e-12, err_msg=loss)


def test_log_rmse_over_the_used_samples_only():
    used = np.array([[1.0], [0.0]])
    want = math.sqrt(sum((math.log1p(F[0, c] * COS[0, 0]) - math.log1p(REF[0, c] * COS[0, 0])) ** 2
                         for c in range(2)) / 2)
    assert float(L.log_rmse(F, REF, COS, used)) == pytest.approx(want, rel=1e-13)
    np.testing.assert_allclose(np.asarray(L.log_residual(F, REF, COS)), _each(WANT["log"]), rtol=1e-13)
    # one sample, one channel: the RMS of one residual is its size
    one = abs(math.log1p(F[0, 0] * COS[0, 0]) - math.log1p(REF[0, 0] * COS[0, 0]))
    assert float(L.log_rmse(F[:1, :1], REF[:1, :1], COS[:1], np.ones((1, 1)))) == pytest.approx(one, rel=1e-13)
    # no used sample: 0, not a division by zero
    assert float(L.log_rmse(F, REF, COS, np.zeros((2, 1)))) == 0.0


def test_loss_names():
    assert L.check_loss(" LOG ") == "log"
    with pytest.raises(UsageError) as caught:
        L.check_loss("nope")
    assert str(caught.value) == "unknown loss 'nope'; known: l2, cosine_l2, log, cbrt, relative"
    with pytest.raises(ValueError):
        L.transform("nope", F, COS, FLOOR)


def test_fit_metrics_against_sums_written_out():
    """``losses.values_metrics`` (every FitResult's metrics): rmse, log_rmse, rel_rmse,
    mean_rel_error and max_abs_error over the used samples (sqrt_w > 0), equally weighted, and
    each loss as the sum of its squared residuals. Sample 2 is unused and far off: it must not count."""
    from brdffit.fitting.losses import values_metrics
    from brdffit.fitting.problem import Data

    f = np.array([[0.5, 3.0], [2.0, -0.2], [100.0, 100.0]])
    ref = np.array([[0.25, 1.0], [-0.1, 0.4], [0.0, 0.0]])
    cos = np.array([[0.5], [0.8], [0.9]])
    sqrt_w = np.array([[2.0], [3.0], [0.0]])
    wi = wo = np.tile([0.0, 0.0, 1.0], (3, 1))
    got = {k: float(v) for k, v in values_metrics(f, Data(wi, wo, ref, sqrt_w, cos, FLOOR), tuple(WANT)).items()}
    used = [(i, c) for i in range(2) for c in range(2)]
    d = {ic: f[ic] - ref[ic] for ic in used}
    want = {
        "rmse": math.sqrt(sum(x * x for x in d.values()) / 4),
        "log_rmse": math.sqrt(sum((math.log1p(f[i, c] * cos[i, 0]) - math.log1p(ref[i, c] * cos[i, 0])) ** 2
                                  for i, c in used) / 4),
        "rel_rmse": math.sqrt(sum(x * x for x in d.values()) / sum(ref[ic] ** 2 for ic in used)),
        "mean_rel_error": sum(abs(d[(i, c)]) / (abs(ref[i, c]) + FLOOR[c]) for i, c in used) / 4,
        "max_abs_error": max(abs(x) for x in d.values()),
    }
    for loss, fn in WANT.items():
        want[loss] = sum((SQRT_W[i, 0] * fn(i, c)) ** 2 for i, c in used)
    assert got.keys() == want.keys()
    for k in want:
        assert got[k] == pytest.approx(want[k], rel=1e-12), k
