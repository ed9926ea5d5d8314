"""``brdffit demo [-o DIR] [--force]``: the pipeline on the bundled sample (docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

import click

from . import cli


@cli.command("demo")
@click.option("-o", "--out", "out", default="brdffit-demo", show_default=True, type=click.Path(path_type=str),
              help="Folder for the results (written atomically).")
@click.option("--force", is_flag=True, help="Replace DIR if it exists.")
def demo(out: str, force: bool) -> int:
    """The whole pipeline on the sample in data/: load, info, convert, fit, compare, validate."""
    from .._files import check_target
    from ..demo import run_demo
    from . import EXIT_NOT_CONVERGED, EXIT_OK

    check_target(out, force, folder=True)  # before any work
    return EXIT_OK if run_demo(out, force=force).converged else EXIT_NOT_CONVERGED
