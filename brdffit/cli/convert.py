"""``brdffit convert SOURCE OUT``: any readable source to a UBO-81 EXR or NPZ table (docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

from pathlib import Path

import click

from . import cli


@cli.command("convert")
@click.argument("source", type=click.Path(path_type=str))
@click.argument("out", type=click.Path(path_type=str))
@click.option("--force", is_flag=True, help="Replace OUT if it exists.")
def convert(source: str, out: str, force: bool) -> int:
    """Resample SOURCE onto the UBO-81 grid and write OUT (.exr or .npz), atomically."""
    from .._files import reserve
    from ..errors import UsageError
    from ..io import WRITERS, resample, save

    if Path(out).suffix.lower() not in WRITERS:
        raise UsageError(f"{out}: output must end in .exr or .npz")
    # checked, writable and locked against other runs before the (possibly long) read
    with reserve(out, force, folder=False):
        m = resample(source, progress=True)
        save(m, out, force=force)
    extra = ""
    if "extrapolated" in m.meta:
        extra = f"; {m.meta['extrapolated']} samples extrapolated (max {m.meta.get('max_extrapolation_deg', 0):.1f} deg)"
    click.echo(f"wrote {out}: {m.name}, UBO-81, {m.n_channels} channels{extra}")
    return 0
