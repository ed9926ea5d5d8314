"""`brdffit.compare`: error against run time for every model x solver x loss (docs/fitting.md#fitting)."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..measurement import Measurement
from .._progress import progress_bar
from .api import fit
from .losses import LOSSES, check_loss
from .losses import evaluate
from .problem import prepare
from .result import FitResult
from .stages import check_solver

from .._fit_defaults import COMPARE_SOLVERS as DEFAULT_SOLVERS

COLUMNS = (
    "model", "solver", "loss", "n_params", "converged", "status", "steps", "compile_s", "run_s",
    *(f"loss_{name}" for name in LOSSES), "rmse", "log_rmse", "rel_rmse", "data_name",
)


@dataclasses.dataclass(frozen=True)
class Report:
    """One row per (model, solver, loss): every loss evaluated on every result, so rows compare."""

    rows: tuple[dict[str, Any], ...]
    data_name: str = ""
    results: tuple[FitResult, ...] = ()

    def to_csv(self, path: str | os.PathLike | None = None) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n")
        w.writeheader()
        for row in self.rows:
            w.writerow({k: row.get(k) for k in COLUMNS})
        text = buf.getvalue()
        if path is not None:
            Path(path).write_text(text)
        return text

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        text = json.dumps({"data_name": self.data_name, "rows": list(self.rows)}, indent=2)
        if path is not None:
            Path(path).write_text(text + "\n")
        return text

    def best(self, metric: str = "loss_log") -> dict[str, Any]:
        return min(self.rows, key=lambda r: r[metric])

    def pareto(self, metric: str = "loss_log", rtol: float = 1e-6) -> list[dict[str, Any]]:
        """The rows on the error-against-run-time front, fastest first (docs/fitting.md#fitting): a row is on it
        when no other row is both at least as fast and lower in ``metric`` by more than ``rtol``
        relative. Rows whose errors tie within ``rtol`` keep only the fastest (the first of equally
        fast ones)."""
        import math

        rows = [(k, r) for k, r in enumerate(self.rows) if math.isfinite(r[metric]) and math.isfinite(r["run_s"])]

        def beats(q: tuple[int, dict], r: tuple[int, dict]) -> bool:
            (kq, q), (kr, r) = q, r
            if q["run_s"] > r["run_s"]:
                return False
            tol = rtol * max(abs(q[metric]), abs(r[metric]))
            if q[metric] < r[metric] - tol:
                return True
            tie = abs(q[metric] - r[metric]) <= tol
            return tie and (q["run_s"] < r["run_s"] or kq < kr)

        front = [r for r in rows if not any(beats(q, r) for q in rows if q[0] != r[0])]
        # No two rows of the front are equally fast (of two such, one beats the other).
        return [r for _, r in sorted(front, key=lambda kr: kr[1]["run_s"])]

    def plot(self, metric: str = "loss_log"):
        """:func:`brdffit.plot.pareto` of this report (a matplotlib Figure)."""
        from ..plot import pareto

        return pareto(self, metric)

    def __repr__(self) -> str:
        best = min(self.rows, key=lambda r: r["loss_log"], default=None)
        tail = f"; best log loss {best['loss_log']:.4g} ({best['model']} / {best['solver']})" if best else ""
        return f"Report({self.data_name!r}: {len(self.rows)} rows{tail})"

    def _repr_png_(self) -> bytes:
        from ..plot import png_bytes

        return png_bytes(self.plot())

    def _repr_html_(self) -> str:
        import base64
        import html

        cols = ("model", "solver", "loss", "n_params", "loss_log", "log_rmse", "run_s", "compile_s", "steps", "converged")
        ranked = sorted(self.rows, key=lambda r: r["loss_log"])
        head = "".join(f"<th>{c}</th>" for c in cols)

        def cell(v):
            return f"{v:.4g}" if isinstance(v, float) else html.escape(str(v))

        body = "".join("<tr>" + "".join(f"<td>{cell(r.get(c))}</td>" for c in cols) + "</tr>" for r in ranked[:12])
        more = f"<p>... {len(ranked) - 12} more rows (report.rows, report.to_csv())</p>" if len(ranked) > 12 else ""
        img = base64.b64encode(self._repr_png_()).decode()
        return (f"<p><b>{html.escape(self.data_name)}</b>: {len(self.rows)} fits, ranked by log loss</p>"
                f"<table><tr>{head}</tr>{body}</table>{more}<img src='data:image/png;base64,{img}'/>")


def _row(r: FitResult, all_losses: dict[str, float]) -> dict[str, Any]:
    return {
        "model": r.model_name,
        "solver": r.solver,
        "loss": r.loss,
        "n_params": r.n_params,
        "converged": r.converged,
        "status": r.status,
        "steps": r.steps,
        "compile_s": r.seconds.get("compile", 0.0),
        "run_s": r.seconds.get("run", 0.0),
        **{f"loss_{k}": all_losses[k] for k in LOSSES},
        "rmse": all_losses["rmse"],
        "log_rmse": all_losses["log_rmse"],
        "rel_rmse": all_losses["rel_rmse"],
        "data_name": r.data_name,
    }


def compare(
    measurement: Measurement,
    models: Sequence[str] | None = None,
    solvers: Sequence[str] = DEFAULT_SOLVERS,
    losses: Sequence[str] = ("log",),
    *,
    progress: Callable[[str], None] | bool | None = None,
    **fit_options,
) -> Report:
    """Fit every (model, solver, loss) combination; evaluate every loss on each result.

    ``progress``: a callable told the label of each fit before it starts, or True for a rich
    progress bar (fits done, the one running, time elapsed) in a terminal or a notebook."""
    from .. import models as _models

    models = list(models) if models else _models.names()
    solvers = [check_solver(s) for s in solvers]
    losses = [check_loss(x) for x in losses]
    prep = prepare(measurement)
    combos = [(m, x, s) for m in models for x in losses for s in solvers]
    rows, results = [], []
    with progress_bar("compare", len(combos), shown=progress is True) as bar:
        for model, loss, solver in combos:
            label = f"{model} / {solver} / {loss}"
            if callable(progress):
                progress(label)
            bar.describe(f"fitting {label}")
            r = fit(measurement, model, loss=loss, solver=solver, **fit_options)
            rows.append(_row(r, evaluate(r.model, r.params, prep.data)))
            results.append(r)
            bar.advance()
        bar.describe("done")
    return Report(tuple(rows), measurement.name, tuple(results))
