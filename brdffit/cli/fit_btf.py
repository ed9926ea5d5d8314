"""``brdffit fit-btf FOLDER --model M [-o DIR] [--scheduler ADDRESS]``: per-texel fit of a BTF, or of
every BTF of a database folder (docs/btf.md#btfs-per-texel-fitting and docs/cli.md#the-command-line-and-set-up).

Writes DIR/params.exr (one part per parameter, plus loss / converged / steps), preview PNGs, maps.png
and summary.json (see :mod:`brdffit.btf.maps`). Finished tiles are kept in DIR/tiles while the run
goes on: run the same command again after an interruption and it resumes. A FOLDER of BTFs
(:mod:`brdffit.btf.database`) gives DIR/<name>/ per BTF and a summary table (printed, and written
as DIR/summary.csv and summary.json). ``--scheduler`` fits the tiles on a Dask cluster
(:mod:`brdffit.btf.cluster`). Exit 1 when some texels did not converge (the maps are still
written; ``converged`` marks them).
"""

from __future__ import annotations

from pathlib import Path

import click

from .._fit_defaults import DEFAULT_LOSS as _LOSS
from .._fit_defaults import LOSSES as _LOSSES
from . import EXIT_NOT_CONVERGED, EXIT_OK, cli
from ._help import DefaultFrom


def _region(text: str | None):
    if text is None:
        return None
    try:
        r = tuple(int(x) for x in text.replace(" ", "").split(","))
    except ValueError:
        raise click.BadParameter("expected ROW0,ROW1,COL0,COL1") from None
    if len(r) != 4:
        raise click.BadParameter("expected ROW0,ROW1,COL0,COL1")
    return r


@cli.command("fit-btf")
@click.argument("folder", type=click.Path(path_type=str))
@click.option("--model", "-m", "model", required=True, help="Model name, e.g. ggx or lambert+ggx.")
@click.option("--loss", default=_LOSS, show_default=True, help=" | ".join(_LOSSES))
@click.option("--solver", default=None, cls=DefaultFrom, default_from="brdffit.fitting.api:fit_batch(solver)",
              help="Solver of fit_batch.")
@click.option("--region", default=None, help="ROW0,ROW1,COL0,COL1 of the photographs (slice bounds).")
@click.option("--step", type=click.IntRange(1), default=1, show_default=True, help="Fit every STEP-th texel.")
@click.option("--includes-cos", is_flag=True, help="Pixel values include cos(theta_light).")
@click.option("--scale", type=float, default=1.0, show_default=True, help="Multiply pixel values by this.")
@click.option("--tile", type=click.IntRange(1, 256), default=16, show_default=True, help="Tile edge in texels.")
@click.option("--cache-dir", type=click.Path(path_type=Path), default=None, help="Folder for the BTF cache [temporary].")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Fit the tiles on the Dask cluster of the scheduler at ADDRESS (e.g. tcp://host:8786; needs "
                   "brdffit[cluster]). OUT, and --cache-dir or the BTF, on a file system the workers share.")
@click.option("--processes", type=click.IntRange(1), default=None,
              help="On a CPU, worker processes of one core each that fit the tiles; 1: this process alone "
                   "[one per core, where the system allows it].")
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [fitbtf-<name>-<model>].")
@click.option("--force", is_flag=True, help="Replace an existing result (or the tiles of another run).")
def fit_btf_command(folder, model, loss, solver, region, step, includes_cos, scale, tile, cache_dir, scheduler,
                    processes, out, force) -> int:
    """Fit MODEL to every texel of the BTF in FOLDER (an image folder or a .zip archive), or of
    every BTF in FOLDER when it holds several (a database: each into OUT/<name>/, with
    OUT/summary.csv and OUT/summary.json; run it again to resume)."""
    from ..btf.database import is_database
    from ..fitting.losses import check_loss
    from ..fitting.problem import resolve_model

    check_loss(loss)
    resolve_model(model, 3)  # an unknown model is a usage error before any work
    src = Path(folder)
    out = out or Path(f"fitbtf-{src.stem}-{model.replace('+', '_')}")
    read = {"region": _region(region), "step": step, "includes_cos": includes_cos, "scale": scale, "tile": tile,
            "cache_dir": cache_dir}
    options = {**({} if solver is None else {"solver": solver}), **({} if processes is None else {"processes": processes})}
    run = _fit_database if is_database(src) else _fit_one
    if scheduler is None:
        return run(src, model, loss, out, force, read, options, client=None)
    from ..btf.cluster import connect

    with connect(scheduler) as client:
        return run(src, model, loss, out, force, read, options, client=client)


def _fit_one(src: Path, model, loss, out: Path, force: bool, read: dict, options: dict, client) -> int:
    from rich.console import Console

    from ..btf import fit_btf, load_btf
    from ..errors import UsageError

    if out.exists() and not force:
        if (out / "params.exr").exists():
            raise UsageError(f"{out}: already exists (use --force to replace it)")
        if any(out.iterdir()) and not (out / "tiles" / "run.json").is_file():
            raise UsageError(f"{out}: exists and is not an interrupted fit-btf run (use --force to replace it)")
    console = Console(stderr=True)
    btf = load_btf(src, **read, progress=True)
    mem = btf.memory()
    console.print(f"{btf!r}; memory: read buffer {mem['read_buffer'] / 2**20:.0f} MB, "
                  f"one tile {mem['tile'] / 2**20:.1f} MB", soft_wrap=True)
    maps = fit_btf(btf, model, loss=loss, out=out, force=force, client=client, **options)
    n_bad = int(maps.loss.size - maps.converged.sum())
    console.print(repr(maps), soft_wrap=True)
    console.print(f"wrote {out}/params.exr, previews and summary.json")
    return _status(console, n_bad)


def _fit_database(src: Path, model, loss, out: Path, force: bool, read: dict, options: dict, client) -> int:
    from rich.console import Console

    from ..btf.database import fit_btf_database

    console = Console(stderr=True)
    result = fit_btf_database(src, model, loss=loss, out=out, force=force, client=client, **read, **options)
    click.echo(result.table())
    console.print(f"wrote {out}/<material>/ for {len(result.rows)} materials, {out}/summary.csv and summary.json")
    return _status(console, result.not_converged)


def _status(console, n_bad: int) -> int:
    if n_bad:
        console.print(f"[bold red]{n_bad} texels did not converge[/] (marked in the converged map)")
        return EXIT_NOT_CONVERGED
    return EXIT_OK
