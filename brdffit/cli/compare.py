"""``brdffit compare SOURCE [--models ...] [--solvers ...] [--losses ...] -o DIR``: error against
run time for every combination (docs/cli.md#the-command-line-and-set-up). Writes report.csv, report.json, pareto.png. Exit 1 when
any fit did not converge (the rows say which)."""

from __future__ import annotations

from pathlib import Path

import click

from .._fit_defaults import COMPARE_SOLVERS as DEFAULT_SOLVERS
from . import EXIT_NOT_CONVERGED, EXIT_OK, check_model, cli
from ._help import DefaultFrom


def _split(values: tuple[str, ...]) -> list[str]:
    out = []
    for v in values:
        out.extend(x.strip() for x in v.split(",") if x.strip())
    return out


def print_report(report, loss: str, console) -> None:
    """The report as a table sorted by the ``loss`` it was ranked with."""
    from rich.table import Table

    table = Table(title=f"{report.data_name}: error against run time")
    for col in ("model", "solver", "loss", "params", f"{loss} loss", "run s", "compile s", "steps", "status"):
        table.add_column(col)
    for r in sorted(report.rows, key=lambda r: r[f"loss_{loss}"]):
        table.add_row(r["model"], r["solver"], r["loss"], str(r["n_params"]), f"{r[f'loss_{loss}']:.4g}",
                      f"{r['run_s']:.3f}", f"{r['compile_s']:.2f}", str(r["steps"]),
                      "ok" if r["converged"] else "[red]not converged[/]")
    print_wide(console, table)


def print_wide(console, renderable) -> None:
    """Print a table uncut: where the output is not a terminal (a pipe, a log file: 80 columns by
    default) the console is widened to the table's natural width for this print."""
    from rich.measure import Measurement

    need = Measurement.get(console, console.options.update_width(10_000), renderable).maximum
    if console.is_terminal or need <= console.width:
        console.print(renderable)
        return
    saved = console.width
    console.width = need
    try:
        console.print(renderable)
    finally:
        console.width = saved


@cli.command("compare")
@click.argument("source", type=click.Path(path_type=str))
@click.option("--models", multiple=True, help="Models (repeat or comma-separate) [all base models].")
@click.option("--solvers", multiple=True, help=f"Solvers [{', '.join(DEFAULT_SOLVERS)}]; also gauss_newton.")
@click.option("--losses", multiple=True, cls=DefaultFrom, default_from="brdffit.fitting.compare:compare(losses)",
              describe=", ".join, help="Losses.")
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [compare-<name>].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
def compare_command(source, models, solvers, losses, out, force) -> int:
    """Fit every model x solver x loss; table of errors and times, and a Pareto plot."""
    import contextlib

    from rich.console import Console
    from .. import load
    from .. import models as _models
    from .._files import atomic_dir, reserve
    from ..fitting.compare import compare
    from ..fitting.losses import check_loss
    from ..fitting.stages import check_solver

    for option, given in (("--models", models), ("--solvers", solvers), ("--losses", losses)):
        if given and not _split(given):  # e.g. --models ",,": refuse rather than run everything
            raise click.UsageError(f"{option}: empty list")
    models = _split(models) or _models.names()
    solvers = [check_solver(s) for s in (_split(solvers) or list(DEFAULT_SOLVERS))]
    losses = [check_loss(x) for x in (_split(losses) or ["log"])]
    for name in models:
        check_model(name)
    console = Console(stderr=True)
    with contextlib.ExitStack() as stack:
        if out is not None:  # checked, writable and locked before any work
            stack.enter_context(reserve(out, force, folder=True))
        with console.status(f"loading {source}"):
            m = load(source)
        if out is None:
            out = Path(f"compare-{m.name}")
            stack.enter_context(reserve(out, force, folder=True))
        report = compare(m, models, solvers, losses, progress=True)
        with atomic_dir(out, force) as tmp:
            report.to_csv(tmp / "report.csv")
            report.to_json(tmp / "report.json")
            report.plot(metric=f"loss_{losses[0]}").savefig(tmp / "pareto.png", dpi=120)
    print_report(report, losses[0], Console())
    console.print(f"wrote {out}/report.csv, {out}/report.json, {out}/pareto.png")
    return EXIT_OK if all(r["converged"] for r in report.rows) else EXIT_NOT_CONVERGED
