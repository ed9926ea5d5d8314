"""Material files are valid for their format whatever the names and ids (docs/cli.md#the-command-line-and-set-up and docs/materials.md#native-materials-and-exports), through the
CLI and the Python API alike: XML that a strict parser (expat) reads, strict JSON (no bare NaN), the
user's id checked by one rule, a name taken from data made safe."""

from __future__ import annotations

import json
import struct
import xml.parsers.expat

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.errors import UsageError
from brdffit.fitting.result import FitResult
from brdffit.materials import export

FITS = {
    "ggx": {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.3], "f0": [0.1]},
    "mitsuba:roughplastic": {"diffuse_reflectance": [0.3, 0.2, 0.1], "alpha": [0.2], "int_ior": [1.5],
                             "specular_reflectance": [1.0, 1.0, 1.0]},
    "gltf:metallic_roughness": {"base_color": [0.8, 0.4, 0.2], "metallic": [0.3], "roughness": [0.45]},
    "blender:principled": {"base_color": [0.7, 0.3, 0.1], "metallic": [0.2], "roughness": [0.35], "ior": [1.5],
                           "specular_tint": [1.0]},
}
#: (model, extension): every text format a fit can be exported to without conversion (.blend: Blender's)
TEXT_EXPORTS = [("ggx", ".xml"), ("mitsuba:roughplastic", ".xml"), ("gltf:metallic_roughness", ".gltf"),
                ("gltf:metallic_roughness", ".glb"), ("gltf:metallic_roughness", ".mtlx"),
                ("blender:principled", ".mtlx")]
#: measurement names as they come: dashes that make '--' in a comment, a comment's end, controls, a
#: lone surrogate (a valid Python string that UTF-8 cannot encode), markup, non-ASCII text
NAMES = ["paint---v2", "a--", "-->", "x\x01y\x7f\x0b", "tab\tline\nend", "\ud800 lone", "<&>\"' ]]>", "漢字 ü"]
HOSTILE_IDS = ["x--y", "-->", "a\x01b", "a b", "1abc", "paint.v2", "", "<x>", "\ud800"]


def doc(model: str, **extra) -> dict:
    return {"format": "brdffit.fit/1", "model": model, "params": FITS[model], "converged": True, "loss": "log",
            "data_name": "paint", **extra}


def strict_json(raw: bytes | str):
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(raw, parse_constant=refuse)


def xml_ok(raw: bytes) -> None:
    """expat, strict XML 1.0: refuses '--' inside a comment, forbidden characters, bad UTF-8."""
    xml.parsers.expat.ParserCreate().Parse(raw, True)


def check_file(path, ext: str) -> dict:
    """The file is valid for its format; returns what it records of the fit (its brdffit extras)."""
    raw = path.read_bytes()
    if ext == ".xml":
        xml_ok(raw)
        return {}
    if ext == ".mtlx":
        xml_ok(raw)
        import MaterialX as mx

        d = mx.createDocument()
        mx.readFromXmlString(d, raw.decode("utf-8"))
        (material,) = d.getMaterialNodes()
        return strict_json(material.getAttribute("brdffit"))["brdffit"]
    if ext == ".glb":
        json_len, json_type = struct.unpack_from("<II", raw, 12)
        assert json_type == 0x4E4F534A
        raw = raw[20:20 + json_len]
    gltf = strict_json(raw)
    return gltf["materials"][0]["extras"]["brdffit"]


@pytest.mark.parametrize("name", NAMES, ids=[ascii(n) for n in NAMES])
@pytest.mark.parametrize("model,ext", TEXT_EXPORTS, ids=[f"{m}{e}" for m, e in TEXT_EXPORTS])
def test_any_data_name_gives_a_valid_file_through_python(tmp_path, name, model, ext):
    fit = FitResult.from_dict(doc(model, data_name=name))
    export(fit, tmp_path / f"paint{ext}")
    extras = check_file(tmp_path / f"paint{ext}", ext)
    if extras:
        assert extras["data_name"].replace("\ufffd", "") == name.replace("\ud800", "")


@pytest.mark.parametrize("model,ext", TEXT_EXPORTS, ids=[f"{m}{e}" for m, e in TEXT_EXPORTS])
def test_any_data_name_gives_a_valid_file_through_the_cli(tmp_path, capsys, model, ext):
    for k, name in enumerate(n for n in NAMES if "\ud800" not in n):  # a fit file with one is refused on reading
        src = tmp_path / f"fit{k}.json"
        src.write_text(json.dumps(doc(model, data_name=name)))
        out = tmp_path / f"paint{k}{ext}"
        assert main(["export", str(src), "-o", str(out)]) == 0, capsys.readouterr().err
        check_file(out, ext)
    if ext == ".xml":  # standard output too
        capsys.readouterr()
        assert main(["export", str(src)]) == 0
        xml_ok(capsys.readouterr().out.encode())


