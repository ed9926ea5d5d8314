"""Hand-edited fit.json files (docs/cli.md#the-command-line-and-set-up): every field FitResult reads is checked, so a hostile file is
one line naming it and exit 2 (never an internal error, exit 3), and a file cannot widen what is
accepted: parameters outside the model's own bounds are refused whatever bounds it records. A
generated corpus of hostile variants (types, NaN/inf, huge arrays, wrong channel counts, lone
surrogates) goes through ``export``: each is refused with one line or exports a valid file."""

from __future__ import annotations

import json
import xml.parsers.expat
from pathlib import Path

import pytest

from brdffit.cli import main

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "sample_ubo81.exr"
GGX = {"format": "brdffit.fit/1", "model": "lambert+ggx", "channels": 3, "converged": True, "loss": "log",
       "status": "converged", "status_code": 0, "data_name": "paint", "loss_value": 0.01, "steps": 12,
       "params": {"kd": [0.3, 0.2, 0.1], "ggx1.ks": [0.5, 0.5, 0.5], "ggx1.alpha": [0.2], "ggx1.f0": [0.04]},
       "metrics": {"log": 0.01, "rel_rmse": 0.08}, "seconds": {"run": 0.1}, "at_bound": {}, "warnings": [],
       "stderr": {"kd": [0.01, 0.01, 0.01]}, "start": {"kd": [0.2, 0.2, 0.2]}, "options": {"solver": "lm"}}


