"""colour-science is imported through ``brdffit._colour`` alone, which leaves NumPy's print options as they were
(colour 0.4 sets ``legacy="1.13"`` for the whole process on import; docs/DESIGN.md#layers)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(REPO)}

#: A new process (this one may have imported colour already): NumPy's print options after brdffit read a
#: spectrum into RGB (the Cornell reader) and made a conductor's spectra (mitsuba:roughconductor).
AFTER_THE_COLOUR_TABLES = """
import numpy as np
before = np.get_printoptions()
from brdffit.io.cornell import spectral_to_rgb_matrix
from brdffit.models._spectra import srgb_projection
spectral_to_rgb_matrix((450.0, 550.0, 650.0))
srgb_projection()
import sys
assert "colour" in sys.modules
print(np.get_printoptions() == before, np.get_printoptions()["legacy"], repr(np.array([0.3, 0.2])))
"""


def test_numpys_print_options_are_left_as_they_were():
    r = subprocess.run([sys.executable, "-c", AFTER_THE_COLOUR_TABLES], capture_output=True, text=True, env=ENV,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split(None, 2) == ["True", "False", "array([0.3, 0.2])\n"]


def test_only_the_gate_imports_colour():
    found = []
    for path in sorted((REPO / "brdffit").rglob("*.py")):
        if path.name == "_colour.py" and path.parent.name == "brdffit":
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
            if any(n == "colour" or n.startswith("colour.") for n in names):
                found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert found == []
