"""Summarise a mutmut 3 run (``make mutation``): score per package, the survivors, the explained ones.

Reads mutmut's own result files (``mutants/**/*.py.meta``, one exit code per mutant) for the mutants
whose names match the PATTERNs (fnmatch, e.g. ``brdffit.io*``), and the committed list of
equivalent mutants, ``tests/mutation_equivalents.toml``:

    [mutants."brdffit.io.npz.x_read__mutmut_42"]
    change = "text of the mutated line, as the mutant has it"
    reason = "why no observable behaviour changes"

An explanation counts only while the mutant's diff (``mutmut show``) still adds a line containing
``change`` ("- text" for a line the mutant deletes): mutant names are numbered within a function, so an edit of that function can give the
name to another mutation; such an entry is printed as stale and the mutant counts as a survivor.

Survivors (and "no tests" mutants) that scripts/mutation_recheck.py killed (``mutants/recheck.json``)
count as killed; those that ran past its time limit, as timeouts.

Score = (killed + timeout + explained) / (all checked mutants). A timeout is a mutant that made the
tests run past mutmut's CPU-time limit (an endless loop or a solver that never stops): detected.
"Not checked" mutants (a run cut short or never started) are counted apart and not in the score.
With ``--sample FILE`` (a list of names from scripts/mutation_sample.py), only those mutants count,
and each row also gives the 95 % Wilson interval of the package's score: what the sample says
about all its mutants. The checked ones must be a uniform sample: run the list, or a prefix of it.

Usage: python scripts/mutation_report.py [--sample FILE] [PATTERN ...]   (run from the repository root)
"""

from __future__ import annotations

import fnmatch
import json
import sys
import time
import tomllib
from collections import Counter, defaultdict
from pathlib import Path

EQUIVALENTS = Path("tests/mutation_equivalents.toml")
RECHECK = Path("mutants/recheck.json")  # scripts/mutation_recheck.py: survivors killed by their package's tests
# mutmut 3.8 exit codes (mutmut/stats.py): 1 and 3 killed, 0 survived, 33/5 no tests, 36/24/-24/152/255
# timeout (SIGXCPU), 37 caught by type check, None not checked, anything else suspicious.
KILLED, SURVIVED, TIMEOUT, NO_TESTS, UNCHECKED = "killed", "survived", "timeout", "no tests", "not checked"
STATUS = {1: KILLED, 3: KILLED, 37: KILLED, 0: SURVIVED, 5: NO_TESTS, 33: NO_TESTS, 36: TIMEOUT, 24: TIMEOUT,
          -24: TIMEOUT, 152: TIMEOUT, 255: TIMEOUT, None: UNCHECKED}


def mutated_sources(root: Path):
    """A test ``source -> bool``: whether ``[tool.mutmut]`` (only_mutate, do_not_mutate) mutates
    the source file at that path, relative to ``root``."""
    cfg = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["mutmut"]
    return lambda source: any(fnmatch.fnmatch(source, p) for p in cfg.get("only_mutate", ["*"])) and not any(
        fnmatch.fnmatch(source, p) for p in cfg.get("do_not_mutate", []))


def load_results(root: Path) -> dict[str, str]:
    is_mutated = mutated_sources(root)
    results = {}
    for meta in sorted((root / "mutants").rglob("*.py.meta")):
        source = str(meta.relative_to(root / "mutants")).removesuffix(".meta")
        if not is_mutated(source):
            continue  # left over from a run before the configuration excluded the file
        for name, code in _read_json(meta)["exit_code_by_key"].items():
            results[name] = STATUS.get(code, "suspicious")
    return results


def _read_json(path: Path) -> dict:
    for _ in range(20):  # a running mutmut rewrites these files; read again when caught mid-write
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError:
            time.sleep(0.1)
    return json.loads(path.read_text())


