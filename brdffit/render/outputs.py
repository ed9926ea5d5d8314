"""What every validation does around its renders: one skeleton for the sphere (``brdffit.validate``),
the BTF (``brdffit.validate_btf``) and the scene (``brdffit.validate_scene``) validations.

A :class:`ValidationRun` times the stages (``lap``), checks the output folder before any work,
writes into it atomically (``folder``: it appears complete or not at all), writes images as
32-bit float EXR and figures as PNG, keeps the list of files written, and writes ``metrics.json``
(strict JSON: an infinite PSNR or a NaN ratio becomes null) with the stages' seconds.
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path

import numpy as np


def finite_or_null(x):
    """Metrics as strict JSON: inf (identical images' PSNR) and NaN (an all-black reference's
    relative RMSE) become null."""
    if isinstance(x, dict):
        return {k: finite_or_null(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_null(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def write_exr(path: Path, img: np.ndarray, compression: str = "rle") -> None:
    """An (H, W, 3) image as a 32-bit float RGB EXR. RLE by default: lossless, fast, and the black
    background around a sphere packs well; "zip" for photographs (the BTF's)."""
    import OpenEXR

    codec = {"rle": OpenEXR.RLE_COMPRESSION, "zip": OpenEXR.ZIP_COMPRESSION}[compression]
    header = {"compression": codec, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(img, dtype=np.float32)}) as f:
        f.write(str(path))


class ValidationRun:
    """One validation's timer and output folder. ``out`` None: nothing is written (the methods that
    write do nothing, ``files`` stays empty)."""

    def __init__(self, out: str | Path | None, force: bool = False):
        from .._files import check_target

        self.out = None if out is None else Path(out)
        self.force = bool(force)
        if self.out is not None:
            check_target(self.out, self.force)  # fail before the work, not after it
        self.seconds: dict[str, float] = {}
        self.files: list[Path] = []
        self._start = self._last = time.perf_counter()
        self._tmp: Path | None = None

    def lap(self, stage: str) -> None:
        """The time since the last lap, added to ``stage``'s."""
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - self._last
        self._last = now

    def total(self) -> float:
        return time.perf_counter() - self._start

    def rounded_seconds(self) -> dict[str, float]:
        return {k: round(v, 4) for k, v in self.seconds.items()}

    @contextlib.contextmanager
    def folder(self):
        """The output folder to write into (a temporary one renamed to ``out`` on success), or None."""
        if self.out is None:
            yield None
            return
        from .._files import atomic_dir

        with atomic_dir(self.out, force=self.force) as tmp:
            self._tmp = tmp
            try:
                yield tmp
            finally:
                self._tmp = None

    @property
    def writing(self) -> bool:
        return self._tmp is not None

    def _target(self, name: str) -> Path | None:
        if self._tmp is None:
            return None
        self.files.append(self.out / name)
        return self._tmp / name

    def exr(self, name: str, img: np.ndarray, compression: str = "rle") -> None:
        path = self._target(name)
        if path is not None:
            write_exr(path, img, compression)

    def png(self, name: str, figure, dpi: float | None = None) -> None:
        path = self._target(name)
        if path is not None:
            figure.savefig(path, **({} if dpi is None else {"dpi": dpi}))

    def metrics_json(self, metrics: dict) -> None:
        """``metrics.json``: ``metrics`` as strict JSON (see :func:`finite_or_null`)."""
        path = self._target("metrics.json")
        if path is not None:
            path.write_text(json.dumps(finite_or_null(metrics), indent=2) + "\n")