@pytest.mark.parametrize("bsdf_id", HOSTILE_IDS, ids=[ascii(i) for i in HOSTILE_IDS])
def test_a_hostile_id_is_refused_alike_by_the_cli_and_python(tmp_path, capsys, bsdf_id):
    fit = FitResult.from_dict(doc("ggx"))
    for ext in (".xml", ".mtlx"):
        with pytest.raises(UsageError) as info:
            export(fit if ext == ".xml" else FitResult.from_dict(doc("gltf:metallic_roughness")),
                   tmp_path / f"m{ext}", bsdf_id=bsdf_id)
        assert "\n" not in str(info.value) and "letters, digits and '_'" in str(info.value)
    src = tmp_path / "fit.json"
    src.write_text(json.dumps(doc("ggx")))
    capsys.readouterr()
    if "\ud800" not in bsdf_id:  # (a command line cannot carry one)
        assert main(["export", str(src), "-o", str(tmp_path / "m.xml"), "--id", bsdf_id]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "letters, digits and '_'" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.json"]


def bsdf_id_of(path) -> str:
    import xml.etree.ElementTree as ET

    return ET.parse(path).getroot().find("bsdf").get("id")


def test_ids_made_from_file_names_are_valid(tmp_path, capsys):
    """Where the id is not the user's choice (the file's or the folder's name), it is made to follow
    the rule the user's id is held to."""
    from brdffit.materials import check_id

    for stem, made, folder_made in (("2024 paint--v2", "m_2024_paint__v2", "m_2024_paint__v2_fit"),
                                    ("-->", "___", "____fit"), ("1", "m_1", "m_1_fit"), ("é", "_", "__fit")):
        out = tmp_path / f"{stem}.xml"
        export(FitResult.from_dict(doc("ggx")), out)
        xml_ok(out.read_bytes())
        assert bsdf_id_of(out) == made and check_id(made) == made
        folder = tmp_path / f"{stem} fit"
        folder.mkdir()
        (folder / "fit.json").write_text(json.dumps(doc("mitsuba:roughplastic")))
        capsys.readouterr()
        assert main(["export", str(folder / "fit.json"), "-o", str(folder / "m.xml")]) == 0
        xml_ok((folder / "m.xml").read_bytes())
        assert bsdf_id_of(folder / "m.xml") == folder_made  # fit.json: its folder's name


def test_non_finite_metrics_never_reach_a_file_as_bare_nan(tmp_path, capsys):
    """A fit.json holding NaN and Infinity metrics (Python's json writes them; so did brdffit's own
    writer) exports as strict JSON, the numbers null or left out; the fit written again is strict too."""
    text = json.dumps(doc("gltf:metallic_roughness", metrics={"rel_rmse": float("nan"), "rmse": float("inf"),
                                                              "log_rmse": 0.1}, loss_value=float("nan")))
    assert "NaN" in text
    src = tmp_path / "fit.json"
    src.write_text(text)
    for ext in (".gltf", ".glb", ".mtlx"):
        assert main(["export", str(src), "-o", str(tmp_path / f"m{ext}")]) == 0, capsys.readouterr().err
        extras = check_file(tmp_path / f"m{ext}", ext)
        assert extras["metrics"]["log_rmse"] == 0.1 and extras["metrics"].get("rel_rmse") is None
        export(FitResult.from_json(src), tmp_path / f"api{ext}")
        check_file(tmp_path / f"api{ext}", ext)
    fit = FitResult.from_json(src)
    again = strict_json(fit.to_json())
    assert again["metrics"]["rel_rmse"] is None and again["loss_value"] is None
    back = FitResult.from_json(fit.to_json())
    assert np.isnan(back.metrics["rel_rmse"]) and np.isnan(back.loss_value) and back.metrics["log_rmse"] == 0.1


def test_a_blend_file_records_strict_json(blender, tmp_path):
    fit = FitResult.from_dict(doc("blender:principled", data_name="paint---v2\x01",
                                  metrics={"rel_rmse": float("nan"), "log_rmse": 0.2}))
    export(fit, tmp_path / "m.blend")
    ((name, mat),) = blender.inspect(tmp_path / "m.blend").items()
    recorded = strict_json(mat["properties"]["brdffit"])["brdffit"]
    assert name == "m" and recorded["metrics"] == {"rel_rmse": None, "log_rmse": 0.2}
