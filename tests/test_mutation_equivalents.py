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


def test_mutants_run_without_the_disk_cache_of_compiled_programs(monkeypatch):
    """brdffit's disk cache finds a compiled program by the hash of its source; mutmut's copy is one
    source for every mutant (``MUTANT_UNDER_TEST`` picks one at run time), so with the cache on a
    mutant loads the program of whichever ran first (seen: ``ggx_ndf__mutmut_8`` fitted the
    unmutated GGX, loss 3.5e-31 instead of 7.4e-3). Both ways of running mutants turn it off."""
    script = (REPO / "scripts" / "mutation_run.sh").read_text()
    assert re.search(r"^export BRDFFIT_CACHE=off\b", script, re.M), "scripts/mutation_run.sh"
    monkeypatch.syspath_prepend(str(REPO / "scripts"))
    from mutation_recheck import mutant_env
    env = mutant_env("brdffit.models.ggx.x_ggx_ndf__mutmut_8")
    assert env["BRDFFIT_CACHE"] == "off" and env["MUTANT_UNDER_TEST"].endswith("__mutmut_8")
