"""The least-squares problem's data, shared by every solver: a measurement as arrays (``Data``), a batch of
them, the model resolved for their channels, the unit a fit is solved in (its residuals: ``objective``).

The measurement enters compiled code only as *arguments* (``Data``), never as constants, so one
compiled solver serves every data set of the same shape (all UBO-81 tables, all BTF texels).
Excluded samples stay in the arrays (shapes do not change) with weight 0 and harmless
directions / values, so no NaN can leak from them into a residual or a gradient.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import UsageError
from ..measurement import Measurement
from ..models import get as get_model
from ..models.base import Model

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array


class Data(NamedTuple):
    """One fit's table as arrays (a pytree: JAX maps and batches it as a tuple). Rows are the used
    samples' order; with a leading batch axis in ``fit_batch``."""

    wi: Array  # (N, 3) light directions
    wo: Array  # (N, 3) view directions
    ref: Array  # (N, C) measured f_r
    sqrt_w: Array  # (N, 1) square root of each sample's weight (0: excluded)
    cos_i: Array  # (N, 1) cos(theta_i), clipped at the horizon
    floor: Array  # (C,) 1 % of the mean |f_r| per channel: the relative and log losses' floor


@dataclasses.dataclass(frozen=True)
class Prepared:
    data: Data
    n_used: int
    n_excluded: int
    excluded: dict[str, int]  # reason -> count (a sample may have several reasons)
    channels: int
    used: np.ndarray  # (N,) bool: the samples the fit uses


def resolve_model(model, channels: int) -> Model:
    try:
        m = get_model(model) if not isinstance(model, Model) else model
    except KeyError as exc:
        raise UsageError(str(exc.args[0]) if exc.args else str(exc)) from None
    return m if m.channels == channels else m.with_channels(channels)


def _exclusions(values, w, wi, wo) -> dict[str, np.ndarray]:
    """Reason -> (N,) bool: the samples a fit may not use, by reason (``Measurement.valid_mask``
    is their complement)."""
    return {
        "weight 0": ~(w > 0),
        "non-finite value": ~_rows_all(np.isfinite(values)),
        "light below horizon": ~(wi[:, 2] > 0),
        "view below horizon": ~(wo[:, 2] > 0),
    }


def _rows_all(a: np.ndarray) -> np.ndarray:
    """``np.all(a, axis=-1)`` of a bool array with a short last axis (channels), an entry at a time:
    NumPy's reduction over a short last axis is ~4x slower (measured: 179 against 40 us on 6,561 x 3)."""
    out = a[..., 0].copy()
    for c in range(1, a.shape[-1]):
        out &= a[..., c]
    return out


def _rows_replaced(a: np.ndarray, keep: np.ndarray, stand_in) -> np.ndarray:
    """``np.where(keep[..., None], a, stand_in)`` as a float64 copy with the few excluded rows
    overwritten; ``keep`` has ``a``'s leading axes (the broadcasting ``np.where`` took 160 us on
    6,561 x 3, this 24 us)."""
    out = np.array(a, dtype=np.float64)
    out[~keep] = stand_in
    return out


def _refuse_infinite(w: np.ndarray, what: str) -> None:
    """An infinite weight would make every other sample's weight 0 and the residuals NaN (docs/fitting.md#hostile-but-valid-data:
    the fit then wrote NaN parameters): one clear line instead. NaN and negative weights keep their
    meaning, "leave this sample out"."""
    bad = np.isinf(w) & (w > 0)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise UsageError(f"{what}: {int(bad.sum())} sample(s) have an infinite weight (the first: sample {first}); "
                         "weights must be finite (0 leaves a sample out)")


