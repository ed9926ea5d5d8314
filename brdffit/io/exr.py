"""UBO-81 tables as OpenEXR "BRDF images" (docs/formats.md#readers-and-writers).

Layout: one 81 x 81 scan-line image, row = light index, column = view index (the UBO order of
``brdffit.grid``), FLOAT channels ``R, G, B`` (or ``Y`` for one channel) holding f_r in 1/sr, and a
FLOAT channel ``weight``. ZIP-compressed. Header attributes:

- ``brdffit.format`` = "ubo81-table/1", ``brdffit.grid`` = "ubo81"
- ``brdffit.meta``: JSON metadata (name, source, grid, colour_space, units, extra)
- ``brdffit.directions``: "ubo81" when the sample directions are exactly the grid's, else
  "stored" with the float64 directions in ``brdffit.f64`` (e.g. UTIA's true, shifted lights)
- ``brdffit.f64``: JSON {array name: base64(zlib(float64 little-endian))} for every array whose
  float64 values are not exactly the float32 pixels (so round trips are exact, not just to float32).
  It is used only while the pixels still equal its float32 rounding: an image edited elsewhere
  is read from its pixels.

Any other 81 x 81 RGB (or Y) EXR is read as a UBO-81 table on the nominal grid.
"""

from __future__ import annotations

import base64
import json
import zlib
from pathlib import Path

import numpy as np

from .._files import atomic_file
from ..errors import InputError, UsageError
from ..grid import UBO_SIZE, ubo_pairs
from ..measurement import Measurement
from ._common import device_copy, meta_from_json, meta_to_json, native_stderr_captured
from .npz import check_usable

FORMAT_TAG = "ubo81-table/1"


def colour_channels(names) -> tuple[str, ...] | None:
    """The channels an EXR table or photograph is read from: R, G, B when all three are there
    (others, such as A or brdffit's weight, are not colour), else Y; None when neither is."""
    names = set(names)
    if {"R", "G", "B"} <= names:
        return ("R", "G", "B")
    return ("Y",) if "Y" in names else None


def _pack(a: np.ndarray) -> str:
    return base64.b64encode(zlib.compress(np.ascontiguousarray(a, dtype="<f8").tobytes(), 6)).decode("ascii")


def _unpack(text: str, shape) -> np.ndarray:
    a = np.frombuffer(zlib.decompress(base64.b64decode(text)), dtype="<f8")
    return a.reshape(shape).astype(np.float64)


def write(m: Measurement, path, *, force: bool = False) -> None:
    import OpenEXR

    if m.grid != "ubo81":
        raise UsageError(
            f"{path}: EXR holds UBO-81 tables only; this measurement has grid={m.grid!r} "
            "(resample it first, e.g. `brdffit convert`, or save as .npz)"
        )
    c = m.n_channels
    if c not in (1, 3):
        raise UsageError(f"{path}: EXR tables hold 1 (Y) or 3 (RGB) channels, not {c}")
    values = np.asarray(m.values, dtype=np.float64)
    weights = np.asarray(m.weights, dtype=np.float64)
    wi, wo = np.asarray(m.wi, dtype=np.float64), np.asarray(m.wo, dtype=np.float64)
    gwi, gwo = ubo_pairs()
    table = values.reshape(UBO_SIZE, UBO_SIZE, c)
    names = ("R", "G", "B") if c == 3 else ("Y",)
    exact = {}
    # Values beyond float32's range become inf in the channels by design (the float64 copy below
    # keeps them): no warning for that cast.
    with np.errstate(over="ignore", invalid="ignore"):
        channels = {n: np.ascontiguousarray(table[:, :, k].astype(np.float32)) for k, n in enumerate(names)}
        channels["weight"] = np.ascontiguousarray(weights.reshape(UBO_SIZE, UBO_SIZE).astype(np.float32))
        if not np.array_equal(values.astype(np.float32).astype(np.float64), values, equal_nan=True):
            exact["values"] = _pack(values)
        if not np.array_equal(weights.astype(np.float32).astype(np.float64), weights, equal_nan=True):
            exact["weights"] = _pack(weights)
    on_grid = np.array_equal(wi, gwi) and np.array_equal(wo, gwo)
    if not on_grid:
        exact["wi"] = _pack(wi)
        exact["wo"] = _pack(wo)
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "brdffit.format": FORMAT_TAG,
        "brdffit.grid": "ubo81",
        "brdffit.layout": "rows = light index, columns = view index (UBO-81 order)",
        "brdffit.directions": "ubo81" if on_grid else "stored",
        "brdffit.meta": meta_to_json(m),
        "brdffit.f64": json.dumps(exact),
    }
    with atomic_file(path, force=force) as tmp:
        OpenEXR.File(header, channels).write(str(tmp))


