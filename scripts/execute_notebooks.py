"""Execute the notebooks in place, with outputs, in a kernel of this interpreter.

    .venv/bin/python scripts/execute_notebooks.py [notebooks/NAME.ipynb ...]

The kernel is this Python (``sys.executable``, the project's venv), registered in a temporary
Jupyter data folder, so nothing needs installing system-wide. Set BRDFFIT_DATA to use the real
measurements (the committed outputs were made with them).
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from notebook_kernel import execute  # noqa: E402


def main(paths: list[str]) -> int:
    import nbformat

    targets = [Path(p) for p in paths] or sorted((REPO / "notebooks").glob("*.ipynb"))
    for path in targets:
        nb = execute(path)
        nbformat.write(nb, path)
        print(f"executed {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