def prepare(m: Measurement, weights=None) -> Prepared:
    """Arrays for the compiled residual; excluded samples get weight 0 and safe stand-ins."""
    if not isinstance(m, Measurement):
        raise UsageError(f"expected a brdffit.Measurement, got {type(m).__name__}")
    # Each field read once (a Measurement's fields are JAX arrays: each NumPy view is a call into JAX).
    values = np.asarray(m.values, dtype=np.float64)
    wi, wo = np.asarray(m.wi, dtype=np.float64), np.asarray(m.wo, dtype=np.float64)
    w = np.asarray(m.weights, dtype=np.float64)
    _refuse_infinite(w, f"{m.name}: weights")
    excluded = _exclusions(values, w, wi, wo)
    mask = ~np.logical_or.reduce(list(excluded.values()))
    if weights is not None:
        extra = np.asarray(weights, dtype=np.float64)
        if extra.shape != w.shape:
            raise UsageError(f"weights has shape {extra.shape}, expected {w.shape}")
        _refuse_infinite(extra, f"{m.name}: weights=")
        w = w * extra
        # counted by reason like the Measurement's own exclusions (a scene that never looks there)
        excluded["weight 0 in weights="] = ~(np.isfinite(extra) & (extra > 0))
        mask &= ~excluded["weight 0 in weights="]
    n_used = int(mask.sum())
    if n_used == 0:
        raise UsageError(f"{m.name}: no valid samples to fit (all have weight 0, non-finite values or lie below the horizon)")
    c = values.shape[1]
    # Directions are replaced only where they are unusable themselves (a sample left out for its value or
    # weight keeps its direction): so the rows of tables that share directions stay equal (``stack``).
    wi, wo = _usable_directions(wi, wo)
    ref = _rows_replaced(values, mask, 0.0)  # the mask holds finite rows only
    w = np.where(mask, w, 0.0)
    w_sum = w.sum()
    # Normalise: sum of squared residuals = weighted mean over samples and channels.
    sqrt_w = np.sqrt(w / (w_sum * c))[:, None]
    cos_i = np.clip(wi[:, 2:3], 1e-7, 1.0)
    # as prepare_stack (tested equal to the last bit: the same einsum loop, no BLAS threads that could
    # change the order of the sum); 2.5x faster than multiplying and summing
    mean_abs = np.einsum("n,nc->c", w, np.abs(ref)) / w_sum
    # Relative to the data (see losses: a table scaled by 1e-12 fits as the original).
    floor = np.maximum(0.01 * mean_abs, np.finfo(np.float64).tiny * 1e10)
    reasons = {k: n for k, n in ((k, int(v.sum())) for k, v in excluded.items()) if n}
    # NumPy arrays: a compiled call takes them as they are (one transfer with the call); an eager
    # jax.device_put per array cost ~0.25 ms each, and jnp.asarray compiles a copy program per shape.
    data = Data(wi, wo, ref, sqrt_w, cos_i, floor)
    return Prepared(data, n_used, int(len(mask) - n_used), reasons, c, mask)


def _usable_directions(wi: np.ndarray, wo: np.ndarray):
    """``wi``, ``wo`` as float64 with the rows that no formula may see (not finite, below the horizon)
    replaced by the normal (they have weight 0): no NaN can leak from them into a residual or gradient."""
    ok = _rows_all(np.isfinite(wi)) & _rows_all(np.isfinite(wo)) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
    up = np.array([0.0, 0.0, 1.0])
    return _rows_replaced(wi, ok, up), _rows_replaced(wo, ok, up)


#: Tables per block of :func:`prepare_values` (its float64 work arrays stay this small).
_BLOCK = 256


