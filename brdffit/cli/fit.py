"""``brdffit fit SOURCE --model M [--loss L] [--solver S] -o DIR``: one fit (docs/cli.md#the-command-line-and-set-up).

Writes DIR/fit.json (``FitResult.to_json``) and DIR/fit.png: for a UBO-81 measurement the 81x81
table measured | fitted | log residual per channel (``brdffit.plot.fit_figure``); for scattered
samples, fitted against measured values per channel. Exit 1 when the fit did not converge (the
results are still written; fit.json says ``"converged": false``).
"""

from __future__ import annotations

from pathlib import Path

import click

from . import EXIT_NOT_CONVERGED, EXIT_OK, check_model, cli


def parse_assignments(option: str, items, expect_pair: bool) -> dict:
    """``--bound NAME=LO,HI`` (either side may be empty: keep it) / ``--fix NAME=V[,V,V]`` ->
    dict for ``fit(bounds=..., fixed=...)``; a malformed item is a usage error (exit 2)."""
    from ..errors import UsageError

    out = {}
    for item in items:
        name, eq, text = item.partition("=")
        name = name.strip()
        if not eq or not name or not text.strip():
            form = "NAME=LO,HI" if expect_pair else "NAME=VALUE"
            raise UsageError(f"{option} {item!r}: expected {form}")
        parts = [t.strip() for t in text.split(",")]
        if expect_pair and len(parts) != 2:
            raise UsageError(f"{option} {item!r}: expected two numbers LO,HI (an empty side keeps that bound)")
        values = []
        for t in parts:
            if expect_pair and t == "":
                values.append(None)
                continue
            try:
                values.append(float(t))
            except ValueError:
                raise UsageError(f"{option} {item!r}: {t!r} is not a number") from None
        if name in out:
            raise UsageError(f"{option}: {name!r} given twice")
        out[name] = tuple(values) if expect_pair else (values[0] if len(values) == 1 else values)
    return out


def model_help() -> str:
    """--model's help: the model names (``brdffit models`` shows their parameters)."""
    from ..models import names

    return (f"Model: {', '.join(names())}, or a sum such as lambert+ggx+ggx "
            "(`brdffit models` lists parameters, bounds and citations).")


class ModelOption(click.Option):
    """``--model``, whose help lists the library's models when help is shown: listing them imports
    every model, and JAX, which a command that is not asked for help must not wait for here."""

    def get_help_record(self, ctx):
        self.help = model_help()
        return super().get_help_record(ctx)


# The CLI's defaults are the API's (one set of defaults, a module without heavy imports).
from .._fit_defaults import COMPOSITE_STARTS as _COMPOSITE_STARTS  # noqa: E402
from .._fit_defaults import DEFAULT_LOSS as _LOSS  # noqa: E402
from .._fit_defaults import DEFAULT_MAX_STEPS as _MAX_STEPS  # noqa: E402
from .._fit_defaults import DEFAULT_SOLVER as _SOLVER  # noqa: E402
from .._fit_defaults import LOSSES as _LOSSES  # noqa: E402
from .._fit_defaults import SOLVERS as _SOLVERS  # noqa: E402


@cli.command("fit")
@click.argument("source", type=click.Path(path_type=str))
@click.option("--model", "-m", "model", cls=ModelOption, required=True, help="Model name, or a sum such as lambert+ggx+ggx.")
@click.option("--loss", default=_LOSS, show_default=True, help=" | ".join(_LOSSES))
@click.option("--solver", default=_SOLVER, show_default=True, help=" | ".join(_SOLVERS))
@click.option("--multistart", default=None, type=click.IntRange(min=0),
              help="Further grid starts solved beside the best one [default: 0"
                   + (f", or {_COMPOSITE_STARTS - 1} for a composite with repeated lobes" if _COMPOSITE_STARTS > 1 else "")
                   + "].")
