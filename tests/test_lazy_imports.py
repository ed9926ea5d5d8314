"""``import brdffit`` and the CLI start without JAX and matplotlib, and whatever imports JAX in
brdffit enables float64 first (``brdffit/_x64.py``)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import brdffit

PACKAGE = Path(brdffit.__file__).parent


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_the_package_the_cli_and_plot_import_neither_jax_nor_each_others_heavy_parts():
    code = ("import sys\n"
            "import brdffit, brdffit.cli\n"
            "brdffit.cli._load_commands()\n"
            "print('jax' in sys.modules, 'matplotlib' in sys.modules)\n"
            "import brdffit.plot\n"
            "print('jax' in sys.modules)\n")
    assert _run(code).split() == ["False", "False", "False"]


def test_the_first_part_that_needs_jax_enables_float64():
    code = ("import brdffit, jax\n"
            "print(jax.config.jax_enable_x64)\n"
            "import brdffit.models\n"
            "m = brdffit.models.get('ggx').with_channels(3)\n"
            "print(jax.config.jax_enable_x64, m.eval(m.defaults(), *brdffit.ubo_pairs()).dtype)\n")
    assert _run(code).split() == ["False", "True", "float64"]


def _imports_jax(tree: ast.AST) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name == "jax" or a.name.startswith("jax.") for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "jax":
            return True
    return False


def _imports_x64_at_top(tree: ast.Module) -> bool:
    return any(isinstance(node, ast.ImportFrom) and node.level >= 1 and any(a.name == "_x64" for a in node.names)
               for node in tree.body)


def test_every_module_that_imports_jax_comes_after_x64():
    """A module importing JAX enables float64 itself (a top-level module) or its package's
    ``__init__`` does (run before any of the package's modules)."""
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "_x64.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if not _imports_jax(tree):
            continue
        covered = _imports_x64_at_top(tree)
        folder = path.parent
        while not covered and folder != PACKAGE:
            covered = _imports_x64_at_top(ast.parse((folder / "__init__.py").read_text(encoding="utf-8")))
            folder = folder.parent
        if not covered:
            offenders.append(str(path.relative_to(PACKAGE.parent)))
    assert offenders == []
