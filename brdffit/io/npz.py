"""NumPy ``.npz`` measurements: arrays ``wi`` (N,3), ``wo`` (N,3), ``values`` (N,C), ``weights`` (N,)
in float64, and ``metadata``: a 0-d unicode array holding JSON (name, source, grid, colour_space,
units, extra). Read without pickle. Round trips are exact (float64 arrays, metadata values of
types str, int, float, bool, None, tuples of those)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from .._files import atomic_file
from ..errors import InputError
from ..measurement import Measurement
from ._common import meta_from_json, meta_to_json

REQUIRED = ("wi", "wo", "values")


def write(m: Measurement, path, *, force: bool = False) -> None:
    with atomic_file(path, force=force) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                wi=np.asarray(m.wi, dtype=np.float64),
                wo=np.asarray(m.wo, dtype=np.float64),
                values=np.asarray(m.values, dtype=np.float64),
                weights=np.asarray(m.weights, dtype=np.float64),
                metadata=np.array(meta_to_json(m)),
            )


def read(path, *, name: str | None = None) -> Measurement:
    path = Path(path)
    if path.stat().st_size == 0:
        raise InputError(path, "empty file (expected a .npz archive)")
    if not zipfile.is_zipfile(path):
        raise InputError(path, "not a .npz archive (no zip structure; truncated or another format)")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, ValueError, OSError) as exc:
        raise InputError(path, f"corrupt .npz archive: {' '.join(str(exc).split())}") from exc
    missing = [k for k in REQUIRED if k not in arrays]
    if missing:
        raise InputError(path, f"missing array(s) {', '.join(missing)} (a measurement .npz holds wi, wo, values)")
    meta = {}
    if "metadata" in arrays:
        try:
            meta = meta_from_json(str(arrays["metadata"][()]))
        except ValueError as exc:
            raise InputError(path, f"unreadable metadata: {exc}") from exc
    for key in (*REQUIRED, "weights"):
        if key in arrays and arrays[key].dtype.kind not in "biuf":
            kind = "complex" if arrays[key].dtype.kind == "c" else str(arrays[key].dtype)
            raise InputError(path, f"array {key!r} holds {kind} values; a measurement holds real numbers")
    wi, wo, values = (np.asarray(arrays[k], dtype=np.float64) for k in REQUIRED)
    if values.ndim == 1:
        values = values[:, None]
    n = values.shape[0]
    if values.ndim != 2 or wi.shape != (n, 3) or wo.shape != (n, 3):
        raise InputError(path, f"inconsistent shapes: wi {wi.shape}, wo {wo.shape}, values {values.shape}")
    weights = np.asarray(arrays.get("weights", np.ones(n)), dtype=np.float64)
    if weights.shape != (n,):
        raise InputError(path, f"weights {weights.shape} do not match {n} samples")
    if n == 0:
        raise InputError(path, "no samples")
    wi, wo = unit_directions(path, "wi", wi), unit_directions(path, "wo", wo)
    check_usable(path, values, weights)
    extra = dict(meta.pop("extra", {}))
    extra.setdefault("format", "npz")
    if name is not None:
        meta["name"] = name
    meta.setdefault("name", path.stem)
    meta.setdefault("source", str(path))
    if meta.get("grid") == "ubo81" and n != 81 * 81:
        raise InputError(path, f"metadata says grid ubo81 but there are {n} samples")
    return Measurement(wi=wi, wo=wo, values=values, weights=weights, extra=extra, **meta)


def check_usable(path, values: np.ndarray, weights: np.ndarray) -> None:
    """A table without a single finite, positively weighted sample is bad input."""
    ok = np.all(np.isfinite(values), axis=1) & (weights > 0)
    if not ok.any():
        raise InputError(path, "no usable sample: every value is NaN/inf or has weight 0")


#: how far from 1 a direction's length may be and still count as a unit vector stored in float32
#: or rounded text; it is then normalised. Anything else is refused: a length of 0.5 or 57 means
#: another convention (degrees, unnormalised half vectors...), and guessing would fit nonsense.
UNIT_TOLERANCE = 1e-3


def unit_directions(path, name: str, d: np.ndarray) -> np.ndarray:
    """``d`` (N, 3) normalised, when every row is a unit vector up to :data:`UNIT_TOLERANCE`."""
    with np.errstate(all="ignore"):
        length = np.linalg.norm(d, axis=1)
    bad = ~(np.abs(length - 1.0) <= UNIT_TOLERANCE)  # NaN lengths are bad too
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(path, f"{int(bad.sum())} of {len(d)} directions in {name!r} are not unit vectors "
                               f"(e.g. sample {k}: length {length[k]:.6g})")
    # rows already unit to rounding are kept bit for bit (exact round trips of brdffit's own files)
    return np.where((np.abs(length - 1.0) > 1e-12)[:, None], d / length[:, None], d)