@click.option("--max-steps", type=click.IntRange(min=1), default=_MAX_STEPS, show_default=True)
@click.option("--bound", "bound_items", multiple=True, metavar="NAME=LO,HI",
              help="Narrow a parameter's box, e.g. ggx1.alpha=0.01,0.5 (an empty side keeps it). Repeatable.")
@click.option("--fix", "fix_items", multiple=True, metavar="NAME=VALUE",
              help="Hold a parameter at a value (or one per channel: kd=0.1,0.2,0.3). Repeatable.")
@click.option("--physical", is_flag=True, help="Keep parameters in their plausible ranges (albedo <= 1, ...).")
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [fit-<name>-<model>].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--scene", default=None, type=click.Path(path_type=str), help="Mitsuba 3 scene: fit where it looks at --material.")
@click.option("--material", default=None, help="Id of the BSDF in --scene that this fit is for.")
def fit_command(**options) -> int:
    """Fit one model to one measurement; writes fit.json and fit.png."""
    from .._figure_process import FigureProcess

    # fit.png is drawn by a worker that imports matplotlib beside this process's imports and fit
    # (on another core): started before anything here imports JAX.
    with FigureProcess() as figure:
        return _fit(figure, **options)


def _fit(figure, source, model, loss, solver, multistart, max_steps, bound_items, fix_items, physical, out,
         force, scene, material) -> int:
    import contextlib

    from rich.console import Console

    from .. import load
    from .._files import atomic_dir, reserve
    from ..fitting import fit
    from ..fitting.losses import check_loss
    from ..fitting.stages import check_solver

    check_loss(loss)
    check_solver(solver)
    check_model(model)  # unknown or impossible model -> usage error before any work
    from ..fitting.problem import resolve_model
    from ..fitting.space import ParameterSpace

    bounds = parse_assignments("--bound", bound_items, expect_pair=True)
    fixed = parse_assignments("--fix", fix_items, expect_pair=False)
    # unknown parameter names or values -> usage error before any work
    ParameterSpace.build(resolve_model(model, 3), bounds, fixed, physical)
    console = Console(stderr=True)
    # Progress only for a person at a terminal (stderr a TTY): reading, compiling, initialising,
    # solving, writing. (Per-step progress from inside the compiled solve would need a host
    # callback, and JAX does not keep executables with host callbacks in its persistent cache.)
    live = console.is_terminal
    with contextlib.ExitStack() as stack:
        if out is not None:  # checked, writable and locked before any work
            stack.enter_context(reserve(out, force, folder=True))
        status = stack.enter_context(console.status(f"reading {source}") if live else contextlib.nullcontext())
        usage = None
        if scene is not None or material is not None:  # docs/scene.md#scene-aware-fitting: scene-aware fit
            from ..scene.usage import cli_usage

            if live:
                status.update(f"recording where {scene} looks at {material!r}")
            m, usage = cli_usage(source, scene, material)
        else:
            m = load(source)
        if out is None:
            out = Path(f"fit-{m.name}-{model.replace('+', '_')}")
            stack.enter_context(reserve(out, force, folder=True))

        def progress(text: str) -> None:
            if live:
                status.update(f"{model} on {m.name}: {text}")

        r = fit(m, model, loss=loss, solver=solver, multistart=multistart, max_steps=max_steps, progress=progress,
                bounds=bounds, fixed=fixed, physical=physical, scene=usage)
        progress("writing fit.json, fit.png")
        from ..plot import fit_figure_data

        data = fit_figure_data(m, r)
        with atomic_dir(out, force) as tmp:
            r.to_json(tmp / "fit.json")
            figure.savefig(data, tmp / "fit.png", dpi=110)
    console.print(repr(r), soft_wrap=True)
    for line in r.warnings:  # one line each, on stderr with the rest of the report
        console.print(f"warning: {line}", soft_wrap=True, markup=False, highlight=False)
    console.print(f"wrote {out}/fit.json, {out}/fit.png")
    if not r.converged:
        console.print(f"[bold red]not converged[/]: {r.status}")
        return EXIT_NOT_CONVERGED
    return EXIT_OK
