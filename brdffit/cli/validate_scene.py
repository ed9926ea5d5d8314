"""``brdffit validate-scene SCENE.xml ID FIT.json --reference SOURCE [-o DIR]`` (docs/scene.md#scene-aware-fitting)."""

from __future__ import annotations

from pathlib import Path

import click

from . import cli


@cli.command("validate-scene")
@click.argument("scene", metavar="SCENE.xml", type=click.Path(path_type=str))
@click.argument("material", metavar="ID")
@click.argument("fit_json", metavar="FIT.json", type=click.Path(path_type=str))
@click.option("--reference", "reference", required=True, type=click.Path(path_type=str),
              help="The measured material: an RGL .bsdf, a UBO table or another measurement file.")
@click.option("-o", "--out", "out", type=click.Path(path_type=str), default=None,
              help="Output folder [default: 'validate-scene' beside FIT.json].")
@click.option("--force", is_flag=True, help="Replace an existing output folder.")
@click.option("--spp", type=click.IntRange(1, 4096), default=64, show_default=True, help="Samples per pixel.")
def validate_scene_cmd(scene: str, material: str, fit_json: str, reference: str, out: str | None, force: bool,
                       spp: int) -> int:
    """Render SCENE.xml with the BSDF ID replaced by the fit in FIT.json and by the reference; write
    reference.exr, fit.exr, panel.png (reference | fit | FLIP) and metrics.json."""
    from rich.console import Console

    from .._files import reserve
    from ..errors import InputError
    from ..render.validate import as_fit, as_source
    from ..scene import validate_scene
    from ..scene.load import load_scene

    for path, what in ((scene, "no such scene file"), (fit_json, "no such file"), (reference, "no such file or folder")):
        if not Path(path).exists():
            raise InputError(path, what)
    out_path = Path(out) if out is not None else Path(fit_json).resolve().parent / "validate-scene"
    # taken before any work: nothing is written on bad usage, and another run writing it is refused now
    with reserve(out_path, force, folder=True):
        # read every input before rendering: bad input is one line, nothing else
        fit, ref = as_fit(fit_json), as_source(reference)
        load_scene(scene, material)
        console = Console(stderr=True)
        with console.status(f"rendering {scene} with {material!r} as the reference and as the fit"):
            v = validate_scene(scene, material, fit, ref, spp=spp, out=out_path, force=force)
    o = v.metrics["image"]
    click.echo(f"{out_path}: {len(v.files)} files; rmse {o['rmse']:.4g}, relative rmse {o['rel_rmse']:.3g}, "
               f"psnr {o['psnr']:.2f} dB, flip {o['flip']:.4f}")
    return 0
