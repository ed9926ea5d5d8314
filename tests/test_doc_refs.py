"""scripts/doc_refs.py, the check of the code's citations of docs/: it finds each form of citation,
resolves a docs/ citation only to a heading that exists, and every heading it maps the old
citations to exists (so that the rewrite it prepares points somewhere). The docs' own references
to one another resolve too."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

import doc_refs  # noqa: E402


@pytest.mark.parametrize("heading, expected", [
    ("BTFs: per-texel fitting", "btfs-per-texel-fitting"),
    ("The data's unit", "the-datas-unit"),
    ("A second renderer: Cycles", "a-second-renderer-cycles"),
    ("Compare and select", "compare-and-select"),
])
def test_anchor_is_what_a_markdown_viewer_links_to(heading, expected):
    assert doc_refs.anchor(heading) == expected


def test_every_mapped_heading_exists():
    missing = [t for t in [*doc_refs.SPEC.values(), *doc_refs.ISSUES.values()] if not doc_refs.resolves(t)]
    assert missing == []


def test_each_form_of_citation_is_found_and_judged(tmp_path):
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "fitting.md").write_text("# Fitting\n\n```\n# not a heading\n```\n\n## The status tests\n")
    text = "\n".join([
        '"""See SPEC 5 and SPEC 7 "At scale"; SPEC sections 8, 13."""',
        "# docs/fitting.md#the-status-tests and docs/fitting.md#not-a-heading and docs/fitting.md",
        "SPEC4 = {}  # the SPEC's names (issue 28)",
        "SPECULAR = 1  # not a citation",
    ])
    found = [(line, kind, target) for line, kind, _, target in doc_refs.citations(text)]
    assert found == [
        (1, "spec", "fitting.md#fitting"), (1, "spec", "btf.md#at-scale"),
        (1, "spec", "materials.md#a-fit-in-any-mitsuba-scene"), (1, "spec", "materials.md#native-materials-and-exports"),
        (2, "docs", "fitting.md#the-status-tests"), (2, "docs", "fitting.md#not-a-heading"), (2, "docs", "fitting.md"),
        (3, "spec-by-hand", None), (3, "spec-by-hand", None), (3, "issue", "fitting.md#hostile-but-valid-data"),
    ]
    judged = [doc_refs.verdict(kind, target, docs)[0] for _, kind, target in found]
    assert judged == [False] * 4 + [True, False, True] + [False] * 3


def test_the_docs_references_to_one_another_resolve():
    """A page names another's heading as ``page.md#anchor``: each must exist."""
    broken = []
    for page in sorted(doc_refs.DOCS.glob("*.md")):
        for page_ref, name in re.findall(r"\b([A-Za-z_]+\.md)#([\w-]+)", page.read_text(encoding="utf-8")):
            if not doc_refs.resolves(f"{page_ref}#{name}"):
                broken.append(f"{page.name}: {page_ref}#{name}")
        for name in re.findall(r"\(#([\w-]+)\)", page.read_text(encoding="utf-8")):
            if not doc_refs.resolves(f"{page.name}#{name}"):
                broken.append(f"{page.name}: #{name}")
    assert broken == []


def test_every_citation_in_the_code_resolves_to_a_heading_of_docs(capsys):
    """The code cites its design only as ``docs/PAGE.md#anchor``, and each names a heading that exists
    (no "SPEC N", no "issue N": the repository does not hold those)."""
    code = doc_refs.main([str(doc_refs.REPO / p) for p in doc_refs.CODE])
    unresolved = [line for line in capsys.readouterr().out.splitlines() if ": " in line and not line.endswith("resolves")]
    assert code == 0 and unresolved == []
