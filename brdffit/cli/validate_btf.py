"""``brdffit validate-btf FOLDER DIR/params.exr [-o DIR]``: the fitted maps rendered in Mitsuba 3
beside the BTF's photographs of chosen (light, view) pairs (docs/btf.md#btfs-per-texel-fitting and docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

from pathlib import Path

import click

from . import cli
from ._help import DefaultFrom


def _pairs(text: str | None):
    if text is None:
        return None
    pairs = []
    for item in text.split(";"):
        try:
            tl, pl, tv, pv = (int(x) for x in item.replace(" ", "").split(","))
        except ValueError:
            raise click.BadParameter(f"{item!r}: expected TL,PL,TV,PV in degrees, pairs separated by ';'") from None
        pairs.append(((tl, pl), (tv, pv)))
    return pairs


@cli.command("validate-btf")
@click.argument("folder", type=click.Path(path_type=str))
@click.argument("params", metavar="PARAMS.exr", type=click.Path(path_type=str))
@click.option("--pairs", default=None, cls=DefaultFrom, default_from="brdffit.btf.validate:DEFAULT_PAIRS_DEG",
              describe=lambda pairs: f"{len(pairs)} pairs from head-on to grazing", help="TL,PL,TV,PV;... (degrees).")
@click.option("-o", "--out", "out", default=None, type=click.Path(path_type=Path),
              help="Output folder [validate-btf beside PARAMS.exr].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--cache-dir", type=click.Path(path_type=Path), default=None, help="Folder for the BTF cache [temporary].")
def validate_btf_command(folder, params, pairs, out, force, cache_dir) -> int:
    """Render the maps in PARAMS.exr on a textured square for (light, view) pairs of the BTF in
    FOLDER and compare with its photographs: EXRs, panels, metrics.json."""
    from .._files import reserve
    from ..btf import load_btf
    from ..btf.maps import ParameterMaps
    from ..btf.validate import DEFAULT_PAIRS_DEG, pair_indices, validate_btf

    chosen = _pairs(pairs) or DEFAULT_PAIRS_DEG
    pair_indices(chosen)  # bad pairs: usage error before any work
    out = out or Path(params).resolve().parent / "validate-btf"
    with reserve(out, force, folder=True):  # before any work: another run writing it is refused now
        maps = ParameterMaps.load(params)
        o = maps.info.get("btf_options", {})
        btf = load_btf(folder, region=o.get("region"), step=o.get("step", 1), includes_cos=o.get("includes_cos", False),
                       scale=o.get("scale", 1.0), srgb=o.get("srgb", True), cache_dir=cache_dir, progress=True)
        v = validate_btf(btf, maps, chosen, out=out, force=force)
    ov = v.metrics["overall"]
    click.echo(f"{out}: {len(v.files)} files; rmse {ov['rmse']:.4g}, relative rmse {ov['rel_rmse']:.3g}, "
               f"psnr {ov['psnr']:.2f} dB (worst pair {ov['psnr_min']:.2f}), flip {ov['flip']:.4f}")
    return 0
