"""The Lafortune parameter table as documented (module docstring / docs/models.md#models): per lobe rho, cx, cz, n
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


def test_rho_alone_is_linear():
    """rho scales its lobe (the table's "linear"; the start's linear solve relies on it); the lobe's
    shape parameters and exponent are not."""
    linear = {p.name: p.linear for p in lafortune(2).params}
    assert linear == {"kd": True, "rho1": True, "cx1": False, "cz1": False, "n1": False,
                      "rho2": True, "cx2": False, "cz2": False, "n2": False}


def test_several_lobes_start_a_decade_apart_each_with_albedo_0_3_over_lobes():
    """As documented: default exponents ..., 2000, 200, 20 (narrowest first), at most the physical
    1e4; each lobe's rho such that its albedo at normal incidence, about rho 2 pi / (n + 2)
    (module docstring), is 0.3 / lobes; kept to 4 decimals, as the parameter tables print it."""
    for lobes, exponents in ((2, [200.0, 20.0]), (3, [2000.0, 200.0, 20.0]), (4, [1e4, 2000.0, 200.0, 20.0])):
        defaults = {p.name: p.default for p in lafortune(lobes).params}
        assert [defaults[f"n{j}"] for j in range(1, lobes + 1)] == exponents
        for j, n in enumerate(exponents, start=1):
            rho = defaults[f"rho{j}"]
            assert abs(rho * 2 * math.pi / (n + 2) - 0.3 / lobes) <= 5e-5 * 2 * math.pi / (n + 2), (lobes, j)
            assert round(rho, 4) == rho, (lobes, j, rho)
