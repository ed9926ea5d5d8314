"""``brdffit export FIT.json [--to MODEL] [-o FILE]``: the fit as a material file (docs/materials.md#a-fit-in-any-mitsuba-scene, docs/cli.md#the-command-line-and-set-up, docs/materials.md#native-materials-and-exports)."""

from __future__ import annotations

from pathlib import Path

import click

from . import cli
from ._help import HelpFrom

_FORMATS = "brdffit.materials.formats:help_text", "brdffit.materials.formats:maps_help_text"


@cli.command("export")
@click.argument("fit_json", metavar="FIT.json|PARAMS.exr", type=click.Path(path_type=str))
@click.option("-o", "--out", "out", type=click.Path(path_type=str), default=None, cls=HelpFrom, help_from=_FORMATS,
              help="Material file to write; its extension picks the format: {} [default: Mitsuba XML on standard "
                   "output]. Parameter maps (PARAMS.exr): {}.")
@click.option("--to", "to", default=None, metavar="MODEL",
              help="Convert the fit to this native model first (e.g. mitsuba:roughplastic, gltf:metallic_roughness): "
                   "fitted to the fit's BRDF on the UBO-81 grid; the conversion error is printed and stored in the file.")
@click.option("--id", "bsdf_id", default=None,
              help="The material's id (Mitsuba: <ref id=...>; glTF: its name) [default: the file name of FIT.json's folder].")
@click.option("--force", is_flag=True, help="Replace an existing FILE.")
def export_cmd(fit_json: str, out: str | None, to: str | None, bsdf_id: str | None, force: bool) -> int:
    """Write the fit in FIT.json as a material other programs load, in the format FILE's extension
    names (-o). A native fit (a renderer's own model: `brdffit models`) becomes that renderer's own
    material, which loads without brdffit; a format that holds only native models says which to
    convert to (--to). Any other fit in Mitsuba XML is <bsdf type="brdffit"> (load the scene after
    `import brdffit; brdffit.register_mitsuba()`). Include an XML fragment in a scene with
    <include filename="FILE"/> and refer to it with <ref id="ID"/>. A PARAMS.exr of fit-btf (maps of
    a native model) becomes the same material with every map a texture."""
    if Path(fit_json).suffix.lower() == ".exr":
        from .export_maps import export_maps_cmd

        return export_maps_cmd(fit_json, out, to, bsdf_id, force)
    import contextlib

    from .._files import reserve
    from ..errors import InputError
    from ..fitting.result import FitResult
    from ..materials import (check_format, check_id, conversion_line, convert, describe, export, material_bytes,
                             safe_id)

    path = Path(fit_json)
    if not path.is_file():
        raise InputError(fit_json, "no such file")
    fit = FitResult.from_json(path)
    ext = check_format(fit, out if out is not None else "stdout.xml", to, source=fit_json)
    if bsdf_id is None:
        parent = path.resolve().parent.name
        bsdf_id = safe_id(parent if path.stem == "fit" and parent else path.stem)
    check_id(bsdf_id)
    with contextlib.ExitStack() as stack:
        if out is not None:  # taken before any work: a place another run writes, or that cannot be written, is refused now
            stack.enter_context(reserve(out, force, folder=False))
        if not fit.converged:
            click.echo(f"brdffit: {fit_json}: the fit did not converge (exported anyway, marked in the file)", err=True)
        if to is not None:
            fit = convert(fit, to)
            click.echo(f"brdffit: {conversion_line(fit) or f'{fit.model.name}: nothing to convert'}", err=True)
            if not fit.converged:
                click.echo(f"brdffit: the conversion to {fit.model.name} did not converge ({fit.status}); "
                           "exported anyway", err=True)
        if out is None:
            click.echo(material_bytes(fit, ext, bsdf_id).decode(), nl=False)
            return 0
        export(fit, out, bsdf_id=bsdf_id, force=force)
    click.echo(f"wrote {out}: {describe(fit, ext)}, id {bsdf_id!r} ({fit.model.name})", err=True)
    return 0
