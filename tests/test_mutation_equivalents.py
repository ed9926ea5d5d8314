"""tests/mutation_equivalents.toml, read by ``make mutation``'s report (scripts/mutation_report.py):
it must parse (TOML refuses a mutant named twice, and the report then stops with a traceback, as it
did once), and every entry must name a mutant of the mutated packages, the line it changes and why
that changes nothing observable."""

from __future__ import annotations

import re
import tomllib
from collections import Counter
from pathlib import Path

import pytest

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


def test_sampled_mutation_scores_carry_the_wilson_interval_of_published_examples(monkeypatch):
    """``make mutation SAMPLE=n`` reports a package's score from a sample, with its 95 % interval.
    Pinned: the score (Wilson) intervals of Newcombe (1998), Stat. Med. 17:857, Table I, method 3."""
    monkeypatch.syspath_prepend(str(REPO / "scripts"))
    from mutation_report import wilson_interval
    for (k, n), expected in {(81, 263): (0.2553, 0.3662), (15, 148): (0.0624, 0.1605),
                             (0, 20): (0.0, 0.1611), (1, 29): (0.0061, 0.1718)}.items():
        assert wilson_interval(k, n) == pytest.approx(expected, abs=6e-5), (k, n)


def test_a_mutant_sample_is_seeded_uniform_per_package_and_any_prefix_covers_every_package(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / "scripts"))
    from mutation_sample import draw
    names = [f"brdffit.fitting.solve.x_f__mutmut_{i}" for i in range(300)] + \
            [f"brdffit.io.npz.x_g__mutmut_{i}" for i in range(40)]
    sample = draw(names, 30, seed=7)
    assert sample == draw(list(reversed(names)), 30, seed=7)  # the seed fixes it, not the input order
    assert sample != draw(names, 30, seed=8)
    assert len(set(sample)) == 60 and set(sample) <= set(names)
    assert sum(s.startswith("brdffit.io.") for s in sample) == 30  # n per package, whatever its size
    assert {s.split(".")[1] for s in sample[:10]} == {"fitting", "io"}
    # uniform: over many seeds every fitting mutant is drawn about 30/300 of the time
    counts = Counter(s for seed in range(400) for s in draw(names, 30, seed) if ".fitting." in s)
    assert len(counts) == 300 and 20 <= min(counts.values()) and max(counts.values()) <= 65


def test_the_rechecks_test_files_and_modules_exist(monkeypatch):
    """A misspelt name in the recheck's maps would silently recheck a survivor against nothing."""
    monkeypatch.syspath_prepend(str(REPO / "scripts"))
    from mutation_recheck import TESTS_BY_MODULE, TESTS_BY_PACKAGE
    for key, patterns in {**TESTS_BY_PACKAGE, **TESTS_BY_MODULE}.items():
        assert (REPO / key.replace(".", "/")).with_suffix(".py").exists() or (REPO / key.replace(".", "/")).is_dir(), key
        for pattern in patterns:
            assert list(REPO.glob(pattern)), (key, pattern)


def test_the_hand_mutations_apply_to_the_current_source(monkeypatch):
    """``make mutation-by-hand`` (scripts/mutation_by_hand.py) applies docs/DESIGN.md#tests-that-fail-when-the-code-is-wrong's mutations by text:
    a source edit that moves one of them must show here, not as a silent 'does not apply' there."""
    monkeypatch.syspath_prepend(str(REPO / "scripts"))
    from mutation_by_hand import MUTATIONS

    assert len(MUTATIONS) >= 10
    for m in MUTATIONS:
        source = (REPO / m.path).read_text()
        assert source.count(m.old) == 1, (m.what, m.path)
        assert m.new != m.old and m.tests and all((REPO / t).is_file() for t in m.tests), m.what
