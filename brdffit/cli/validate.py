"""``brdffit validate SOURCE FIT.json [-o DIR] [--renderer cycles]``: renders, panels, metrics (docs/validation.md#validation-rendering, docs/cli.md#the-command-line-and-set-up, docs/validation.md#a-second-renderer-cycles)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

from . import cli
from ._help import DefaultFrom, HelpFrom


def _since_process_start() -> float | None:
    """Seconds since this process started (Python start-up and imports included), Linux only."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return uptime - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


@cli.command("validate")
@click.argument("source", type=click.Path(path_type=str))
@click.argument("fit_json", metavar="FIT.json", type=click.Path(path_type=str))
@click.option("-o", "--out", "out", type=click.Path(path_type=str), default=None,
              help="Output folder [default: 'validate' beside FIT.json].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--lights", "n_lights", type=click.IntRange(1, 64), default=5, show_default=True,
              help="Number of light directions (theta 0..75 degrees).")
@click.option("--size", type=click.IntRange(8, 4096), default=256, show_default=True, help="Image size in pixels.")
@click.option("--spp", type=click.IntRange(1, 1024), default=None, cls=DefaultFrom,
              default_from="brdffit.render.scene:DEFAULT_SPP", help="Samples per pixel.")
@click.option("--renderer", default=None, cls=HelpFrom, help_from=("brdffit.render.renderers:choices",),
              help="What renders the fit, one of {} (Cycles: a blender:principled fit; needs .venv-blender). "
                   "The reference is always rendered by Mitsuba.")
def validate_cmd(source: str, fit_json: str, out: str | None, force: bool, n_lights: int, size: int, spp: int | None,
                 renderer: str) -> int:
    """Render the fit in FIT.json and the reference SOURCE on spheres under a light sweep; write
    linear EXRs, PNG panels (reference | fit | error), the 81x81 table panel and metrics.json."""
    t0 = time.perf_counter()
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from .._files import reserve
    from ..errors import InputError

    console = Console(stderr=True)
    if not Path(source).exists():
        raise InputError(source, "no such file or folder")
    if not Path(fit_json).exists():
        raise InputError(fit_json, "no such file")
    out_path = Path(out) if out is not None else Path(fit_json).resolve().parent / "validate"
    # checked, writable and locked against other runs before any work: nothing is written on bad usage
    with reserve(out_path, force, folder=True):
        from ..render import default_lights, validate
        from ..render.scene import DEFAULT_SPP
        from ..render.validate import as_fit, as_source

        # Read both inputs before any progress is shown: bad input is one line, nothing else.
        from ..fitting.result import FitResult

        # FIT.json is a fit file whatever its name: checked as one (not guessed as a measurement)
        fit = as_fit(FitResult.from_json(Path(fit_json)))  # the small file first: a bad one costs nothing
        from ..render.renderers import get as get_renderer, names

        chosen = get_renderer(renderer or names()[0])  # a name it does not know: one line
        chosen.check(fit)  # a fit it cannot render: one line, before reading the reference
        reference = as_source(source)

        t_import = time.perf_counter() - t0
        stages = ("render reference", "render fit", "metrics", "panels")
        with Progress(TextColumn("{task.description:<17}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                      TimeElapsedColumn(), console=console, transient=True) as bar:
            tasks = {s: bar.add_task(s, total=n_lights + (1 if s == "panels" else 0)) for s in stages}

            def progress(stage, k, n):
                if stage in tasks:
                    bar.update(tasks[stage], completed=k, total=n)

            v = validate(reference, fit, lights=default_lights(n_lights), size=size, out=out_path, force=force,
                         spp=spp or DEFAULT_SPP, progress=progress, renderer=chosen)
    from ..render.metrics import format_metric as fm

    o = v.metrics["overall"]
    line = (f"{out_path}: {len(v.files)} files; rmse {fm(o['rmse'], '.4g')}, relative rmse "
            f"{fm(o['rel_rmse'], '.3g')}, psnr {fm(o['psnr'], '.2f')} dB, flip {fm(o['flip'], '.4f')}")
    if any(o[k] != o[k] for k in ("rmse", "psnr", "flip")):
        line += " (n/a: the rendered images hold values that are not finite numbers)"
    click.echo(line)
    total = _since_process_start()
    startup = None if total is None else max(0.0, total - (time.perf_counter() - t0))
    # startup: Python and `import brdffit` (JAX) before this command ran
    times = {"startup": startup, "import + read inputs": t_import, **v.seconds}
    times = {k: s for k, s in times.items() if s is not None}
    console.print("time: " + ", ".join(f"{k} {s:.2f} s" for k, s in times.items())
                  + (f"; total since the process started {total:.2f} s" if total is not None else ""), style="dim")
    return 0
