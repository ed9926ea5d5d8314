"""Every model's Param table equals the parameter table of its module docstring (the one documented
truth): names, channels, bounds, default, role, and a "(log)" mark where the solver moves on a log
axis. The docstring tables are parsed generically (by the column header names), so a change of
bounds must change both places or fail here. A few bounds fixed by the papers are pinned outright."""

from __future__ import annotations

import importlib
import math
import re

import numpy as np
import pytest

from brdffit.models import get, names


def _eval_number(text: str) -> float:
    text = text.strip().replace(" ", "")
    if not re.fullmatch(r"[-+0-9.eE*/()piinf]+", text):
        raise ValueError(f"not a number expression: {text!r}")
    return float(eval(text, {"__builtins__": {}}, {"pi": math.pi, "inf": math.inf}))  # noqa: S307 - checked above


def doc_table(module) -> dict[str, dict[str, str]]:
    """Rows of the first RST simple table in the docstring that has name/bounds/default columns."""
    lines = (module.__doc__ or "").splitlines()
    seps = [i for i, line in enumerate(lines) if re.fullmatch(r"=+( +=+)+ *", line)]
    for a, b in zip(seps, seps[1:]):
        spans = [(m.start(), m.end()) for m in re.finditer(r"=+", lines[a])]
        # the last column runs to the end of the line
        spans[-1] = (spans[-1][0], 10_000)
        header = [lines[a + 1][s:e].strip() for s, e in spans] if b == a + 2 else None
        if not header or not {"name", "bounds", "default"} <= set(header):
            continue
        end = next(i for i in seps if i > b)
        rows: dict[str, dict[str, str]] = {}
        for line in lines[b + 1 : end]:
            cells = [line[s:e].strip() if s < len(line) else "" for s, e in spans]
            if cells[0]:
                rows[cells[0]] = dict(zip(header, cells))
            elif rows:  # continuation of the previous row's text
                last = rows[next(reversed(rows))]
                for h, c in zip(header, cells):
                    if c:
                        last[h] = f"{last[h]} {c}"
        return rows
    raise AssertionError(f"{module.__name__}: no parameter table (name / bounds / default) in the docstring")


def parse_bounds(text: str) -> tuple[float, float, bool]:
    m = re.match(r"\s*[\[(]\s*([^,]+),\s*([^\])]+)[\])](.*)", text)
    assert m, f"unparsable bounds {text!r}"
    return _eval_number(m.group(1)), _eval_number(m.group(2)), "(log)" in m.group(3)


@pytest.mark.parametrize("name", names())
def test_param_table_equals_the_documented_table(name):
    model = get(name)
    module = importlib.import_module(f"brdffit.models.{name.replace(':', '_')}")  # mitsuba:x lives in mitsuba_x.py
    table = doc_table(module)
    assert list(table) == [p.name for p in model.params], (name, list(table))
    for p in model.params:
        row = table[p.name]
        lo, hi, log = parse_bounds(row["bounds"])
        assert (p.lower, p.upper) == pytest.approx((lo, hi), rel=1e-12), (name, p.name, row["bounds"])
        assert p.default == pytest.approx(_eval_number(row["default"].split()[0]), rel=1e-12), (name, p.name)
        if "channels" in row:
            assert p.channels == int(row["channels"]), (name, p.name)
        if "role" in row:
            assert p.role == row["role"].split()[0], (name, p.name)
        assert (p.scale == "log") == log, (name, p.name, p.scale, row["bounds"])


def test_parser_reads_a_table_with_extra_columns():
    # the parser is driven by the header, so a new column (e.g. a physical range) does not break it
    class Fake:
        __name__ = "fake"
        __doc__ = """x

====  ========  =============  ==========  =======  ======  =======
name  channels  bounds         physical    default  role    meaning
====  ========  =============  ==========  =======  ======  =======
ks    3         [0, inf)       [0, 1]      0.5      albedo  scale
                                                            more
s     1         [1e-4, 1] (log)  -         0.2      roughness  width
====  ========  =============  ==========  =======  ======  =======
"""

    rows = doc_table(Fake)
    assert list(rows) == ["ks", "s"]
    assert parse_bounds(rows["ks"]["bounds"]) == (0.0, math.inf, False)
    assert rows["ks"]["meaning"] == "scale more"


# Ranges fixed by the papers' definitions, whatever the library's choices elsewhere: the
# physical range (docs/fitting.md#fitting: applied with physical=True; the default bounds restrict only what the
# formula needs, so a measured albedo may exceed 1 by default).
PINNED = [
    ("oren_nayar", "sigma", "upper", math.pi / 2),  # facet slope angle, radians: at most 90 degrees
    ("oren_nayar", "sigma", "lower", 0.0),  # sigma = 0 is Lambert
    ("lambert", "kd", "upper", 1.0),  # an albedo
    ("ggx", "f0", "upper", 1.0),  # a reflectance at normal incidence
    ("ggx", "f0", "lower", 0.0),
    ("cook_torrance", "f0", "upper", 1.0),
]


@pytest.mark.parametrize("model, param, side, value", PINNED)
def test_bounds_fixed_by_the_papers(model, param, side, value):
    p = next(p for p in get(model).params if p.name == param)
    lo, hi = p.physical if p.physical is not None else (p.lower, p.upper)
    assert {"lower": lo, "upper": hi}[side] == pytest.approx(value, rel=1e-12, abs=0)
