"""The code's citations of its design, listed and checked against the headings of docs/.

    .venv/bin/python scripts/doc_refs.py [--summary] [PATH ...]      (default: brdffit tests benchmarks scripts notebooks)

Every citation in the files under PATH is printed as ``file:line: kind "text" -> target: verdict``:

- ``docs/PAGE.md#anchor`` (or ``docs/PAGE.md``): the form the code is to use. It resolves when the
  page exists and holds a heading whose anchor is ``anchor`` (the heading in lower case, spaces as
  ``-``, other punctuation dropped: what a Markdown viewer links to).
- ``SPEC N`` (``SPEC section N``, ``SPEC N, M``, ``SPEC N "Subsection"``): a section of the product
  specification, which the repository does not hold, so it resolves to nothing a reader can open.
  The target shown is the heading of docs/ that :data:`SPEC` maps it to: what the rewrite writes.
- ``issue N``: an issue of the project's tracker, likewise; the target is the heading of docs/ that
  explains its topic (:data:`ISSUES`). Most of these say where a test or a rule came from: the
  rewrite may drop them where the sentence explains itself.
- ``SPEC`` without a number, and names built on it (``SPEC4``): to be rewritten by hand.

A mapped target that names no heading of docs/ is shown as such (the mapping or the docs are
wrong). The exit status is 0 when every citation is of the docs/ form and resolves, 1 otherwise.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"

#: SPEC section -> the heading of docs/ that explains it (``(section, subsection)`` for the
#: subsections the code names in quotes).
SPEC = {
    "1": "conventions.md#conventions",
    "2": "formats.md#measurement",
    "3": "formats.md#readers-and-writers",
    "4": "models.md#models",
    "5": "fitting.md#fitting",
    ("5", "parameter space"): "fitting.md#parameter-space",
    "6": "validation.md#validation-rendering",
    "7": "btf.md#btfs-per-texel-fitting",
    ("7", "at scale"): "btf.md#at-scale",
    ("7", "an interrupted run resumes"): "btf.md#resuming",
    "8": "materials.md#a-fit-in-any-mitsuba-scene",
    "9": "validation.md#figures",
    "10": "cli.md#the-command-line-and-set-up",
    "11": "cli.md#set-up",
    "12": "scene.md#scene-aware-fitting",
    "13": "materials.md#native-materials-and-exports",
    "14": "explorer.md#the-explorer",
}
#: issue -> the heading of docs/ that explains its topic.
ISSUES = {
    "3": "models.md#how-models-are-tested",
    "8": "fitting.md#solvers",
    "9": "cli.md#bad-input",
    "10": "DESIGN.md#where-users-meet-brdffit",
    "11": "btf.md#neighbour-starts",
    "12": "scene.md#scene-aware-fitting",
    "13": "DESIGN.md#tests-that-fail-when-the-code-is-wrong",
    "27": "materials.md#native-materials-and-exports",
    "28": "fitting.md#hostile-but-valid-data",
    "29": "DESIGN.md#layers",
}

#: Files whose citations are examples of the forms, not citations (this script's test).
EXAMPLES = ("tests/test_doc_refs.py", "scripts/doc_refs.py")
#: Where the code is: every citation under these resolves (tests/test_doc_refs.py).
CODE = ("brdffit", "tests", "benchmarks", "scripts", "notebooks")

_DOCS_REF = re.compile(r"docs/(?P<page>[\w./-]+?\.md)(?:#(?P<anchor>[\w-]+))?")
_SPEC_REF = re.compile(r"\bSPEC(?: sections?)? (?P<numbers>\d+(?:(?:, | and |, and )\d+)*)"
                       r"(?:'s)?(?P<sub>,? [\"'“][^\"'”]{3,40}[\"'”])?")
_SPEC_OTHER = re.compile(r"\bSPEC(?:\d+\b|(?:'s)?\b(?! (?:sections? )?\d))")
_ISSUE_REF = re.compile(r"\b[Ii]ssues? (?P<number>\d+)")
_SUFFIXES = (".py", ".js", ".css", ".toml", ".md", ".txt", ".sh", ".ipynb")


def anchor(heading: str) -> str:
    """The anchor of a Markdown heading: lower case, spaces as '-', other punctuation dropped."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def headings(page: Path) -> set[str]:
    """The anchors of every heading of a docs page (none outside fenced code)."""
    out, fenced = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"#{1,6} ", line):
            out.add(anchor(line.lstrip("#")))
    return out


def resolves(target: str, docs: Path = DOCS) -> bool:
    """Whether ``PAGE.md#anchor`` (or ``PAGE.md``) names a page of ``docs`` and a heading on it."""
    page, _, name = target.partition("#")
    path = docs / page
    if not path.is_file():
        return False
    return not name or name in headings(path)


def citations(text: str):
    """(line, kind, text, target) of every citation in ``text``; target is a docs/ target or None."""
    for number, line in enumerate(text.splitlines(), 1):
        for m in _DOCS_REF.finditer(line):
            yield number, "docs", m.group(0), m.group("page") + (f"#{m.group('anchor')}" if m.group("anchor") else "")
        for m in _SPEC_REF.finditer(line):
            numbers = re.findall(r"\d+", m.group("numbers"))
            sub = (m.group("sub") or "").strip(" ,\"'“”").lower()
            for n in numbers:
                target = SPEC.get((n, sub)) if sub and n == numbers[-1] else None
                yield number, "spec", m.group(0), target or SPEC.get(n)
        for m in _SPEC_OTHER.finditer(line):
            yield number, "spec-by-hand", m.group(0), None
        for m in _ISSUE_REF.finditer(line):
            yield number, "issue", m.group(0), ISSUES.get(m.group("number"))


def verdict(kind: str, target: str | None, docs: Path = DOCS) -> tuple[bool, str]:
    """(resolves, what to say) of one citation."""
    if kind == "docs":
        return (True, "resolves") if resolves(target, docs) else (False, "MISSING: no such page or heading in docs/")
    if target is None:
        return False, "to rewrite by hand (no mapping)"
    if resolves(target, docs):
        return False, f"to rewrite as docs/{target} (exists)"
    return False, f"to rewrite as docs/{target}, which does NOT exist"


def files(paths):
    for path in paths:
        path = Path(path)
        if path.is_file():
            yield path
        else:
            yield from sorted(p for p in path.rglob("*") if p.is_file() and p.suffix in _SUFFIXES
                              and "__pycache__" not in p.parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("paths", nargs="*", default=[str(REPO / p) for p in CODE])
    parser.add_argument("--summary", action="store_true", help="only the counts")
    args = parser.parse_args(argv)
    counts: Counter = Counter()
    ok = True
    for path in files(args.paths):
        if path.is_relative_to(REPO) and path.relative_to(REPO).as_posix() in EXAMPLES:
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        for line, kind, cited, target in citations(text):
            good, said = verdict(kind, target)
            ok &= good
            counts[(kind, "resolves" if good else said.split(" (")[0].split(",")[0])] += 1
            if not args.summary:
                shown = path.relative_to(REPO) if path.is_relative_to(REPO) else path
                print(f"{shown}:{line}: {kind} {cited!r} -> {said}")
    for (kind, said), n in sorted(counts.items()):
        print(f"{n:5d}  {kind}: {said}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
