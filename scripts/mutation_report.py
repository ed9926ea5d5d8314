"""Summarise a mutmut 3 run (``make mutation``): score per package and the surviving mutants.

Reads ``mutmut results --all=True`` (one ``name: status`` line per mutant) from stdin. Score =
killed / (killed + survived + timeout + no tests + suspicious); "not checked" mutants (a run cut
short) are counted apart. Prints survivors with ``mutmut show NAME`` as the next step.
Usage: mutmut results --all=True | python scripts/mutation_report.py [PATTERN ...]
"""

from __future__ import annotations

import fnmatch
import sys
from collections import Counter, defaultdict

BAD = ("survived", "timeout", "no tests", "suspicious", "segfault")


def main(argv: list[str]) -> int:
    patterns = argv or ["*"]
    by_pkg: dict[str, Counter] = defaultdict(Counter)
    survivors: list[tuple[str, str]] = []
    for line in sys.stdin:
        if ":" not in line:
            continue
        name, status = (s.strip() for s in line.rsplit(":", 1))
        if not any(fnmatch.fnmatch(name, p.strip('"')) for p in patterns):
            continue
        pkg = ".".join(name.split(".")[:2])
        status = "killed" if status == "caught by type check" else status
        by_pkg[pkg][status] += 1
        if status in BAD:
            survivors.append((name, status))
    total = Counter()
    print(f"{'package':<20} {'killed':>7} {'survived':>9} {'other':>6} {'unchecked':>10} {'score':>7}")
    for pkg in sorted(by_pkg):
        c = by_pkg[pkg]
        total.update(c)
        _row(pkg, c)
    _row("all", total)
    if survivors:
        print(f"\n{len(survivors)} mutants not killed (inspect with `mutmut show NAME`):")
        for name, status in sorted(survivors):
            print(f"  {status:<10} {name}")
    return 0


def _row(label: str, c: Counter) -> None:
    judged = c["killed"] + sum(c[s] for s in BAD)
    score = f"{100 * c['killed'] / judged:.1f}%" if judged else "-"
    other = sum(c[s] for s in BAD if s != "survived")
    print(f"{label:<20} {c['killed']:>7} {c['survived']:>9} {other:>6} {c['not checked']:>10} {score:>7}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
