"""``brdffit demo``: the pipeline on the bundled sample measurement (SPEC 7).

This first version runs what exists in the I/O layer: load the sample (``data/sample_ubo81.exr``,
or a fresh generation when the package is installed without the repository's ``data/``), show
what it holds, convert it to NPZ, and plot the 81 x 81 table. Later steps (fit, validate) are
added as further functions called from :func:`run_demo`. Everything is written into a temporary
folder that replaces ``out`` only when all steps succeeded (atomic, ``force`` to replace).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .measurement import Measurement


def sample_measurement() -> tuple[Measurement, str]:
    """The bundled sample and where it came from."""
    from . import sample
    from .io import load

    if sample.DEFAULT_PATH.exists():
        return load(sample.DEFAULT_PATH), str(sample.DEFAULT_PATH)
    return sample.generate(), "brdffit.sample.generate()"


def plot_table(m: Measurement, path: Path, title: str | None = None) -> Path:
    """PNG of the 81 x 81 table (rows light, columns view), log-scaled luminance-preserving RGB."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .grid import UBO_PHI_STEP_DEG, UBO_THETA_DEG

    table = m.table()
    if table.shape[2] == 1:
        table = np.repeat(table, 3, axis=2)
    valid = m.valid_mask().reshape(81, 81)
    # log tone map: the table spans decades between diffuse and highlight
    positive = table[valid & np.all(table > 0, axis=2)]
    lo = np.percentile(positive, 1) if positive.size else 1e-3
    hi = np.percentile(positive, 99.9) if positive.size else 1.0
    img = np.clip((np.log(np.maximum(table, lo)) - np.log(lo)) / max(np.log(hi) - np.log(lo), 1e-9), 0, 1)
    img[~valid] = (1.0, 0.0, 1.0)  # invalid samples in magenta
    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=110)
    ax.imshow(img, interpolation="nearest")
    # ring boundaries (theta) on both axes
    counts = [360 // s for s in UBO_PHI_STEP_DEG]
    edges = np.cumsum([0, *counts])[1:-1] - 0.5
    for e in edges:
        ax.axhline(e, color="white", lw=0.4, alpha=0.6)
        ax.axvline(e, color="white", lw=0.4, alpha=0.6)
    centres = np.cumsum([0, *counts])[:-1] + np.array(counts) / 2 - 0.5
    ax.set_xticks(centres, [f"{t}" for t in UBO_THETA_DEG])
    ax.set_yticks(centres, [f"{t}" for t in UBO_THETA_DEG])
    ax.set_xlabel("view (theta ring, deg; phi within ring)")
    ax.set_ylabel("light (theta ring, deg; phi within ring)")
    ax.set_title(title or f"{m.name}: f_r, log scale {lo:.3g}..{hi:.3g} 1/sr (magenta: invalid)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def run_demo(out: str | Path, force: bool = False, console=None) -> dict[str, Path]:
    """Run the demo into ``out``; returns the written files by role."""
    from rich.console import Console

    from ._files import atomic_dir
    from .cli.info import print_info
    from .io import save

    console = console or Console()
    out = Path(out)
    m, origin = sample_measurement()
    written: dict[str, Path] = {}
    with atomic_dir(out, force=force) as tmp:
        console.rule("[bold]1. load + info")
        print_info(m, "exr" if origin.endswith(".exr") else "sample", origin, console=console)
        console.rule("[bold]2. convert")
        save(m, tmp / "sample_ubo81.npz")
        console.print(f"wrote {out / 'sample_ubo81.npz'} (wi, wo, values, weights, metadata)")
        written["npz"] = out / "sample_ubo81.npz"
        console.rule("[bold]3. plot the 81 x 81 table")
        plot_table(m, tmp / "table.png")
        console.print(f"wrote {out / 'table.png'}")
        written["table_png"] = out / "table.png"
    return written
