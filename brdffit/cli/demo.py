"""``brdffit demo [-o DIR] [--force]``: the pipeline on the bundled sample (SPEC 7)."""

from __future__ import annotations

import click

from . import cli


@cli.command("demo")
@click.option("-o", "--out", "out", default="brdffit-demo", show_default=True, type=click.Path(path_type=str),
              help="Folder for the results (written atomically).")
@click.option("--force", is_flag=True, help="Replace DIR if it exists.")
def demo(out: str, force: bool) -> int:
    """Run load, info, convert and a table plot on the sample measurement in data/."""
    from ..demo import run_demo

    written = run_demo(out, force=force)
    click.echo(f"demo finished: {len(written)} files in {out}")
    return 0