def prepare_values(values, wi, wo, weights, name: str = "batch", own: bool = False, floors: bool = True) -> Data:
    """:func:`prepare` of n tables that share their directions and weights (the texels of a BTF), at once:
    ``values`` (n, N, C), kept in their own precision (a BTF's float32: the solve converts) -> the batch's
    ``Data``: ``ref`` (n, N, C) and ``floor`` (n, C) per table; the directions, cosines and weights held once
    (``sqrt_w`` per table only where some table leaves out a sample the others use). Equal to :func:`stack`
    of ``prepare`` of each table (tested), without a Measurement per table. ``own``: the caller hands
    ``values`` over (a float32 or float64 array): its left-out samples are zeroed in place, no copy.
    ``floors=False``: the loss floors are left NaN, not computed, for a loss that does not read them
    (``losses.READS_FLOOR``): their weighted mean of |values| took 0.06 of the 0.79 ms that a BTF texel's
    preparation and solve take on one core here."""
    values = np.asarray(values)
    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    w0 = np.asarray(weights, dtype=np.float64)
    n, N, c = values.shape
    shared = (w0 > 0) & (wi[:, 2] > 0) & (wo[:, 2] > 0) & _rows_all(np.isfinite(wi)) & _rows_all(np.isfinite(wo))
    keep = values.dtype in (np.float32, np.float64)
    ref = values if own and keep else np.array(values, dtype=values.dtype if keep else np.float64)
    masks, floor = np.empty((n, N), bool), np.full((n, c), np.nan)
    for s in range(0, n, _BLOCK):  # blocks: the float64 work arrays stay small whatever n is
        block = ref[s : s + _BLOCK]
        # One pass finds the tables with a non-finite value (their sum is not finite); only those are
        # looked at sample by sample.
        odd = ~np.isfinite(np.add.reduce(block.reshape(len(block), -1), axis=1, dtype=np.float64))
        mask = np.broadcast_to(shared, (len(block), N)).copy()
        if odd.any():
            mask[odd] &= _rows_all(np.isfinite(block[odd]))
            rows = block[odd]
            rows[~mask[odd]] = 0.0  # the mask holds finite rows only
            block[odd] = rows
        if not shared.all():
            block[:, ~shared] = 0.0
        w = np.where(mask, w0[None, :], 0.0)
        total = w.sum(axis=1, keepdims=True)
        if np.any(total == 0):
            raise UsageError(f"{name}[{s + int(np.argmin(total[:, 0]))}]: no valid samples to fit (all have weight 0, "
                             "non-finite values or lie below the horizon)")
        if floors:  # as prepare (tested equal to the last bit: the same einsum loop, the float32 values cast in it)
            mean_abs = np.einsum("kn,knc->kc", w, np.abs(block), dtype=np.float64) / total
            floor[s : s + _BLOCK] = np.maximum(0.01 * mean_abs, np.finfo(np.float64).tiny * 1e10)
        masks[s : s + _BLOCK] = mask
    same = bool(np.all(masks == masks[:1]))
    w = np.where(masks[:1] if same else masks, w0[None, :], 0.0)
    sqrt_w = np.sqrt(w / (w.sum(axis=1, keepdims=True) * c))[..., None]
    wi, wo = _usable_directions(wi, wo)
    cos_i = np.clip(wi[:, 2:3], 1e-7, 1.0)
    return Data(wi, wo, ref, sqrt_w[0] if same else sqrt_w, cos_i, floor)


def prepare_values_device(values, wi, wo, weights, name: str = "batch") -> Data:
    """:func:`prepare_values` on the accelerator that holds ``values`` (n, N, C) (a JAX array there): the
    masks and floors computed there, so that the host only reads and sends the values (one compiled call;
    the floors equal prepare_values' to rounding, their sums taken in another order)."""
    import jax

    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    w0 = np.asarray(weights, dtype=np.float64)
    shared = (w0 > 0) & (wi[:, 2] > 0) & (wo[:, 2] > 0) & _rows_all(np.isfinite(wi)) & _rows_all(np.isfinite(wo))
    ref, floor, total, same = _prepare_on_device(values, shared, w0)
    total = np.asarray(total)
    if np.any(total == 0):
        raise UsageError(f"{name}[{int(np.argmin(total))}]: no valid samples to fit (all have weight 0, "
                         "non-finite values or lie below the horizon)")
    c = values.shape[-1]
    if bool(same):
        w = np.where(shared, w0, 0.0)
        sqrt_w = np.sqrt(w / (w.sum() * c))[:, None]
    else:
        sqrt_w = jax.jit(lambda r, s, w: jnp.sqrt(jnp.where(jnp.all(jnp.isfinite(r), -1) & s, w, 0.0)
                                                  / (jnp.asarray(total)[:, None] * c))[..., None])(values, shared, w0)
    wi, wo = _usable_directions(wi, wo)
    return Data(wi, wo, ref, sqrt_w, np.clip(wi[:, 2:3], 1e-7, 1.0), floor)


