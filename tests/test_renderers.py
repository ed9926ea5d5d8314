"""The renderers behind one registry (docs/validation.md#a-second-renderer-cycles): names, choices and
refusals come from it, a new entry is all a renderer needs, and no other module looks at a
renderer's name. (Renders themselves: test_render_sphere.py, test_render_cycles.py.)"""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import brdffit
from brdffit.cli import main
from brdffit.errors import UsageError
from brdffit.render import renderers
from brdffit.render.bsdf import as_source

PACKAGE = Path(brdffit.__file__).resolve().parent
PRINCIPLED = {"base_color": [0.6, 0.3, 0.15], "metallic": 0.0, "roughness": 0.35, "ior": 1.5, "specular_tint": 1.0}
GGX = {"kd": [0.3, 0.2, 0.1], "ks": [0.5, 0.5, 0.5], "alpha": 0.2, "f0": 0.04}


def test_names_and_lookup():
    assert renderers.names() == ("mitsuba", "cycles")  # the default, which renders every source, first
    assert renderers.get(" Cycles ") is renderers.RENDERERS["cycles"]
    with pytest.raises(UsageError, match=r"renderer 'povray': use one of mitsuba, cycles$"):
        renderers.get("povray")


def test_what_each_renderer_can_render():
    """Mitsuba renders any source; Cycles a blender:principled fit only, with Blender's Principled
    settings (the fit's own ``native()``), and says in one line what to do with another fit."""
    principled, ggx = as_source(("blender:principled", PRINCIPLED)), as_source(("ggx", GGX))
    mitsuba, cycles = renderers.get("mitsuba"), renderers.get("cycles")
    assert mitsuba.can_render(ggx) and mitsuba.can_render(principled)
    assert cycles.can_render(principled) and not cycles.can_render(ggx)
    with pytest.raises(UsageError, match=r"this fit is ggx: convert it first .*blender:principled"):
        cycles.check(ggx)
    material = cycles.material(principled)
    assert material == brdffit.models.get("blender:principled").native({k: np.asarray(v) for k, v in PRINCIPLED.items()})


def test_a_new_renderer_is_one_entry(monkeypatch):
    """render_sphere takes what an entry renders, checks what it is given first, and passes the
    framing's mask and the light directions."""
    seen = {}

    def render(src, dirs, size, irradiance, spp, seed, mask, progress):
        seen.update(label=src.label, dirs=dirs, spp=spp)
        return np.where(mask[None, ..., None], 1.0, 0.0).repeat(len(dirs), 0).repeat(3, -1).astype(np.float32)

    flat = renderers.Renderer("flat", " (flat)", material=lambda src: None, render=render)
    monkeypatch.setitem(renderers.RENDERERS, "flat", flat)
    images = brdffit.render_sphere(("ggx", GGX), [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]], size=8, spp=2, renderer="FLAT")
    assert images.shape == (2, 8, 8, 3) and images[:, 0, 0].sum() == 0 and images[:, 4, 4].min() == 1.0
    assert np.allclose(seen["dirs"], [[0, 0, 1], [0.6, 0, 0.8]]) and seen["spp"] == 2
    refusing = dataclasses.replace(flat, material=lambda src: renderers.get("cycles").check(src))
    monkeypatch.setitem(renderers.RENDERERS, "flat", refusing)
    assert renderers.choices() == "mitsuba (default) | cycles | flat"
    with pytest.raises(UsageError, match="convert it first"):
        renderers.get("flat").check(as_source(("ggx", GGX)))


def test_the_cli_takes_its_choices_from_the_registry(tmp_path, capsys, monkeypatch):
    assert main(["validate", "--help"]) == 0
    assert "mitsuba (default) | cycles" in " ".join(capsys.readouterr().out.split())
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": "ggx", "converged": True, "params": {k: np.atleast_1d(v).tolist()
                                                                             for k, v in GGX.items()}}))
    source = tmp_path / "missing-is-not-read.npz"
    source.write_bytes(b"")  # a renderer refusal comes before the reference is read
    for renderer, said in (("povray", "renderer 'povray': use one of mitsuba, cycles"),
                           ("cycles", "this fit is ggx: convert it first")):
        assert main(["validate", str(source), str(fit), "-o", str(tmp_path / "out"), "--renderer", renderer]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and said in err and "Traceback" not in err, err
        assert not (tmp_path / "out").exists()


def _names_a_renderer(side) -> bool:
    values = [side] if isinstance(side, ast.Constant) else list(getattr(side, "elts", []))
    return any(isinstance(v, ast.Constant) and v.value in renderers.names() for v in values)


def test_only_the_registry_looks_at_a_renderer_name():
    """No ``renderer == "cycles"`` (or ``in ("mitsuba", ...)``) outside brdffit/render/renderers.py: a
    renderer's behaviour is its entry's, not a switch somewhere else. (A native model's ``target``,
    the renderer its parameters belong to, is the model's, not a choice of renderer.)"""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "renderers.py" and path.parent.name == "render":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                if any(_names_a_renderer(s) for s in sides) and any("renderer" in ast.unparse(s) for s in sides):
                    found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {ast.unparse(node)}")
    assert found == []
