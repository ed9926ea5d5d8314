"""The notebooks run in a real Jupyter kernel (nbclient, ipykernel, the inline backend): no cell
fails, every plotting cell shows an image, and no brdffit call changes the kernel's matplotlib
backend (docs/DESIGN.md#where-users-meet-brdffit, defects 2 and 7).

The kernel is this interpreter (tests/notebook_kernel.py writes a kernel spec for sys.executable
into a temporary folder), so the test needs nothing registered on the machine.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from notebook_kernel import INLINE, execute

nbformat = pytest.importorskip("nbformat", reason="the test extra (nbformat, nbclient, ipykernel) is not installed")
pytest.importorskip("nbclient", reason="the test extra (nbclient) is not installed")
pytest.importorskip("ipykernel", reason="the test extra (ipykernel) is not installed")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
CHECK = "__import__('matplotlib').get_backend()"
#: a cell that plots: tagged "plot", or one that calls brdffit.plot / plt.show
PLOTTING = re.compile(r"brdffit\.plot\.|plt\.show\(")


def is_plotting(cell) -> bool:
    return "plot" in cell.metadata.get("tags", []) or bool(PLOTTING.search(cell.source))


def with_backend_checks(nb):
    """A copy of ``nb`` with a cell after each code cell that prints the kernel's backend."""
    out = nbformat.v4.new_notebook(metadata=nb.metadata)
    for cell in nb.cells:
        out.cells.append(cell)
        if cell.cell_type == "code":
            check = nbformat.v4.new_code_cell(f"print('BACKEND', {CHECK})")
            check.metadata["backend_check"] = True
            out.cells.append(check)
    return out


def backend_after(cell) -> str:
    text = "".join(o.get("text", "") for o in cell.outputs if o.output_type == "stream")
    return text.split("BACKEND", 1)[1].strip()


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_in_kernel(path, shared_data, monkeypatch):
    monkeypatch.setenv("BRDFFIT_DATA", str(shared_data))
    nb = nbformat.read(path, as_version=4)
    plotting = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and is_plotting(c)]
    assert plotting, f"{path.name} has no plotting cell"
    done = execute(path, with_backend_checks(nb))  # raises CellExecutionError on any failing cell

    cells = [c for c in done.cells if not c.metadata.get("backend_check")]
    checks = [c for c in done.cells if c.metadata.get("backend_check")]
    for cell in cells:
        errors = [o for o in cell.get("outputs", []) if o.output_type == "error"]
        assert not errors, f"{path.name}: {errors[0]['ename']}: {errors[0]['evalue']}"
    for i in plotting:
        outputs = cells[i].outputs
        assert any("image/png" in o.get("data", {}) for o in outputs), (
            f"{path.name}: plotting cell {i} shows no image:\n{cells[i].source}"
        )
    backends = [backend_after(c) for c in checks]
    assert backends and all(b == INLINE for b in backends), f"{path.name}: backend changed: {backends}"


def test_committed_notebooks_have_outputs():
    """The committed notebooks carry their outputs (a reader sees the figures without running them)."""
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        for i, cell in enumerate(nb.cells):
            if cell.cell_type == "code" and is_plotting(cell):
                assert any("image/png" in o.get("data", {}) for o in cell.outputs), f"{path.name} cell {i}"