@functools.partial(jax.jit, static_argnums=())
def _prepare_on_device(values, shared, w0):
    mask = shared[None, :] & jnp.all(jnp.isfinite(values), axis=-1)
    ref = jnp.where(mask[..., None], values, 0.0).astype(values.dtype)
    w = jnp.where(mask, w0[None, :], 0.0)
    total = w.sum(axis=1)
    mean_abs = jnp.einsum("kn,knc->kc", w, jnp.abs(ref).astype(w.dtype)) / total[:, None]
    floor = jnp.maximum(0.01 * mean_abs, np.finfo(np.float64).tiny * 1e10)
    return ref, floor, total, jnp.all(mask == mask[:1])


def stack_data(parts) -> Data:
    """One batch ``Data`` of several fits' (each from :func:`prepare`): ``ref`` and ``floor`` with a leading
    fit axis; ``wi``, ``wo``, ``sqrt_w``, ``cos_i`` held once where every fit has the same (a batch of one:
    always)."""
    out = []
    for i, field in enumerate(Data._fields):
        rows = [np.asarray(p[i]) for p in parts]
        if field in ("ref", "floor") or any(not np.array_equal(r, rows[0]) for r in rows[1:]):
            out.append(np.stack(rows))
        else:
            out.append(rows[0])
    return Data(*out)


# -- the data's unit ---------------------------------------------------------------------------------
#: A table whose mean |f_r cos theta_i| (over the used samples) lies in this range is fitted in its own
#: unit; outside it (a radiometric unit change: x1e-12, x1e12) a fit under a loss whose objective a unit
#: only rescales (l2, cosine_l2, cbrt, relative: every one but ``log``) is solved in units of a power of
#: ten that brings that mean near CANONICAL_MEAN, and the linear parameters are scaled back: the same
#: optimum, and every solver sees numbers of order one (optimistix's dogleg ran out of steps at x1e12).
#: The ``log`` loss has a unit of its own (ln(1 + f cos)): a table in another unit is another problem for
#: it, solved as it is (a unit of the fit's own once changed its objective: a mirror table's lambert fit
#: minimised another loss than it reported).
UNIT_RANGE = (1e-3, 1e2)
CANONICAL_MEAN = 0.1


@functools.lru_cache(maxsize=None)
def homogeneous(model: Model) -> bool:
    """Whether f_r is proportional to the model's linear parameters together (f = 0 when they are 0),
    so that a table scaled by s is fitted by the same model with them scaled by s."""
    if not any(p.linear for p in model.params):
        return False
    zero = np.where(model.flat.linear, 0.0, model.flat.defaults)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2, 64, 3))
    d[..., 2] = np.abs(d[..., 2]) + 0.1
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return bool(np.all(np.asarray(model.flat.f_r(zero, d[0], d[1])) == 0.0))


def data_unit(model: Model, loss: str, data: Data) -> float:
    """1.0, or the power of ten in whose units the fit of ``model`` to the batch ``data`` is solved (see
    UNIT_RANGE: one unit for a batch, from the mean over all its used samples; 1.0 for the ``log`` loss)."""
    if loss == "log" or not homogeneous(model):
        return 1.0
    ref = np.abs(np.asarray(data.ref, np.float64) * np.asarray(data.cos_i))
    used = np.broadcast_to(np.asarray(data.sqrt_w) > 0, ref.shape[:-1] + (1,))
    total = int(np.count_nonzero(used)) * ref.shape[-1]
    if not total:
        return 1.0
    mean = float(np.sum(np.where(used, ref, 0.0)) / total)
    if not (np.isfinite(mean) and mean > 0) or UNIT_RANGE[0] <= mean <= UNIT_RANGE[1]:
        return 1.0
    return float(10.0 ** round(np.log10(mean / CANONICAL_MEAN)))


def loss_in_unit(loss: str, unit: float) -> float:
    """The factor from a loss value in the solve's unit (:func:`data_unit`) to the table's: the losses a unit
    only rescales are homogeneous in f, of degree 2 (l2, cosine_l2), 2/3 (cbrt) or 0 (relative)."""
    return {"l2": unit**2, "cosine_l2": unit**2, "cbrt": unit ** (2.0 / 3.0)}.get(loss, 1.0)


def in_unit(data: Data, unit: float) -> Data:
    """``data`` with its values (and the loss floors that follow them) divided by ``unit``."""
    if unit == 1.0:
        return data
    return data._replace(ref=np.asarray(data.ref) / unit, floor=np.asarray(data.floor) / unit)
