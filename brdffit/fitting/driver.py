"""The fit driver: every fit of brdffit runs here, as a batch (docs/fitting.md#fitting: a single fit is a batch of one).

``brdffit.fit`` (one measurement), ``brdffit.fit_batch`` (many) and ``brdffit.fit_btf`` (the texels of a
BTF, tile by tile) check their options into one :class:`~brdffit.fitting.options.FitOptions` and call
:func:`solve`: arrays in, a :class:`Solved` record out, one row per fit, each with its status code (``fit`` and
``fit_batch`` through ``measurements.fit_measurements``, which makes a FitResult of each row). What :func:`solve`
runs, the same for one fit and for a million:

1. starts: the variable-projection grid and any given starts, the best ``k`` of each fit
   (``init.start_stage``), or the given starts alone;
2. the solves, one lane per start, in rounds (``stages.solve_rounds``; ``scipy``: in Python, one start after
   another, ``solver_scipy.solve_lanes``); the best lane of each fit;
3. lobes the data do not see (switched off, or a needle between the samples: ``ParameterSpace.unseen_lobes``) tried
   again at every roughness, scored on every sample; the fit keeps what lowers its loss;
4. the finish (``stages.finish_stage``): the loss afresh where the solver's own is not exact, metrics and
   J^T J where FitResults are made;
5. the status tests: the solver's test, a result no worse than its start, a model that cannot reach the
   data (every scale on a bound, rel_rmse near 1), a given start that ends far above the default's.

Every solve minimises the loss it reports, in the table's own unit: a table far from reflectance's range is
solved in a unit of its own only under a loss whose objective a unit merely rescales (``problem.data_unit``:
not ``log``), and :func:`solve` gives its results back in the table's (for FitResults, the loss, metrics and
J^T J of the table itself).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from . import init as _init
from .stages import Stages
from .options import FitOptions
from .problem import Data, in_unit, loss_in_unit
from .._fit_defaults import NEAR_START_DAMPING, START_DAMPING
from .space import ParameterSpace, sample_spacing

#: A fit from a given start whose loss ends above this factor of the default start's is not converged.
GIVEN_START_FACTOR = 1.1
#: rel_rmse from which a fit with every scale on a bound has not reached the data.
UNREACHED_REL_RMSE = 0.5


def quiet(_message: str) -> None:
    """A ``note`` that says nothing (the default where a caller does not listen)."""


class Solved(NamedTuple):
    """What the solves found, one row per fit (NumPy, the fit axis first), in the table's unit."""

    v: np.ndarray  # (n, P) canonical lobe order, fixed entries exact
    loss: np.ndarray  # (n,) the fit's loss at v
    code: np.ndarray  # (n,) int: status code (``_fit_defaults.STATUS_TEXT``), 0 converged
    steps: np.ndarray  # (n,) int
    start: np.ndarray  # (n, P) the start the best solve came from
    metrics: dict | None  # name -> (n,), or None (not asked for; scipy: computed with the result)
    jtj: np.ndarray | None  # (n, P, P) in v's order, or None
    seconds: dict  # "compile", "run", "init": the whole call's
    starts: int  # candidates solved per fit
    notes: dict  # fit index -> one sentence on its status (a model that cannot reach the data ...)


def _best_of(loss: np.ndarray, n: int, k: int) -> np.ndarray:
    """The lane index (into n*k lanes, fit-major) of each fit's lowest finite loss."""
    key = np.where(np.isfinite(loss), loss, np.inf).reshape(n, k)
    return np.arange(n) * k + np.argmin(key, axis=1)


