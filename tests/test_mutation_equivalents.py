"""tests/mutation_equivalents.toml, read by ``make mutation``'s report (scripts/mutation_report.py):
it must parse (TOML refuses a mutant named twice, and the report then stops with a traceback, as it
did once), and every entry must name a mutant of the mutated packages, the line it changes and why
that changes nothing observable."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_every_explained_mutant_is_named_once_with_its_change_and_reason():
    text = (REPO / "tests" / "mutation_equivalents.toml").read_text()
    names = re.findall(r'^\[mutants\."([^"]+)"\]', text, re.M)
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    entries = tomllib.loads(text)["mutants"]
    assert sorted(entries) == sorted(names)
    for name, entry in entries.items():
        assert re.fullmatch(r"brdffit\.(models|fitting|io)\.[\w.]+__mutmut_\d+", name), name
        assert set(entry) == {"change", "reason"} and entry["change"].strip() and entry["reason"].strip(), name
