"""`brdffit.fit` (one measurement, one model -> FitResult) and `brdffit.fit_batch` (many measurements,
one model -> a FitResult each): the public signatures, through the fit driver (``driver``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .._progress import progress_bar
from .._fit_defaults import DEFAULT_ATOL, DEFAULT_LOSS, DEFAULT_MAX_STEPS, DEFAULT_RTOL, DEFAULT_SOLVER
from ..errors import UsageError
from ..measurement import Measurement
from ..models.base import Model
from .measurements import fit_measurements, with_warning
from .options import FitOptions
from .result import FitResult


def fit(
    measurement: Measurement,
    model: str | Model,
    *,
    loss: str = DEFAULT_LOSS,
    solver: str = DEFAULT_SOLVER,
    init=None,
    multistart: int | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    weights=None,
    scene=None,
    scipy_jac: str = "exact",
    progress: Callable[[str], None] | None = None,
    bounds: Mapping[str, tuple] | None = None,
    fixed: Mapping[str, object] | None = None,
    physical: bool = False,
) -> FitResult:
    """Fit ``model`` to ``measurement``.

    loss: l2 | cosine_l2 | log | cbrt | relative. solver: lm | optx_lm | gauss_newton | dogleg |
    bfgs | scipy. init: None (the variable-projection grid, see ``brdffit.fitting.init``),
    "defaults", a params dict (missing parameters take their defaults) or a FitResult.
    multistart: further grid starts solved beside the best one (all in one vmapped solve; the
    lowest loss wins); None (default) = ``default_starts(model) - 1``. rtol: relative tolerance
    (see ``solver_lm.BoundedLevenbergMarquardt``); atol: absolute floor on the loss, 0 = none.
    progress: called with a short text at each phase (initialising, compiling, solving, solved).
    Non-convergence is reported in ``.status`` (and ``.status_code``), never raised; parameters
    are never NaN.

    Parameter space (``brdffit.fitting.space``): the model's bounds (only what its formula needs),
    ``physical=True`` for its plausible ranges, ``bounds={"name": (lo, hi)}`` to narrow a box
    (None on a side keeps it), ``fixed={"name": value}`` to hold a parameter. Lobes of one kind
    come out narrowest first. ``.at_bound`` and ``.warnings`` report what the constraints decided.

    scene: a ``brdffit.scene.Usage`` (``brdffit.scene_usage``, docs/scene.md#scene-aware-fitting): the samples are weighted
    by where that scene looks (``usage.weights``), times ``weights``.
    """
    scene_note = None
    if scene is not None:  # docs/scene.md#scene-aware-fitting
        weights = scene.weights(measurement) * (1.0 if weights is None else np.asarray(weights, np.float64))
        scene_note = _coverage_note(scene, measurement)
    options = FitOptions(loss=loss, solver=solver, max_steps=max_steps, rtol=rtol, atol=atol, multistart=multistart,
                         scipy_jac=scipy_jac, bounds=bounds, fixed=fixed, physical=physical)
    if isinstance(init, FitResult):
        init = init.params
    elif init is not None and not isinstance(init, (str, Mapping)):
        raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {type(init).__name__}")
    result, = fit_measurements([measurement], model, options, result_type=FitResult, weights=weights,
                               starts=None if init is None else [init],
                               grid=init is None, check_given=init is not None,
                               note=progress or (lambda _message: None))
    return with_warning(result, scene_note)


def fit_batch(
    measurements: Sequence[Measurement],
    model,
    *,
    loss: str = DEFAULT_LOSS,
    solver: str = DEFAULT_SOLVER,
    max_steps: int = DEFAULT_MAX_STEPS,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    chunk: int | None = None,
    multistart: int | None = None,
    progress: bool = False,
    lanes: int | None = None,
    bounds=None,
    fixed=None,
    physical: bool = False,
    starts=None,
    grid: bool = True,
) -> list[FitResult]:
    """Fit ``model`` to each measurement independently; see the module docstring.

    Same defaults as ``fit`` (loss, solver, starts, tolerances). ``progress=True`` shows a
    progress bar (rich, on stderr) over the fits. ``bounds``, ``fixed``, ``physical``: the
    parameter space, as for ``fit``. ``starts``: one start per measurement (flat vectors (n, P),
    or params dicts / FitResults), ranked beside the grid; ``grid=False``: those starts only."""
    options = FitOptions(loss=loss, solver=solver, max_steps=max_steps, rtol=rtol, atol=atol, multistart=multistart,
                         bounds=bounds, fixed=fixed, physical=physical, chunk=chunk, lanes=lanes).batched("fit_batch")
    measurements = list(measurements)
    if not measurements:
        return []
    shapes = {(m.n_samples, m.n_channels) for m in measurements}
    if len(shapes) != 1:
        raise UsageError(f"fit_batch: all measurements need the same samples and channels, got {sorted(shapes)}")
    n = len(measurements)
    if starts is not None:
        if len(starts) != n:
            raise UsageError(f"fit_batch: {len(starts)} starts for {n} measurements")
        starts = [s.params if isinstance(s, FitResult) else s for s in starts]
    if not grid and starts is None:
        raise UsageError("fit_batch: grid=False needs starts")
    name = model.name if isinstance(model, Model) else str(model)
    with progress_bar(f"fit_batch {name}", n, shown=progress) as bar:
        return fit_measurements(measurements, model, options, result_type=FitResult, starts=starts, grid=grid,
                                progress=lambda fraction: bar.advance(fraction * n), who="fit_batch")


#: Below this fraction of a scene's weight covered by the data, a scene-weighted fit says so.
COVERAGE_WARN = 0.95


def _coverage_note(scene, measurement: Measurement) -> str | None:
    """One sentence when the data cover too little of where ``scene`` looks (docs/fitting.md#hostile-but-valid-data: such a fit
    was the plain fit without a word), else None."""
    if not hasattr(scene, "coverage"):  # any object with weights(measurement) may weight a fit
        return None
    covered = scene.coverage(measurement)  # a brdffit.scene.Usage (duck-typed: no upward import)
    if covered >= COVERAGE_WARN:
        return None
    return (f"the data cover {covered:.0%} of where the scene looks ({scene.material!r} in {scene.scene}); "
            "the rest gets the floor weight, so the fit is closer to the plain fit than to the scene's: "
            "for a source that can be evaluated anywhere (RGL, MERL, UTIA), brdffit.scene.fit_data(source, usage) "
            "samples it where the scene looks")
