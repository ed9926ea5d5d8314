"""Run a notebook in a real Jupyter kernel of this interpreter (used by test_notebooks.py and
scripts/execute_notebooks.py).

The kernel spec is written into a temporary Jupyter data folder and points at ``sys.executable``:
the kernel is the project's venv python in a fresh clone too, whatever kernels the machine has.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
from pathlib import Path

KERNEL_NAME = "brdffit-venv"
INLINE = "module://matplotlib_inline.backend_inline"


@contextlib.contextmanager
def venv_kernel():
    """A kernel spec named KERNEL_NAME for this interpreter, visible while the context is open;
    the kernel gets the inline backend (MPLBACKEND unset, so ipykernel chooses it)."""
    saved = {k: os.environ.get(k) for k in ("JUPYTER_PATH", "MPLBACKEND")}
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "kernels" / KERNEL_NAME
        spec.mkdir(parents=True)
        (spec / "kernel.json").write_text(json.dumps({
            "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            "display_name": "brdffit (this venv)",
            "language": "python",
        }))
        os.environ["JUPYTER_PATH"] = os.pathsep.join(x for x in (tmp, saved["JUPYTER_PATH"]) if x)
        os.environ.pop("MPLBACKEND", None)
        try:
            yield KERNEL_NAME
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


def execute(path: Path, nb=None, timeout: int = 600):
    """The notebook at ``path`` (or ``nb``) executed top to bottom in its own folder."""
    import nbformat
    from nbclient import NotebookClient

    path = Path(path)
    nb = nb if nb is not None else nbformat.read(path, as_version=4)
    with venv_kernel() as name:
        client = NotebookClient(nb, kernel_name=name, timeout=timeout, resources={"metadata": {"path": str(path.parent)}})
        client.execute()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    return nb
