"""``brdffit fit SOURCE --model M [--loss L] [--solver S] -o DIR``: one fit (SPEC 7).

Writes DIR/fit.json (``FitResult.to_json``) and DIR/fit.png: for a UBO-81 measurement the 81x81
table measured | fitted | log residual per channel (``brdffit.plot.fit_figure``); for scattered
samples, fitted against measured values per channel. Exit 1 when the fit did not converge (the
results are still written; fit.json says ``"converged": false``).
"""

from __future__ import annotations

from pathlib import Path

import click

from . import EXIT_NOT_CONVERGED, EXIT_OK, cli


def model_help() -> str:
    """--model's help: the model names (``brdffit models`` shows their parameters)."""
    from ..models import names

    return (f"Model: {', '.join(names())}, or a sum such as lambert+ggx+ggx "
            "(`brdffit models` lists parameters, bounds and citations).")


@cli.command("fit")
@click.argument("source", type=click.Path(path_type=str))
@click.option("--model", "-m", "model", required=True, help=model_help())
@click.option("--loss", default="log", show_default=True, help="l2 | cosine_l2 | log | cbrt | relative")
@click.option("--solver", default="lm", show_default=True, help="lm | lmb | gauss_newton | dogleg | bfgs | scipy")
@click.option("--multistart", default=0, show_default=True, help="Further grid starts to polish.")
@click.option("--max-steps", default=200, show_default=True)
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [fit-<name>-<model>].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
def fit_command(source, model, loss, solver, multistart, max_steps, out, force) -> int:
    """Fit one model to one measurement; writes fit.json and fit.png."""
    from rich.console import Console

    from .. import load, plot
    from .._files import atomic_dir, check_target
    from ..fitting import fit
    from ..fitting.losses import check_loss
    from ..fitting.problem import resolve_model
    from ..fitting.solve import check_solver

    check_loss(loss)
    check_solver(solver)
    resolve_model(model, 3)  # unknown model -> usage error before any work
    console = Console(stderr=True)
    with console.status(f"loading {source}"):
        m = load(source)
    out = out or Path(f"fit-{m.name}-{model.replace('+', '_')}")
    check_target(out, force)
    with console.status(f"fitting {model} to {m.name} ({loss} loss, {solver})"):
        r = fit(m, model, loss=loss, solver=solver, multistart=multistart, max_steps=max_steps)
    with atomic_dir(out, force) as tmp:
        r.to_json(tmp / "fit.json")
        plot.fit_figure(m, r).savefig(tmp / "fit.png", dpi=110)
    console.print(repr(r), soft_wrap=True)
    console.print(f"wrote {out}/fit.json, {out}/fit.png")
    if not r.converged:
        console.print(f"[bold red]not converged[/]: {r.status}")
        return EXIT_NOT_CONVERGED
    return EXIT_OK
