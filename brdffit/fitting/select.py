"""`brdffit.select`: the simplest model that fits well enough, with the reason as text."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from ..errors import UsageError
from ..measurement import Measurement
from .losses import evaluate
from .problem import prepare
from .result import FitResult


@dataclasses.dataclass(frozen=True)
class Selection:
    result: FitResult
    reason: str
    scores: dict[str, float]  # candidate label -> score used

    @property
    def model_name(self) -> str:
        return self.result.model_name


def _label(r: FitResult) -> str:
    return f"{r.model_name}/{r.solver}/{r.loss}"


def select(
    measurement: Measurement,
    candidates: Sequence[FitResult],
    *,
    metric: str = "log",
    tolerance: float = 0.05,
    criterion: str = "tolerance",
) -> Selection:
    """Pick among fitted candidates.

    criterion "tolerance": the fewest parameters among those whose ``metric`` (a loss name or
    rmse / log_rmse / rel_rmse, evaluated on ``measurement``) is within ``tolerance`` (relative)
    of the best; ties go to the lower error. "aic" / "bic": the lowest Akaike / Bayesian
    information criterion, n ln(SSE/n) + k (2 | ln n), with SSE from the ``metric`` loss.
    """
    if hasattr(candidates, "results"):  # a Report
        candidates = candidates.results
    candidates = list(candidates)
    if not candidates:
        raise UsageError("select: no candidates")
    prep = prepare(measurement)
    n = prep.n_used * prep.channels
    errs = {}
    for r in candidates:
        vals = evaluate(r.model, r.params, prep.data)
        if metric not in vals:
            raise UsageError(f"select: unknown metric {metric!r}; known: {', '.join(vals)}")
        errs[id(r)] = vals[metric]
    if criterion == "tolerance":
        best = min(candidates, key=lambda r: errs[id(r)])
        limit = errs[id(best)] * (1 + tolerance)
        ok = [r for r in candidates if errs[id(r)] <= limit]
        pick = min(ok, key=lambda r: (r.n_params, errs[id(r)]))
        reason = (
            f"{pick.model_name} ({pick.n_params} parameters): {metric} {errs[id(pick)]:.4g} is within "
            f"{tolerance:.0%} of the best ({_label(best)}, {errs[id(best)]:.4g}, {best.n_params} parameters); "
            f"{len(ok)} of {len(candidates)} candidates qualified and it has the fewest parameters"
        )
        scores = {_label(r): errs[id(r)] for r in candidates}
    elif criterion in ("aic", "bic"):
        def score(r):
            sse = max(errs[id(r)] * n, 1e-300)  # losses are means of squared residuals
            penalty = 2.0 if criterion == "aic" else math.log(n)
            return n * math.log(sse / n) + penalty * r.n_params

        scores = {_label(r): score(r) for r in candidates}
        pick = min(candidates, key=score)
        reason = f"{pick.model_name} ({pick.n_params} parameters) has the lowest {criterion.upper()} ({score(pick):.2f}) on {metric}"
    else:
        raise UsageError(f"select: criterion must be 'tolerance', 'aic' or 'bic', not {criterion!r}")
    return Selection(pick, reason, scores)
