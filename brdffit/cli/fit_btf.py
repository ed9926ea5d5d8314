"""``brdffit fit-btf FOLDER --model M [-o DIR]``: per-texel fit of a BTF (SPEC 7, 10).

Writes DIR/params.exr (one part per parameter, plus loss / converged / steps), preview PNGs, maps.png
and summary.json (see :mod:`brdffit.btf.maps`). Finished tiles are kept in DIR/tiles while the run
goes on: run the same command again after an interruption and it resumes. Exit 1 when some
texels did not converge (the maps are still written; ``converged`` marks them).
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
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path), help="Output folder [fitbtf-<name>-<model>].")
@click.option("--force", is_flag=True, help="Replace an existing result (or the tiles of another run).")
def fit_btf_command(folder, model, loss, solver, region, step, includes_cos, scale, tile, cache_dir, out, force) -> int:
    """Fit MODEL to every texel of the BTF in FOLDER (an image folder or a .zip archive)."""
    from rich.console import Console

    from ..btf import fit_btf, load_btf
    from ..errors import UsageError
    from ..fitting.losses import check_loss
    from ..fitting.problem import resolve_model

    check_loss(loss)
    resolve_model(model, 3)  # an unknown model is a usage error before any work
    src = Path(folder)
    out = out or Path(f"fitbtf-{src.stem}-{model.replace('+', '_')}")
    if out.exists() and not force:
        if (out / "params.exr").exists():
            raise UsageError(f"{out}: already exists (use --force to replace it)")
        if any(out.iterdir()) and not (out / "tiles" / "run.json").is_file():
            raise UsageError(f"{out}: exists and is not an interrupted fit-btf run (use --force to replace it)")
    console = Console(stderr=True)
    btf = load_btf(src, region=_region(region), step=step, includes_cos=includes_cos, scale=scale, tile=tile,
                   cache_dir=cache_dir, progress=True)
    mem = btf.memory()
    console.print(f"{btf!r}; memory: read buffer {mem['read_buffer'] / 2**20:.0f} MB, "
                  f"one tile {mem['tile'] / 2**20:.1f} MB", soft_wrap=True)
    options = {} if solver is None else {"solver": solver}
    maps = fit_btf(btf, model, loss=loss, out=out, force=force, **options)
    n_bad = int(maps.loss.size - maps.converged.sum())
    console.print(repr(maps), soft_wrap=True)
    console.print(f"wrote {out}/params.exr, previews and summary.json")
    if n_bad:
        console.print(f"[bold red]{n_bad} texels did not converge[/] (marked in the converged map)")
        return EXIT_NOT_CONVERGED
    return EXIT_OK
