"""The Lafortune parameter table as documented (module docstring / SPEC 4): per lobe rho, cx, cz, n
with their bounds, physical ranges and one-line docs, suffixed 1..k for k lobes."""

from __future__ import annotations

import math

from brdffit.models.lafortune import lafortune

LOBE = {  # name: (channels, lower, upper, role, doc, physical)
    "rho": (3, 0.0, math.inf, "albedo", "lobe scale", (0.0, 1.6e3)),
    "cx": (1, -2.0, 2.0, "shape", "C_x = C_y", (-2.0, 2.0)),  # physical = the bounds when not given
    "cz": (1, 0.0, 2.0, "shape", "C_z", (0.0, 2.0)),
    "n": (1, 1.0, math.inf, "exponent", "lobe exponent", (1.0, 1e4)),
}


def rows(model):
    return {p.name: (p.channels, p.lower, p.upper, p.role, p.doc, p.physical) for p in model.params}


def test_one_lobe_table():
    table = rows(lafortune(1))
    assert list(table) == ["kd", "rho", "cx", "cz", "n"]
    for name, row in LOBE.items():
        assert table[name] == row, name
    defaults = {p.name: p.default for p in lafortune(1).params}
    assert (defaults["rho"], defaults["cx"], defaults["cz"], defaults["n"]) == (1.0, -1.0, 1.0, 20.0)


def test_three_lobe_table():
    table = rows(lafortune(3))
    assert list(table) == ["kd"] + [q + s for s in "123" for q in ("rho", "cx", "cz", "n")]
    for s in "123":
        for name, row in LOBE.items():
            assert table[name + s] == row, name + s
