"""``brdffit models``: every model with its parameters, bounds and citation (docs/cli.md#the-command-line-and-set-up)."""

from __future__ import annotations

import click

from . import cli

#: Base models that are diffuse terms themselves.
_DIFFUSE = ("lambert", "oren_nayar")


def lambert_note(model) -> str:
    """One sentence when ``model`` already contains a Lambertian term kd/pi (so that
    ``lambert+<model>`` is the same function as ``<model>``), else ''."""
    if model.components:
        names = [c.name for c in model.components]
        rest = [c for c in model.components if c.name != "lambert"]
        if "lambert" in names and rest and all("kd" in c.param_names for c in rest):
            return (f"the same function as `{'+'.join(c.name for c in rest)}`, whose kd/pi already is the "
                    "Lambertian term (only the parameter names differ)")
        return ""
    if model.name in _DIFFUSE or "kd" not in model.param_names:
        return ""
    return (f"includes a Lambertian term kd/pi: `lambert+{model.name}` is the same function as "
            f"`{model.name}` (its parameters are then named {model.name}1.*)")


def mitsuba_note(model) -> str:
    """How a fit of ``model`` renders in Mitsuba (docs/materials.md#a-fit-in-any-mitsuba-scene and docs/materials.md#native-materials-and-exports), parameter maps included."""
    if model.target == "mitsuba":
        from ..materials.textured_mitsuba import TEXTURED

        plugin = model.name.split(":", 1)[1]
        numbers = [p for p in model.param_names if p not in TEXTURED[plugin]]
        return (f"Mitsuba's own {plugin} plugin, every variant; parameter maps as its textures"
                + (f" ({', '.join(numbers)}: one number each)" if numbers else ""))
    return "the brdffit plugin (this formula translated), every variant, symbolic, differentiable, maps as textures"


def describe(model) -> str:
    """Name, citation, parameter table (name, channels, bounds, default, role), and notes."""
    lines = [f"{model.name}  ({'reciprocal' if model.reciprocal else 'not reciprocal'})",
             f"  {model.citation.splitlines()[0] if model.citation else ''}"]
    lines += ["  " + row for row in model.table().splitlines()]
    note = lambert_note(model)
    if note:
        lines.append(f"  note: {note}")
    lines.append(f"  in Mitsuba: {mitsuba_note(model)}")
    return "\n".join(lines)


@cli.command("models")
@click.argument("names", nargs=-1)
def models_command(names: tuple[str, ...]) -> int:
    """List every model (or the NAMES given, composites such as lambert+ggx+ggx included) with its
    parameters, bounds, defaults, roles and citation."""
    from .. import models
    from ..fitting.problem import resolve_model

    chosen = [resolve_model(n, 3) for n in names] if names else [models.get(n) for n in models.names()]
    blocks = [describe(m) for m in chosen]
    if not names:
        blocks.append("Models compose with '+': lambert+ggx+ggx is one diffuse kd and two GGX lobes "
                      "(ggx1.*, ggx2.*). A model with kd already holds the diffuse term; adding lambert to it "
                      "changes only the parameter names.")
    click.echo("\n\n".join(blocks))
    return 0
