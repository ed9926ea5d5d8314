"""What brdffit says about a fit and an export is what it is (docs/fitting.md#fitting and docs/materials.md#native-materials-and-exports): a bound warning names each
side where it applies, the line after an export names what the file holds, a converted file's
metrics are named as the error against the source fit, and a conversion from a fit that is zero
everywhere has no relative error (it printed rel_rmse 1e150)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdffit import models
from brdffit.cli import main
from brdffit.fitting.result import FitResult
from brdffit.fitting.space import fit_warnings, parameter_space
from brdffit.materials import convert

GGX = {"kd": [0.2, 0.3, 0.1], "ks": [0.6, 0.5, 0.4], "alpha": [0.3], "f0": [0.1]}


def write(folder, model: str, params: dict, **extra):
    p = folder / "fit.json"
    p.write_text(json.dumps({"model": model, "params": params, "converged": True, "loss": "log",
                             "data_name": "paint", **extra}))
    return p


def test_a_bound_warning_says_each_side_with_its_own_value():
    """kd on its lower bound in channel 2 and on its upper bound in channel 0 (per-channel at_bound):
    one clause per side (it read "kd ended on its lower in channel 2; upper in channel 0 bound 0")."""
    space = parameter_space(models.get("ggx"), bounds={"kd": (0.0, 0.5), "alpha": (0.05, 0.9)})
    v = space.clip(np.concatenate([[0.5, 0.2, 0.0], [0.3] * 3, [0.05], [0.1]]))
    at_bound = space.at_bound(v)
    assert at_bound == {"kd": "lower in channel 2; upper in channel 0", "alpha": "lower"}
    assert fit_warnings(space, v, at_bound, {}, None) == [
        "kd ended on its lower bound 0 in channel 2 (set by bounds=) and on its upper bound 0.5 in channel 0 "
        "(set by bounds=).",
        "alpha ended on its lower bound 0.05 (set by bounds=).",
    ]
    both = parameter_space(models.get("ggx"), bounds={"kd": (0.0, 0.5)})
    v = both.clip(np.concatenate([[0.5, 0.0, 0.0], [0.3] * 3, [0.2], [0.1]]))
    assert fit_warnings(both, v, both.at_bound(v), {}, None) == [
        "kd ended on its lower bound 0 in channels 1, 2 (set by bounds=) and on its upper bound 0.5 in channel 0 "
        "(set by bounds=)."]


@pytest.mark.parametrize("model,params,says", [
    ("gltf:metallic_roughness", {"base_color": [0.8, 0.4, 0.2], "metallic": [0.3], "roughness": [0.45]},
     "a MaterialX 1.39 gltf_pbr material"),
    ("blender:principled", {"base_color": [0.7, 0.3, 0.1], "metallic": [0.2], "roughness": [0.35], "ior": [1.5],
                            "specular_tint": [1.0]}, "a MaterialX 1.39 open_pbr_surface material"),
])
def test_the_line_after_a_materialx_export_names_a_materialx_material(tmp_path, capsys, model, params, says):
    assert main(["export", str(write(tmp_path, model, params)), "-o", str(tmp_path / "m.mtlx")]) == 0
    err = capsys.readouterr().err
    assert f"wrote {tmp_path / 'm.mtlx'}: {says}, id " in err and "sphere" not in err


def test_a_converted_files_metrics_are_named_as_the_error_against_the_source_fit(tmp_path, capsys):
    src = write(tmp_path, "ggx", GGX, metrics={"rel_rmse": 0.05, "log_rmse": 0.01})
    assert main(["export", str(src), "--to", "gltf:metallic_roughness", "-o", str(tmp_path / "m.gltf")]) == 0
    err = capsys.readouterr().err
    assert "against the ggx fit" in err
    about = json.loads((tmp_path / "m.gltf").read_text())["materials"][0]["extras"]["brdffit"]
    assert "metrics" not in about  # where a fit's metrics against its data sit
    source = FitResult.from_json(src)
    converted = convert(source, "gltf:metallic_roughness")
    assert about["metrics_against_source_fit"] == pytest.approx(converted.metrics)
    assert about["converted_from"]["source_fit_metrics"] == {"rel_rmse": 0.05, "log_rmse": 0.01}
    assert about["converted_from"]["rel_rmse"] == pytest.approx(converted.metrics["rel_rmse"])
    assert "against the ggx fit" in repr(converted) and "against" not in repr(source)
    # an export of the source itself keeps its data metrics under their name
    src_glb = write(tmp_path, "gltf:metallic_roughness", {"base_color": [0.5] * 3, "metallic": [0.1],
                                                         "roughness": [0.4]}, metrics={"rel_rmse": 0.07})
    assert main(["export", str(src_glb), "-o", str(tmp_path / "n.gltf")]) == 0
    plain = json.loads((tmp_path / "n.gltf").read_text())["materials"][0]["extras"]["brdffit"]
    assert plain["metrics"] == {"rel_rmse": 0.07} and "metrics_against_source_fit" not in plain


def test_converting_a_fit_that_is_zero_everywhere_has_no_relative_error(tmp_path, capsys):
    src = write(tmp_path, "lambert", {"kd": [0.0, 0.0, 0.0]})
    assert main(["export", str(src), "--to", "gltf:metallic_roughness", "-o", str(tmp_path / "m.mtlx")]) == 0
    err = capsys.readouterr().err
    assert "rel_rmse undefined" in err and "e+" not in err, err
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(tmp_path / "m.mtlx"))
    about = json.loads(doc.getMaterialNodes()[0].getAttribute("brdffit"))["brdffit"]
    assert about["converted_from"]["rel_rmse"] is None
    assert about["metrics_against_source_fit"]["rel_rmse"] is None
    assert about["metrics_against_source_fit"]["mean_rel_error"] is None
    assert about["metrics_against_source_fit"]["rmse"] < 0.1  # the absolute error stays a number
