"""Timings of the readers and writers: ``.venv/bin/python benchmarks/bench_io.py [DATA_DIR]``.

Prints best-of-n wall times (after one warm-up call) for each format; DATA_DIR defaults to
``../shared/data`` (or $BRDFFIT_DATA). Real files that are absent are skipped.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _time(label: str, fn, n: int = 3) -> None:
    fn()
    best = min(_once(fn) for _ in range(n))
    print(f"{label:45s} {best * 1e3:9.1f} ms (best of {n})")


def _once(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    from PIL import Image

    import brdffit
    from brdffit.io.images import direction_name

    argv = sys.argv[1:] if argv is None else argv
    root = Path(argv[0] if argv else os.environ.get("BRDFFIT_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    rgl = sorted((root / "measured" / "rgl").glob("*.bsdf"))
    cornell = sorted((root / "measured" / "cornell").glob("*.brdf"))
    tmp = Path(tempfile.mkdtemp(prefix="brdffit-bench-"))
    from brdffit import sample

    ubo = sample.generate()
    if rgl:
        _time(f"load RGL {rgl[0].name} on UBO-81", lambda: brdffit.load(rgl[0]))
        ubo = brdffit.load(rgl[0])
    if cornell:
        _time(f"load Cornell {cornell[0].name}", lambda: brdffit.load(cornell[0]))
        m = brdffit.load(cornell[0])
        _time("resample Cornell -> UBO-81", lambda: brdffit.resample(m))
    _time("save EXR", lambda: brdffit.save(ubo, tmp / "a.exr", force=True))
    _time("load EXR", lambda: brdffit.load(tmp / "a.exr"))
    _time("save NPZ", lambda: brdffit.save(ubo, tmp / "a.npz", force=True))
    _time("load NPZ", lambda: brdffit.load(tmp / "a.npz"))
    folder = tmp / "png"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(81):
        for j in range(81):
            Image.fromarray(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)).save(folder / f"{direction_name(i, j)}.png")
    _time("load image folder (6561 PNG, 8x8)", lambda: brdffit.load(folder), n=2)
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
