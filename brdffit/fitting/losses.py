"""Fitting losses (docs/fitting.md#fitting): each is a per-sample transform g applied to model and reference alike.

The residual of sample k, channel c is ``sqrt(w_k) * (g(f_model) - g(f_ref))``, with the weights
normalised so that the sum of squared residuals is the weighted *mean* squared difference (the
loss value does not grow with the number of samples, so tolerances mean the same on every data
set). ``relative`` is the exception: it divides the difference by the reference, not a transform.

| name        | residual                                                    | reference              |
| ----------- | ----------------------------------------------------------- | ---------------------- |
| `l2`        | f - f_ref                                                   |                        |
| `cosine_l2` | (f - f_ref) cos th_i                                        | Ngan et al. 2005       |
| `log`       | ln(1 + f cos th_i) - ln(1 + f_ref cos th_i)                 | Löw et al. 2012        |
| `cbrt`      | cbrt(f cos th_i) - cbrt(f_ref cos th_i) (sign-preserving)   | Forés et al. 2012      |
| `relative`  | (f - f_ref) / (|f_ref| + floor), floor = 1 % of mean |f_ref| per channel |      |

Measured data can be slightly negative (RGB conversion of spectral data near a specular peak):
every transform is defined there. ``log`` is ``log1p(f cos)`` with f cos clamped above -1 + 1e-12
(f cos < -1 is not a reflectance); ``log1p`` keeps full relative precision for tiny values.
``cbrt`` is odd and smoothed near zero, where the plain cube root has an infinite slope that would
hand a Gauss-Newton solver an infinite Jacobian.

Data scale. ``floor`` (per channel) is 1 % of the mean |f_ref|, and the cube root's smoothing
width is CBRT_EPS times ``floor``: both scale with the data, so ``l2``, ``cosine_l2``, ``cbrt``
and ``relative`` fits of a table multiplied by any factor (1e-12) are the original fit scaled
(with the solver's relative tolerances, see ``solve``). ``log`` has a unit by its definition
(1/sr: ln(1 + f cos) is ~ f cos for f cos << 1 and ~ ln(f cos) for f cos >> 1), so a scaled
table is a different (more ``cosine_l2``-like) problem for it; it still converges in the same way.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from .._fit_defaults import LOSSES  # noqa: F401 (re-exported)

#: The losses whose residual reads the loss floor (``Data.floor``): the others ignore it, so a batch fitted with one
#: of those need not compute it (``problem.prepare_values(..., floors=False)``: a BTF's texels).
READS_FLOOR = ("cbrt", "relative")

#: Smoothing width of the cube root at zero, relative to ``floor`` (1 % of the mean |f_ref|):
#: 1e-6 of the mean value.
CBRT_EPS = 1e-4


def _cbrt(x, eps):
    # Odd and smooth: x (x^2 + eps^2)^(-1/3) = sign(x) |x|^(1/3) for |x| >> eps, with the finite
    # slope eps^(-2/3) at 0 (the plain cube root's slope there is infinite).
    return x * (x * x + eps**2) ** (-1.0 / 3.0)


#: fdlibm's minimax coefficients for log(1 + s^2 ...) on |s| <= 0.1716 (e_log.c, Sun Microsystems 1993).
_LG = (6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01, 2.222219843214978396e-01,
       1.818357216161805012e-01, 1.531383769920937332e-01, 1.479819860511658591e-01)
_LN2_HI, _LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10


@jax.custom_jvp
def log1p(x):
    """ln(1 + x) for x > -1, within 2 ulp: ``jnp.log1p``, but in float64 on a CPU fdlibm's algorithm
    written out, which XLA vectorises (its own float64 log is a scalar call per element: 3.8 against
    2.1 ns per value, measured here; the log loss's largest cost per step). The argument is reduced
    with the exponent of 1 + x to m in [sqrt(1/2), sqrt(2)) (near 0: x itself, exact), then
    ln(m) = 2 atanh(s), s = (m - 1)/(m + 1), by fdlibm's minimax polynomial in s^2. Its derivative
    is 1/(1 + x) (the bit manipulation has none)."""
    if x.dtype != jnp.float64 or jax.default_backend() != "cpu":
        return jnp.log1p(x)
    u = 1.0 + x
    bits = jax.lax.bitcast_convert_type(u, jnp.int64)
    e = (bits >> 52) - 1023
    m = jax.lax.bitcast_convert_type((bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000, jnp.float64)  # [1, 2)
    high = m > 1.4142135623730951
    m = jnp.where(high, 0.5 * m, m)
    e = jnp.where(high, e + 1, e)
    near = (x > -0.2928932188134524) & (x < 0.41421356237309503)  # m - 1 would lose what 1 + x rounded
    f = jnp.where(near, x, m - 1.0)
    e = jnp.where(near, 0, e).astype(x.dtype)
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG[1] + w * (_LG[3] + w * _LG[5]))
    t2 = z * (_LG[0] + w * (_LG[2] + w * (_LG[4] + w * _LG[6])))
    half_f2 = 0.5 * f * f
    return e * _LN2_HI + ((f - (half_f2 - s * (half_f2 + t2 + t1))) + e * _LN2_LO)


@log1p.defjvp
def _log1p_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    return log1p(x), dx / (1.0 + x)


def check_loss(loss: str) -> str:
    from ..errors import UsageError

    key = str(loss).strip().lower()
    if key not in LOSSES:
        raise UsageError(f"unknown loss {loss!r}; known: {', '.join(LOSSES)}")
    return key


def transform(loss: str, f, cos_i, floor):
    """g(f) for the transform losses; for ``relative``, f / (|f_ref| + floor) is done by ``residual``.

    f: (N, C); cos_i: (N, 1); floor: (C,).
    """
    if loss == "l2" or loss == "relative":
        return f
    if loss == "cosine_l2":
        return f * cos_i
    if loss == "log":
        return log1p(jnp.maximum(f * cos_i, -1.0 + 1e-12))
    if loss == "cbrt":
        return _cbrt(f * cos_i, CBRT_EPS * floor)
    raise ValueError(loss)


def log_residual(f, ref, cos_i):
    """ln(1 + f cos th_i) - ln(1 + f_ref cos th_i): the ``log`` loss's residual before weighting."""
    return transform("log", f, cos_i, None) - transform("log", ref, cos_i, None)


def log_rmse(f, ref, cos_i, used):
    """The one ``log_rmse`` (docs/fitting.md#fitting): RMS of :func:`log_residual` over the used samples (``used``
    (N, 1) or (..., 1) in {0, 1}) and every channel, equally weighted. Fit metrics, compare rows,
    validate's metrics.json and the table figure all call this."""
    ld = log_residual(f, ref, cos_i) * used
    n = jnp.sum(jnp.broadcast_to(used, ld.shape))
    return jnp.sqrt(jnp.sum(ld**2) / jnp.maximum(n, 1))


def masked_log_residual(f, ref, cos_i, used):
    """(:func:`log_residual`, :func:`log_rmse` over ``used``) for the table figures: samples
    outside ``used`` enter neither, whatever they hold (NaN for an excluded measurement)."""
    inside = used > 0
    return log_residual(f, ref, cos_i), log_rmse(jnp.where(inside, f, 0.0), jnp.where(inside, ref, 0.0), cos_i, used)


def reference_transform(loss: str, ref, cos_i, floor):
    """g(f_ref) of a transform loss (None for ``relative``): the same at every step of a fit, so a
    solver computes it once and hands it to :func:`residual`."""
    return None if loss == "relative" else transform(loss, ref, cos_i, floor)


def residual(loss: str, f, ref, cos_i, sqrt_w, floor, g_ref=None):
    """Per-sample, per-channel residuals (N, C) of model values f against reference values ref.
    ``g_ref``: :func:`reference_transform` of ref, when the caller has it."""
    if loss == "relative":
        d = (f - ref) / (jnp.abs(ref) + floor)
    else:
        d = transform(loss, f, cos_i, floor) - (transform(loss, ref, cos_i, floor) if g_ref is None else g_ref)
    return sqrt_w * d


def linearised_row_weights(loss: str, ref, cos_i, floor):
    """(dg/df at the reference)^2, (N, C): the weights of the weighted linear least squares that
    approximates this loss near the reference (used by the variable-projection initialisation)."""
    if loss == "relative":
        return 1.0 / (jnp.abs(ref) + floor) ** 2
    one = jnp.ones_like(ref)
    import jax

    _, slope = jax.jvp(lambda f: transform(loss, f, cos_i, floor), (ref,), (one,))
    return slope**2


# -- the values of every loss and the metrics of model values (a FitResult's, compare's) -----------------

@functools.lru_cache(maxsize=None)
def loss_values_fn(model):
    """Compiled: flat params, data -> every loss's value (sum of squared normalised residuals)."""
    return jax.jit(loss_values(model))


@functools.lru_cache(maxsize=None)
def loss_values(model):
    """flat params, data -> every loss's value and the metrics (jit-able)."""

    def fn(v, data, losses=LOSSES):
        wi, wo = data[0], data[1]
        return values_metrics(model.flat.f_r(v, wi, wo), data, losses)

    return fn


def values_metrics(f, data, losses=LOSSES) -> dict:
    """The value of each loss in ``losses`` and the metrics of model values f (N, C) against the
    data (jit-able). A fit reports its own loss only: the cube root of the ``cbrt`` loss alone
    cost more than a solver step (XLA's ``pow`` on 2 x 19,683 values, ~1 ms on UBO-81)."""
    wi, wo, ref, sqrt_w, cos_i, floor = data
    out = {name: jnp.sum(residual(name, f, ref, cos_i, sqrt_w, floor) ** 2) for name in losses}
    # Metrics on f itself, over used samples (sqrt_w > 0), equally weighted.
    used = (sqrt_w > 0).astype(f.dtype)
    n = jnp.sum(used) * f.shape[1]
    d = (f - ref) * used
    out["rmse"] = jnp.sqrt(jnp.sum(d**2) / n)
    out["log_rmse"] = log_rmse(f, ref, cos_i, used)
    out["rel_rmse"] = jnp.sqrt(jnp.sum(d**2) / jnp.maximum(jnp.sum((ref * used) ** 2), 1e-300))
    out["mean_rel_error"] = jnp.sum(jnp.abs(d) / (jnp.abs(ref) + floor)) / n
    out["max_abs_error"] = jnp.max(jnp.abs(d))
    return out


def evaluate(model, params, data) -> dict[str, float]:
    """Every loss's value and the metrics of ``model`` at ``params`` on ``data`` (``problem.Data``), as floats
    (what ``compare`` reports beside a fit's own loss)."""
    v = model.flatten(params)
    return {k: float(x) for k, x in loss_values_fn(model)(v, data).items()}