def solve(space: ParameterSpace, options: FitOptions, data: Data, *, k: int, unit: float = 1.0,
          fits: np.ndarray | None = None, starts: np.ndarray | None = None, grid: bool = True, near: bool = False,
          results: bool = True, check_given: bool = False, note: Callable[[str], None] = quiet,
          progress=None) -> Solved:
    """Fit the fits ``fits`` (rows of the per-fit fields; default: all) of ``data`` (``Data``: ref and floor
    with a leading fit axis (n, ...), the other fields with one too or shared by every fit) in ``space``;
    the results' rows follow ``fits``. ``k``: how many of the grid's best points each fit solves from (with
    the grid; ``FitOptions.starts`` of the model, resolved once by the caller). ``unit``: the unit the fits
    are solved in (``problem.data_unit`` of the table: 1, or a power of ten); ``data``, ``space``, ``starts``
    and every result are in the table's.
    ``starts``: (len(fits), P) given starts, or (len(fits), E, P) E candidates each, ranked beside the grid's
    points (``grid``); without the grid a fit's candidates are ranked where they differ (on the grid's
    rows, as its points are), and the best starts it. ``near``: the given starts lie near their fits' optima (a
    BTF's fitted neighbours' results): lm's first step from a fit's one start is nearly Gauss-Newton's
    (``_fit_defaults.NEAR_START_DAMPING``; the grid's points, and the best of several that differ, are guesses).
    ``results``: also every metric and J^T J (for FitResults; else the loss alone). ``check_given``: a fit from a
    given start is also solved from the default start, and marked not converged when it ends far above that
    (``GIVEN_START_FACTOR``). ``progress(fraction)``: called with the share of the fits whose solves ended, as
    they end."""
    model = space.model
    fits = np.arange(int(np.shape(data.ref)[0])) if fits is None else np.asarray(fits)
    n, P = len(fits), model.n_free
    unscale = np.where(space.linear, unit, 1.0)
    # The solves, in the solve's unit (a copy of the values when it is not 1: a table far from
    # reflectance's range under a loss a unit only rescales).
    table_space, table_data = space, data
    run = Stages(space.in_unit(unit), options, in_unit(data, unit), note)
    space = run.space
    given = np.zeros((n, 0, P)) if starts is None else (np.asarray(starts, np.float64) / unscale).reshape(n, -1, P)
    damping = START_DAMPING  # the grid's points are guesses
    if grid:
        candidates = run.starts(fits, given, k)
    else:  # the given starts alone: where a fit has several that differ, the best on the grid's rows
        candidates = given[:, :1].copy()
        differ = np.any(given != given[:, :1], axis=(1, 2))
        choice = np.flatnonzero(differ)
        if len(choice):
            candidates[choice] = run.starts(fits[choice], given[choice], 1, grid=False)
        # A fit's one start that lies near its optimum takes a nearly Gauss-Newton first step; the best of
        # several that differ (a texel between materials) is a guess.
        damping = np.where(near & ~differ, NEAR_START_DAMPING, START_DAMPING)
    k = candidates.shape[1]
    # One damping per fit, and so per lane: without the grid k is 1.
    r = run.solve(candidates.reshape(n * k, P), np.repeat(fits, k), progress, damping=damping)
    best = _best_of(r.loss, n, k)
    v, loss, code, steps = r.v[best], r.loss[best], r.code[best], r.steps[best].copy()
    start, start_loss, jtj = candidates.reshape(n * k, P)[best], r.start_loss[best], r.jtj[best]
    if k > 1:
        steps = r.steps.reshape(n, k).sum(axis=1)

    # Lobes the data do not see: tried again at every roughness (scored on every sample), kept where better.
    spacing = sample_spacing(np.asarray(data.wo if np.ndim(data.wo) == 2 else data.wo[fits[0]]))
    for lobe, flagged in space.unseen_lobes(v, spacing).items():
        which = np.flatnonzero(flagged)
        note(f"re-seeding the lobe of {lobe[0]}: the data do not see it")
        again = run.starts(fits[which], v[which][:, None, :], 1, grids=_init.reseed_grids(space, v[which], lobe),
                           subset=np.arange(np.shape(data.ref)[-2]))
        r2 = run.solve(again[:, 0], fits[which])
        better = np.isfinite(r2.loss) & (r2.loss < loss[which])
        idx = which[better]
        v[idx], loss[idx], code[idx], jtj[idx] = r2.v[better], r2.loss[better], r2.code[better], r2.jtj[better]
        steps[which] += r2.steps

    notes = {}
    metrics = None
    # Metrics, and J^T J that the solver did not give (scipy's lanes) or gave not finite, from this finish
    # where the solve's data are the table's; in another unit the table's own finish below gives them.
    report_here = results and unit == 1.0
    fresh_jtj = report_here and not np.all(np.isfinite(jtj))
    if results or options.solver != "lm":
        # The solver's claim checked on the loss evaluated afresh (lm's own loss is exact: it only ever
        # moves to a point of lower loss, so a BTF's maps need no finish).
        out = run.finish(v, fits, metrics=report_here, jtj=fresh_jtj)
        if fresh_jtj:
            jtj = out.pop("jtj")
        ok, code = result_check(out["loss"], start_loss, v, code, out["floor"])
        if not ok.all():  # a point worse than its start (or not finite) gives way to the start
            bad = np.flatnonzero(~ok)
            v[bad] = np.where(space.free, np.clip(start[bad], space.lo, space.hi), space.anchor)
            again = run.finish(v[bad], fits[bad], metrics=report_here, jtj=True)
            jtj[bad] = again.pop("jtj")
            for key, value in again.items():
                if isinstance(value, dict):
                    for name in value:
                        out[key][name][bad] = value[name]
                else:
                    out[key][bad] = value
        loss = out["loss"]
        metrics = out.get("metrics")
    _unreached(run, fits, v, metrics, code, notes)
    if check_given and starts is not None and not grid:
        _far_from_default(run, fits, v, loss, code, notes)
    v, jtj = space.canonical_rows(v, jtj)
    if unit != 1.0:  # back in the table's unit: the loss, metrics and J^T J of the table there
        v, start = table_space.clip(v * unscale), start * unscale
        if results:
            table = Stages(table_space, options, table_data, note, run.seconds)
            out = table.finish(v, fits, metrics=True, jtj=True)
            loss, metrics, jtj = out["loss"], out["metrics"], out["jtj"]
        else:
            loss = loss * loss_in_unit(options.loss, unit)
    return Solved(v, loss, code, steps, start, metrics, jtj, run.seconds, k, notes)