def _exr_contents(OpenEXR, path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """(header, channel name -> pixels copied out): no OpenEXR object outlives this call."""
    f = OpenEXR.File(str(path), separate_channels=True)
    return dict(f.header()), {k: np.array(v.pixels) for k, v in f.channels().items()}


def read(path, *, name: str | None = None) -> Measurement:
    import OpenEXR

    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        raise InputError(path, "empty file (expected an OpenEXR image)")
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic != b"\x76\x2f\x31\x01":
        raise InputError(path, "not an OpenEXR file (wrong magic number)")
    problem = None
    # The library prints its own messages (some when its objects are freed): they would add
    # lines to the CLI's one, so they are captured, and the objects freed inside the capture:
    # they live only in _exr_contents' frame (no reference cycles), so they are freed when it
    # returns or when the exception that left it is dropped below. (A gc.collect() here cost
    # ~85 ms with JAX loaded, 3 % of a `brdffit fit`.)
    with native_stderr_captured():
        try:
            header, chans = _exr_contents(OpenEXR, path)
        except Exception as exc:  # noqa: BLE001 - the OpenEXR library's message, on one line
            problem = " ".join(str(exc).split())[:200]
    if problem is not None:
        raise InputError(path, f"unreadable OpenEXR (truncated or corrupt): {problem}")
    names = colour_channels(chans)
    if names is None:
        raise InputError(path, f"no R,G,B or Y channels (has {', '.join(sorted(chans)) or 'none'})")
    shape = chans[names[0]].shape
    if shape != (UBO_SIZE, UBO_SIZE):
        raise InputError(path, f"image is {shape[1]}x{shape[0]} pixels; a UBO-81 table is 81x81 (rows light, columns view)")
    table = np.stack([chans[n].astype(np.float64) for n in names], axis=-1)
    values = table.reshape(UBO_SIZE * UBO_SIZE, len(names))
    weights = chans["weight"].astype(np.float64).reshape(-1) if "weight" in chans else np.ones(UBO_SIZE * UBO_SIZE)
    wi, wo = ubo_pairs()
    meta: dict = {}
    try:
        if "brdffit.meta" in header:
            meta = meta_from_json(str(header["brdffit.meta"]))
        exact = json.loads(str(header.get("brdffit.f64", "{}")))
        n = UBO_SIZE * UBO_SIZE
        if "values" in exact:
            v64 = _unpack(exact["values"], values.shape)
            with np.errstate(over="ignore", invalid="ignore"):
                if np.array_equal(v64.astype(np.float32).astype(np.float64), values, equal_nan=True):
                    values = v64
        if "weights" in exact:
            w64 = _unpack(exact["weights"], (n,))
            if np.array_equal(w64.astype(np.float32).astype(np.float64), weights, equal_nan=True):
                weights = w64
        if "wi" in exact and "wo" in exact:
            wi, wo = _unpack(exact["wi"], (n, 3)), _unpack(exact["wo"], (n, 3))
    except (ValueError, KeyError, zlib.error, TypeError) as exc:
        raise InputError(path, f"corrupt brdffit header attributes: {' '.join(str(exc).split())[:200]}") from exc
    check_usable(path, values, weights)
    extra = dict(meta.pop("extra", {}))
    extra.setdefault("format", "exr")
    meta["grid"] = "ubo81"
    if name is not None:
        meta["name"] = name
    meta.setdefault("name", path.stem)
    meta.setdefault("source", str(path))
    wi, wo, values, weights = (device_copy(a) for a in (wi, wo, values, weights))
    return Measurement(wi=wi, wo=wo, values=values, weights=weights, extra=extra, **meta)
