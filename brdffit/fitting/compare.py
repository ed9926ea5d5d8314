"""`brdffit.compare`: error against run time for every model x solver x loss (SPEC 5)."""

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
from .api import fit
from .losses import LOSSES, check_loss
from .problem import evaluate, prepare
from .result import FitResult
from .solve import check_solver

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

    def plot_pareto(self, path: str | os.PathLike, metric: str = "loss_log") -> Path:
        """Error (``metric``) against run time, log axes, one labelled point per row; the Pareto
        front (no other row both faster and more accurate) is joined by a line."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rows = [r for r in self.rows if r[metric] > 0 and r["run_s"] > 0]
        fig, ax = plt.subplots(figsize=(9, 6.5), dpi=120)
        solvers = sorted({r["solver"] for r in rows})
        markers = dict(zip(solvers, "osD^v<>p*"))
        models = sorted({r["model"] for r in rows})
        cmap = plt.get_cmap("tab20" if len(models) > 10 else "tab10")
        colours = {m: cmap(i % cmap.N) for i, m in enumerate(models)}
        for r in rows:
            ax.scatter(r["run_s"], r[metric], marker=markers[r["solver"]], color=colours[r["model"]], s=46,
                       edgecolors="black" if r["converged"] else "red", linewidths=0.6 if r["converged"] else 1.6,
                       zorder=3)
        front = []
        for r in sorted(rows, key=lambda r: (r["run_s"], r[metric])):
            if not front or r[metric] < front[-1][metric]:
                front.append(r)
        # Colour = model, marker = solver (legend); text labels only on the Pareto front, where
        # the choice is made (labelling every point makes an unreadable pile).
        several_losses = len({x["loss"] for x in rows}) > 1
        for i, r in enumerate(front):
            label = f"{r['model']} / {r['solver']}" + (f" / {r['loss']}" if several_losses else "")
            ax.annotate(label, (r["run_s"], r[metric]), fontsize=7.5, xytext=(6, 6 if i % 2 else -10),
                        textcoords="offset points", bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
        if len(front) > 1:
            ax.plot([r["run_s"] for r in front], [r[metric] for r in front], "k--", lw=0.8, zorder=2,
                    label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("run time [s] (after compilation)")
        ax.set_ylabel(f"{metric.replace('loss_', '')} loss on the measurement")
        ax.set_title(f"error against run time: {self.data_name}")
        ax.grid(True, which="both", alpha=0.3)
        from matplotlib.lines import Line2D

        handles = [Line2D([], [], marker=markers[s], ls="", color="grey", label=f"solver {s}") for s in solvers]
        handles += [Line2D([], [], marker="s", ls="", color=colours[m], label=m) for m in models]
        handles.append(Line2D([], [], marker="o", ls="", mfc="white", mec="red", mew=1.6, label="not converged"))
        if len(front) > 1:
            handles.append(Line2D([], [], ls="--", color="k", label="Pareto front"))
        ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
        fig.tight_layout()
        path = Path(path)
        fig.savefig(path)
        plt.close(fig)
        return path


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
    progress: Callable[[str], None] | None = None,
    **fit_options,
) -> Report:
    """Fit every (model, solver, loss) combination; evaluate every loss on each result."""
    from .. import models as _models

    models = list(models) if models else _models.names()
    solvers = [check_solver(s) for s in solvers]
    losses = [check_loss(x) for x in losses]
    prep = prepare(measurement)
    rows, results = [], []
    for model in models:
        for loss in losses:
            for solver in solvers:
                if progress:
                    progress(f"{model} / {solver} / {loss}")
                r = fit(measurement, model, loss=loss, solver=solver, **fit_options)
                rows.append(_row(r, evaluate(r.model, r.params, prep.data)))
                results.append(r)
    return Report(tuple(rows), measurement.name, tuple(results))