def result_check(value, l0, v, code, loss_floor):
    """(ok, code), NumPy, one entry per fit: whether the solver's point v (rows) with loss ``value``
    (evaluated afresh) may stand, i.e. is finite and no worse than the start's loss l0 beyond
    roundoff, whatever the solver claims; if not, a failure code (2: worse, 3: non-finite) unless the
    solver gave one. A point at the exact-fit floor (``loss_floor``) is converged."""
    value, l0, code, loss_floor = (np.asarray(a) for a in (value, l0, code, loss_floor))
    finite = np.all(np.isfinite(np.asarray(v)), axis=-1) & np.isfinite(value)
    ok = finite & (np.where(finite, value, np.inf) <= l0 * (1 + 1e-9) + loss_floor)
    # Non-finite first: a NaN loss also fails the comparison, and must not read as "worse".
    mine = np.where(finite, np.where(ok, 0, 2), 3)
    code = np.where(code != 0, code, mine)
    # An exact fit (residuals at roundoff level) has converged, whatever the solver's own stopping
    # test said: optimistix's Gauss-Newton and BFGS test the change of every unknown, which an exact
    # fit with a direction the data do not determine never settles (blinn_phong and oren_nayar on
    # their own noise-free data, rel_rmse 1e-15, "did not converge" after 200 steps).
    code = np.where(finite & (np.where(finite, value, np.inf) <= loss_floor), 0, code)
    return ok, code


def _unreached(run: Stages, fits: np.ndarray, v: np.ndarray, metrics: dict | None, code: np.ndarray, notes: dict) -> None:
    """A fit whose every scale (linear parameter: reflectances, albedos) ended on a bound while rel_rmse is
    near 1 or above has not reached the data: the model cannot reach the data's level within its bounds (a
    table in another unit than a native model's reflectances <= 1 allow: x1e12 left every native model at
    rel_rmse 1.0, x1e-12 principled at 1e9, both "converged"). ``metrics``: every fit's, or None (then
    computed for the fits on their bounds)."""
    every = np.flatnonzero(run.space.scales_on_bounds(v))
    if not len(every):
        return
    if metrics is None:
        rel = run.finish(v[every], fits[every], metrics=True, jtj=False)["metrics"]["rel_rmse"]
    else:
        rel = np.asarray(metrics["rel_rmse"])[every]
    for i, value in zip(every, rel):
        if value >= UNREACHED_REL_RMSE:
            code[i] = 5
            notes[int(i)] = (f"every scale ended on a bound with rel_rmse {float(value):.3g}: the model cannot reach "
                             "the data's level within its bounds (is the table in another unit?)")


def _far_from_default(run: Stages, fits: np.ndarray, v: np.ndarray, loss: np.ndarray, code: np.ndarray,
                      notes: dict) -> None:
    """A converged fit from a given start also solved from the default start: far above it, it is not
    converged (its solver's test passed, but in a basin the default start leaves)."""
    n, P = v.shape
    check = np.flatnonzero(code == 0)
    if not len(check):
        return
    ref = run.solve(run.starts(fits[check], np.zeros((len(check), 0, P)), 1)[:, 0], fits[check])
    far = np.zeros(n, bool)
    far[check] = np.isfinite(ref.loss) & (loss[check] > GIVEN_START_FACTOR * ref.loss + 1e-300)
    default_loss = np.full(n, np.nan)
    default_loss[check] = ref.loss
    for i in np.flatnonzero(far):
        code[i] = 6
        notes[int(i)] = (f"the fit from the given start ended at loss {loss[i]:.6g}, {loss[i] / default_loss[i]:.3g} "
                         f"times the default start's ({default_loss[i]:.6g}): start from the default (init=None)")
