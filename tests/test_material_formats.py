"""The material formats as a registry: each format module of brdffit/materials declares its
extensions, the models it holds and its writer; the CLI's help and the messages that name formats
or held models are read from the registry; a native model that a format holds by its renderer is
held as soon as its model file exists (one file, no table to edit)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from click.testing import CliRunner

from brdffit import models
from brdffit.errors import UsageError
from brdffit.fitting.result import FitResult
from brdffit.materials import check_format, formats

#: What the package's format modules hold today (written out here, not read from the code).
NATIVE = ["blender:principled", "gltf:metallic_roughness", "mitsuba:principled", "mitsuba:roughconductor",
          "mitsuba:roughplastic"]
FITS = {".blend": ("blender:principled",), ".glb": ("gltf:metallic_roughness",), ".gltf": ("gltf:metallic_roughness",),
        ".mtlx": ("gltf:metallic_roughness", "blender:principled"), ".xml": ()}
MAPS = {".blend": ("blender:principled",), ".glb": ("gltf:metallic_roughness",), ".gltf": ("gltf:metallic_roughness",),
        ".xml": ("mitsuba:principled", "mitsuba:roughconductor", "mitsuba:roughplastic")}


def test_the_registry_finds_every_format_module_and_what_each_holds():
    assert {ext: formats.for_path(f"m{ext}").held() for ext in formats.extensions()} == FITS
    assert {ext: formats.for_path(f"m{ext}", maps=True).held() for ext in formats.extensions(maps=True)} == MAPS
    assert formats.for_path("m.xml").holds("lambert+ggx") and not formats.for_path("m.glb").holds("ggx")
    modules = {name: importlib.import_module(f"brdffit.materials.{name}") for name in
               ("blender", "gltf", "materialx", "mitsuba_xml", "textured_blender", "textured_gltf", "textured_mitsuba")}
    assert formats.formats() == tuple(modules[n].FORMAT for n in ("blender", "gltf", "materialx", "mitsuba_xml"))
    assert formats.formats(maps=True) == tuple(modules[n].MAPS_FORMAT for n in
                                               ("textured_blender", "textured_gltf", "textured_mitsuba"))


def test_the_native_models_are_read_from_the_model_files():
    """``models/base.py`` listed them by hand and left out ``blender:principled``."""
    assert models.native_names() == NATIVE
    with pytest.raises(ValueError) as info:
        models.get("ggx").native({"kd": 0.1, "ks": 0.5, "alpha": 0.2, "f0": 0.04})
    assert str(info.value).endswith("native models: " + ", ".join(NATIVE))


def test_a_new_native_model_of_a_formats_renderer_is_held_without_editing_the_format(monkeypatch):
    """A ``gltf:*`` model file is all a glTF export needs: the format holds it by its renderer, and
    the messages that name what the format holds name it too."""
    assert formats.for_path("m.glb").holds("gltf:specular_glossiness")
    assert not formats.for_path("m.glb").holds("gltfx:metallic_roughness")
    monkeypatch.setattr(models, "native_names", lambda: [*NATIVE, "gltf:specular_glossiness"])
    assert formats.for_path("m.gltf").held() == ("gltf:metallic_roughness", "gltf:specular_glossiness")
    fit = FitResult.from_dict({"model": "ggx", "params": {"kd": [0.1], "ks": [0.5], "alpha": [0.2], "f0": [0.04]}})
    with pytest.raises(UsageError, match="holds a gltf:metallic_roughness or gltf:specular_glossiness material, and "
                                         "this fit is ggx: convert it with --to gltf:metallic_roughness"):
        check_format(fit, "paint.glb")


def test_help_and_errors_name_the_formats_of_the_registry():
    from brdffit.cli import _load_commands, cli

    _load_commands()
    text = " ".join(CliRunner().invoke(cli, ["export", "--help"]).output.split())
    for maps in (False, True):
        for f in formats.formats(maps=maps):
            assert f"{' or '.join(f.extensions)} ({f.name}" in text, (f.name, text)
    assert ".mtlx (MaterialX 1.39)" in text and ".blend (Blender; needs .venv-blender)" in text
    assert "Parameter maps (PARAMS.exr): .blend (Blender; needs .venv-blender), .glb or .gltf (glTF 2.0), .xml " \
           "(Mitsuba 3; bitmap textures in <stem>_textures beside it)." in text
    with pytest.raises(UsageError, match=r"unknown material format '\.obj'; use one of \.blend, \.glb, \.gltf, \.mtlx, \.xml$"):
        formats.for_path("paint.obj")
    with pytest.raises(UsageError, match=r"parameter maps export as \.blend, \.glb, \.gltf, \.xml$"):
        formats.for_path("paint.mtlx", maps=True)


def test_an_extension_declared_twice_is_refused(monkeypatch):
    """Two format modules claiming one extension would make the export's choice depend on the
    order of the files: the registry refuses it, naming the module."""
    import brdffit.materials.gltf as gltf

    monkeypatch.setattr(formats, "_FOUND", [])
    monkeypatch.setattr(gltf, "FORMAT", formats.Format("copy", (".xml",), gltf.FORMAT.write, gltf.FORMAT.describe))
    with pytest.raises(RuntimeError, match=r"\.xml is declared by another format too"):
        formats.formats()


def test_a_fit_exports_through_its_formats_writer(tmp_path):
    """``export`` writes what the format module's writer returns, for every format that needs no
    worker process (Blender's is tested with Blender)."""
    from brdffit.materials import export, material_bytes

    fit = FitResult.from_dict({"model": "gltf:metallic_roughness", "converged": True, "data_name": "x",
                               "params": {"base_color": [0.8, 0.4, 0.2], "metallic": [0.3], "roughness": [0.45]}})
    for ext in (".xml", ".gltf", ".mtlx"):
        written = export(fit, tmp_path / f"m{ext}", bsdf_id="m")
        assert written is fit
        assert (tmp_path / f"m{ext}").read_bytes() == formats.for_path(f"m{ext}").write(fit, ext, "m") == \
            material_bytes(fit, ext, "m")
    assert np.frombuffer((tmp_path / "m.gltf").read_bytes()[:1], np.uint8)[0] == ord("{")