def run(capsys, argv) -> tuple[int, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def write(tmp_path, text: str, name: str = "fit.json") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def one_line_exit_2(code: int, err: str, named: Path) -> None:
    assert code == 2, err
    assert err.count("\n") == 1 and str(named) in err and "Traceback" not in err and "internal error" not in err, err


# the six files that gave exit 3 ("internal error") before they were checked
SIX = {
    "at_bound as a list": {"at_bound": ["ggx1.alpha"]},
    "warnings as a number": {"warnings": 5},
    "converted_from as a string": {"options": {"converted_from": "ggx"}},
    "converted_from's error as strings": {"options": {"converted_from": {"model": "ggx", "rel_rmse": "0.1"}}},
    "a lone surrogate in data_name": "\\ud800",
    "a lone surrogate in an option's key": {"options": {"\udc80": 1}},
}


def text_of(change) -> str:
    if isinstance(change, str):  # a JSON escape Python writes only as the escape itself
        return json.dumps({**GGX, "data_name": "X"}).replace('"data_name": "X"', f'"data_name": "{change}"')
    return json.dumps({**GGX, **change})


@pytest.mark.parametrize("what", list(SIX))
def test_the_files_that_crashed_are_one_line_and_exit_2(tmp_path, capsys, what):
    src = write(tmp_path, text_of(SIX[what]))
    out = tmp_path / "out"
    out.mkdir()
    for argv in (["export", src, "-o", out / "m.xml"], ["export", src],
                 ["validate", SAMPLE, src, "-o", out / "v", "--size", "8", "--lights", "1"]):
        code, err = run(capsys, argv)
        one_line_exit_2(code, err, src)
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("param,value,bounds", [
    ("ggx1.alpha", [-0.1], [-1, 1]), ("kd", [-0.5, 0.2, 0.1], [-1, 1]), ("ggx1.f0", [5.0], [0, 10]),
    ("ggx1.alpha", [0.0], {"lower": 0, "upper": 1}),  # alpha's own lower bound is 1e-4
])
def test_recorded_bounds_never_widen_the_models_own(tmp_path, capsys, param, value, bounds):
    """The file's ``bounds`` may narrow what is accepted, never widen it: before, alpha -0.1, kd -0.5
    and f0 5 exported with exit 0 and ``validate`` rendered a negative BRDF."""
    src = write(tmp_path, json.dumps({**GGX, "params": {**GGX["params"], param: value}, "bounds": {param: bounds}}))
    for argv in (["export", src, "-o", tmp_path / "m.xml"], ["export", src, "--to", "gltf:metallic_roughness",
                                                             "-o", tmp_path / "m.gltf"],
                 ["validate", SAMPLE, src, "-o", tmp_path / "v", "--size", "8", "--lights", "1"]):
        code, err = run(capsys, argv)
        one_line_exit_2(code, err, src)
        assert f"parameter {param!r} = {value}" in err and "bounds of lambert+ggx" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.json"]
    narrower = write(tmp_path, json.dumps({**GGX, "bounds": {"ggx1.alpha": [0.3, 0.5]}}))  # still narrows
    code, err = run(capsys, ["export", narrower, "-o", tmp_path / "m.xml"])
    one_line_exit_2(code, err, narrower)
    assert "recorded bounds [0.3, 0.5]" in err


# -- the corpus ---------------------------------------------------------------------------------------
HOSTILE = [None, True, -1, 0, 1e308, "x", "\x00\x1b[31m", [], {}, [None], ["a"], {"a": "b"}, [[0.1]], [1e-320],
           list(range(100_000)), float("nan"), float("inf"), -float("inf")]


def corpus() -> dict[str, str]:
    """name -> fit.json text: every field given every hostile value, parameters broken one way each."""
    cases = {}
    for field in list(GGX) + ["bounds", "options.converted_from", "options.converted_from.rel_rmse",
                              "at_bound.kd", "metrics.rel_rmse", "stderr.kd", "start.kd"]:
        for k, value in enumerate(HOSTILE):
            d = json.loads(json.dumps(GGX))
            head, _, tail = field.partition(".")
            if tail:
                inner = d.setdefault(head, {})
                if "." in tail:
                    a, b = tail.split(".")
                    inner.setdefault(a, {"model": "ggx"})
                    inner[a][b] = value
                else:
                    inner[tail] = value
            else:
                d[field] = value
            cases[f"{field}={k}"] = json.dumps(d)
    params = GGX["params"]
    for name, p in {
        "kd 2 channels": {**params, "kd": [0.1, 0.2]}, "kd 4 channels": {**params, "kd": [0.1] * 4},
        "alpha 3 channels": {**params, "ggx1.alpha": [0.1] * 3}, "kd nested": {**params, "kd": [[0.1, 0.2, 0.3]]},
        "kd huge": {**params, "kd": [0.1] * 1_000_000}, "unknown parameter": {**params, "x": [1]},
        "missing parameter": {"kd": params["kd"]}, "kd bool": {**params, "kd": [True, False, True]},
        "alpha tiny": {**params, "ggx1.alpha": [1e-320]}, "kd huge value": {**params, "kd": [1e308] * 3},
    }.items():
        cases[name] = json.dumps({**GGX, "params": p})
    cases["one channel, three values"] = json.dumps({**GGX, "channels": 1})
    cases["nested deeply"] = json.dumps({**GGX, "options": {}}).replace('"options": {}', '"options": ' + "[" * 5000 + "]" * 5000)
    cases["lone surrogate deep"] = json.dumps({**GGX, "options": {"a": [{"b": "X"}]}}).replace('"X"', '"\\udfff"')
    cases["lone surrogate in a warning"] = json.dumps({**GGX, "warnings": ["X"]}).replace('"X"', '"\\ud83d"')
    return cases


def test_hostile_fit_file_corpus_is_refused_or_exported_validly(tmp_path, capsys):
    """Each variant through ``export -o m.xml``: exit 2 with one line naming the file and nothing
    written, or exit 0 and a well-formed file. Never exit 3, a traceback or a half-written file."""
    failures, refused, exported = [], 0, 0
    for k, (name, text) in enumerate(corpus().items()):
        d = tmp_path / f"c{k}"
        d.mkdir()
        src = write(d, text)
        out = d / "m.xml"
        code, err = run(capsys, ["export", src, "-o", out])
        if code == 2:
            refused += 1
            if err.count("\n") != 1 or str(src) not in err or "internal error" in err or out.exists():
                failures.append(f"{name}: {err!r}")
        elif code == 0:
            exported += 1
            try:
                xml.parsers.expat.ParserCreate().Parse(out.read_bytes(), True)
            except xml.parsers.expat.ExpatError as exc:
                failures.append(f"{name}: exported a malformed file ({exc})")
        else:
            failures.append(f"{name}: exit {code}: {err.strip()[-300:]!r}")
    assert refused + exported >= 400 and refused > 300
    assert not failures, f"{len(failures)} of {refused + exported + len(failures)}:\n" + "\n".join(failures[:30])
