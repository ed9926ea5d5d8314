"""``brdffit export PARAMS.exr -o FILE``: fitted parameter maps as a textured native material
(docs/btf.md#btfs-per-texel-fitting and docs/materials.md#native-materials-and-exports); ``brdffit export`` hands a ``.exr`` argument here (:mod:`brdffit.cli.export`)."""

from __future__ import annotations

from pathlib import Path

import click


def export_maps_cmd(params_exr: str, out: str | None, to: str | None, bsdf_id: str | None, force: bool) -> int:
    from ..btf.maps import ParameterMaps
    from ..errors import UsageError
    from ..materials import formats, safe_id

    if out is None:
        raise UsageError(f"{params_exr}: parameter maps export to a file with their textures: give -o FILE "
                         f"({formats.help_text(maps=True)})")
    maps = ParameterMaps.load(params_exr)
    if to is not None and "".join(to.split()).lower() != maps.model:
        raise UsageError(f"--to {to}: parameter maps are not converted ({params_exr} holds {maps.model} maps); "
                         f"fit the BTF with --model {to} instead")
    if bsdf_id is None:
        path = Path(params_exr)  # fit-btf's OUT/params.exr is named after OUT, as `export` names fit.json
        stem = path.resolve().parent.name if path.stem == "params" and path.resolve().parent.name else path.stem
        bsdf_id = safe_id(stem)
    written = maps.export(out, bsdf_id=bsdf_id, force=force, source=params_exr)
    missed = int(maps.converged.size - maps.converged.sum())
    if missed:
        click.echo(f"brdffit: {params_exr}: the fit did not converge at {missed} of {maps.converged.size} texels "
                   "(exported all the same)", err=True)
    h, w = maps.shape
    extra = f" and {written[0]}/" if len(written) > 1 else ""
    click.echo(f"wrote {out}{extra}: {maps.model} maps, {h} x {w} texels as textures, id {bsdf_id!r}", err=True)
    return 0
