"""brdffit's shape (docs/DESIGN.md#layers): the contracts of pyproject.toml ([tool.importlinter]) hold (the layers;
the starts, stages and solvers evaluate a loss through its Objective),
every module stands in a layer, no modules import each other in a circle (imports inside
functions count), and no module is over 450 lines."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import grimp

import brdffit

REPO = Path(__file__).resolve().parents[1]
PACKAGE = Path(brdffit.__file__).resolve().parent
MAX_LINES = 450


def _lint_imports() -> str:
    here = Path(sys.executable).with_name("lint-imports")
    found = str(here) if here.is_file() else shutil.which("lint-imports")
    assert found, "lint-imports (import-linter, in the test extra) is not installed: pip install -e '.[test]'"
    return found


def test_the_contracts_are_kept():
    """``lint-imports`` over this checkout's brdffit (the one this test imports): a lower layer
    importing a higher one, even inside a function or through a third module, breaks the layers; the
    starts, stages or solvers importing the losses themselves break the other."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(PACKAGE.parent), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([_lint_imports(), "--no-cache"], cwd=REPO, capture_output=True, text=True, env=env,
                         timeout=600)
    assert run.returncode == 0 and "2 kept, 0 broken" in run.stdout, run.stdout[-4000:] + run.stderr[-2000:]


def _modules() -> list[str]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


def test_every_module_stands_in_a_layer():
    """The contract names some modules one by one (the renderer's beside ``render.validate``): a new
    module must be placed in a layer, or the contract would not check it. Left out: the packages
    whose modules are placed one by one (``brdffit``, ``brdffit.fitting``, ``brdffit.render``: a layer
    may not contain another); what they import still counts on every way from a lower layer to a
    higher one."""
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]
    (layers,) = [c["layers"] for c in config["contracts"] if c["type"] == "layers"]
    named = [m.strip() for layer in layers for m in layer.replace("|", ":").split(":")]
    unplaced = [m for m in _modules() if not any(m == n or m.startswith(n + ".") for n in named)]
    assert unplaced == ["brdffit", "brdffit.fitting", "brdffit.render"]


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_what_a_hand_drawn_graph_holds():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e2"}, "e2": {"e"}, "f": {"a"}}
    assert sorted(_cycles(edges)) == [["a", "b", "c"], ["e", "e2"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    """Counting every import statement, those inside functions too (grimp, import-linter's graph)."""
    graph = grimp.build_graph("brdffit", cache_dir=None)
    edges = {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    assert _cycles(edges) == []


def test_no_module_over_450_lines():
    sizes = {str(p.relative_to(PACKAGE.parent)): len(p.read_text(encoding="utf-8").splitlines())
             for p in PACKAGE.rglob("*.py")}
    assert {p: n for p, n in sizes.items() if n > MAX_LINES} == {}
