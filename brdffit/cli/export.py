"""``brdffit export FIT.json [-o FILE]``: the fit as a Mitsuba 3 BSDF, scene-XML (SPEC 8, 10)."""

from __future__ import annotations

import re
from pathlib import Path

import click

from . import cli


@cli.command("export")
@click.argument("fit_json", metavar="FIT.json", type=click.Path(path_type=str))
@click.option("-o", "--out", "out", type=click.Path(path_type=str), default=None,
              help="XML file to write [default: standard output].")
@click.option("--id", "bsdf_id", default=None, help="The BSDF's id in the scene [default: the file name of FIT.json's folder].")
@click.option("--force", is_flag=True, help="Replace an existing FILE.")
def export_cmd(fit_json: str, out: str | None, bsdf_id: str | None, force: bool) -> int:
    """Write the fit in FIT.json as a Mitsuba 3 scene-XML fragment holding one
    <bsdf type="brdffit">: include it in a scene with <include filename="FILE"/>, refer to it with
    <ref id="ID"/>, and load the scene after `import brdffit; brdffit.register_mitsuba()`."""
    from .._files import atomic_file, check_target
    from ..errors import InputError, UsageError
    from ..fitting.result import FitResult
    from ..render.export import bsdf_xml

    path = Path(fit_json)
    if not path.is_file():
        raise InputError(fit_json, "no such file")
    if out is not None:
        check_target(out, force)  # before any work: nothing is written on bad usage
    fit = FitResult.from_json(path)
    if bsdf_id is None:
        parent = path.resolve().parent.name
        bsdf_id = re.sub(r"[^A-Za-z0-9_]", "_", parent if path.stem == "fit" and parent else path.stem) or "brdffit"
    elif not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", bsdf_id):
        raise UsageError(f"--id {bsdf_id!r}: use letters, digits and '_' (Mitsuba ids cannot hold '.')")
    text = bsdf_xml(fit, bsdf_id=bsdf_id)
    if not fit.converged:
        click.echo(f"brdffit: {fit_json}: the fit did not converge (exported anyway, marked in the XML)", err=True)
    if out is None:
        click.echo(text, nl=False)
        return 0
    with atomic_file(out, force=force) as tmp:
        tmp.write_text(text)
    click.echo(f"wrote {out}: <bsdf type=\"brdffit\" id=\"{bsdf_id}\"> ({fit.model.name})", err=True)
    return 0