def mutated_lines(name: str) -> list[str]:
    """The lines the mutant adds (``+`` lines of ``mutmut show``), and the ones it only removes,
    prefixed "- " (a mutant that deletes an argument line adds nothing)."""
    from mutmut.mutation.diff_apply import get_diff_for_mutant

    diff = [ln for ln in get_diff_for_mutant(name).splitlines() if not ln.startswith(("+++", "---"))]
    return [ln[1:].strip() for ln in diff if ln.startswith("+")] + ["- " + ln[1:].strip() for ln in diff if ln.startswith("-")]


def main(argv: list[str]) -> int:
    sample = None
    if argv[:1] == ["--sample"]:
        sample = set(Path(argv[1]).read_text().split())
        argv = argv[2:]
    patterns = [p.strip('"') for p in argv] or ["*"]
    results = {n: s for n, s in load_results(Path(".")).items()
               if any(fnmatch.fnmatch(n, p) for p in patterns) and (sample is None or n in sample)}
    equivalents = tomllib.loads(EQUIVALENTS.read_text())["mutants"] if EQUIVALENTS.exists() else {}
    by_pkg: dict[str, Counter] = defaultdict(Counter)
    survivors, stale = [], []
    recheck = json.loads(RECHECK.read_text()) if RECHECK.exists() else {}
    rechecked = 0
    for name, status in sorted(results.items()):
        if status in (SURVIVED, TIMEOUT, NO_TESTS) and name in recheck:  # run again in a fresh process
            rechecked += recheck[name] == KILLED
            status = {KILLED: KILLED, TIMEOUT: TIMEOUT}.get(recheck[name], SURVIVED)
        if status == SURVIVED and name in equivalents:
            change = equivalents[name]["change"].strip()
            if any(change in line for line in mutated_lines(name)):
                status = "explained"
            else:
                stale.append(name)
        module = name.rsplit(".", 1)[0]  # the last part names the function (and the mutant)
        pkg = ".".join(module.split(".")[:2])
        by_pkg[pkg][status] += 1
        by_pkg[module if module != pkg else pkg + ".__init__"][status] += 1
        if status in (SURVIVED, NO_TESTS, "suspicious"):
            survivors.append((name, status))
    print(f"{'package / file':<34} {'killed':>7} {'timeout':>8} {'explained':>10} {'survived':>9} "
          f"{'unchecked':>10} {'score':>7}" + ("   95 % interval (sample)" if sample else ""))
    total = Counter()
    for key in sorted(by_pkg, key=lambda k: (k.split(".")[1], k.count("."), k)):
        c = by_pkg[key]
        if key.count(".") == 1:
            total.update(c)
        _row(key if key.count(".") == 1 else "  " + key.split(".")[-1] + ".py", c, sample is not None)
    _row("all", total, sample is not None)
    if rechecked:
        print(f"({rechecked} of the killed: mutmut's survivors killed by scripts/mutation_recheck.py)")
    for name in stale:
        print(f"stale explanation (the mutant's diff no longer shows its `change`): {name}")
    if survivors:
        print(f"\n{len(survivors)} mutants not killed and not explained (inspect with `mutmut show NAME`):")
        for name, status in survivors:
            print(f"  {status:<10} {name}")
    return 0


def _row(label: str, c: Counter, interval: bool = False) -> None:
    detected = c[KILLED] + c[TIMEOUT] + c["explained"]
    checked = sum(v for k, v in c.items() if k != UNCHECKED)
    score = f"{100 * detected / checked:.1f}%" if checked else "-"
    bad = checked - detected
    line = f"{label:<34} {c[KILLED]:>7} {c[TIMEOUT]:>8} {c['explained']:>10} {bad:>9} {c[UNCHECKED]:>10} {score:>7}"
    if interval and checked:
        low, high = wilson_interval(detected, checked)
        line += f"   {100 * low:.1f}-{100 * high:.1f}%"
    print(line)


def wilson_interval(detected: int, checked: int) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion (it stays inside [0, 1] and is sound at 100 %)."""
    from scipy.stats import binomtest

    ci = binomtest(detected, checked).proportion_ci(confidence_level=0.95, method="wilson")
    return ci.low, ci.high


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
