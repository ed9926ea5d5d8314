"""Helpers shared by the readers."""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import UsageError
from ..grid import ubo_pairs
from ..measurement import Measurement

if TYPE_CHECKING:  # the annotation only: readers import jax where they copy
    import jax


def query_directions(wi=None, wo=None) -> tuple[np.ndarray, np.ndarray, str | None]:
    """The (light, view) pairs a reader that can evaluate anywhere should sample.

    Default: the UBO-81 pairs (grid "ubo81"); else the given unit vectors (grid None).
    """
    if wi is None and wo is None:
        wi, wo = ubo_pairs()
        return wi, wo, "ubo81"
    if wi is None or wo is None:
        raise UsageError("give both wi and wo (light and view directions), or neither for the UBO-81 grid")
    wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
    wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
    if wi.shape != wo.shape or wi.ndim != 2 or wi.shape[1] != 3:
        raise UsageError(f"wi {wi.shape} and wo {wo.shape} must both be (N, 3)")
    # A reader evaluates the table at these directions as given: a vector that is not unit would
    # be read at some other angle, or fall outside the table, without a word.
    for name, d in (("wi", wi), ("wo", wo)):
        length = np.linalg.norm(d, axis=1)
        bad = ~(np.abs(length - 1.0) <= 1e-6)  # NaN and inf count as bad
        if bad.any():
            k = int(np.argmax(bad))
            raise UsageError(f"{name}[{k}] = {d[k].tolist()} has length {length[k]:.6g}: directions must be unit vectors")
    return wi, wo, None


def sampled(path, light, view, values, ok, *, name: str | None, grid: str | None, extra: dict) -> Measurement:
    """A source that can be evaluated anywhere (MERL, RGL, UTIA) sampled at (light, view): a sample not
    ``ok`` (below the horizon, not measured, not finite) has value 0 and weight 0, so that the table
    keeps the requested pairs in their order and a fit skips those."""
    ok = np.asarray(ok, dtype=bool)
    return Measurement(wi=light, wo=view, values=np.where(ok[:, None], values, 0.0), weights=ok.astype(np.float64),
                       name=name or Path(path).stem, source=str(path), grid=grid, extra=extra)


# -- metadata as JSON (EXR header, NPZ member) ------------------------------------------------------
def _jsonable(v):
    if isinstance(v, tuple | list):
        return {"__tuple__": [_jsonable(x) for x in v]}
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {"__dict__": [[str(k), _jsonable(x)] for k, x in v.items()]}
    if v is None or isinstance(v, bool | int | float | str):
        return v
    return str(v)  # anything exotic survives as its text


def _from_jsonable(v):
    if isinstance(v, dict) and "__tuple__" in v:
        return tuple(_from_jsonable(x) for x in v["__tuple__"])
    if isinstance(v, dict) and "__dict__" in v:
        return tuple((k, _from_jsonable(x)) for k, x in v["__dict__"])
    return v


META_FIELDS = ("name", "source", "grid", "colour_space", "units")


def meta_to_json(m) -> str:
    import json

    doc = {k: getattr(m, k) for k in META_FIELDS}
    doc["extra"] = [[k, _jsonable(v)] for k, v in m.extra]
    return json.dumps(doc, allow_nan=True)


def meta_from_json(text: str) -> dict:
    """Keyword arguments for Measurement(...) from meta_to_json's text."""
    import json

    doc = json.loads(text)
    if not isinstance(doc, dict):
        raise ValueError("metadata is not a JSON object")
    out = {k: doc[k] for k in META_FIELDS if k in doc}
    out["extra"] = {str(k): _from_jsonable(v) for k, v in doc.get("extra", [])}
    return out


@contextlib.contextmanager
def native_stderr_captured():
    """Capture what a C/C++ library writes straight to file descriptors 1 and 2 (the OpenEXR
    library prints its own messages for a damaged file, some on stdout): the CLI's one line must
    be the only one. Yields a list that holds the captured text afterwards."""
    captured: list[str] = []
    with contextlib.ExitStack() as stack:
        saved = []
        for stream, fd in ((sys.stdout, 1), (sys.stderr, 2)):  # the descriptors C code writes to
            with contextlib.suppress(Exception):
                stream.flush()
            sink = stack.enter_context(tempfile.TemporaryFile())
            saved.append((stream, fd, os.dup(fd), sink))
            os.dup2(sink.fileno(), fd)
        # some messages go through Python's sys.stdout/sys.stderr objects instead of the descriptors
        python_level = io.StringIO()
        stack.enter_context(contextlib.redirect_stdout(python_level))
        stack.enter_context(contextlib.redirect_stderr(python_level))
        try:
            yield captured
        finally:
            captured.append(python_level.getvalue())
            for stream, fd, old, sink in saved:
                with contextlib.suppress(Exception):
                    stream.flush()
                os.dup2(old, fd)
                os.close(old)
                sink.seek(0)
                captured.append(sink.read().decode("utf-8", "replace"))


def device_copy(a) -> "jax.Array":
    """A float64 copy of ``a`` as a JAX array, for a reader's Measurement. (``Measurement`` takes
    NumPy arrays through ``jnp.asarray``, which compiles a copy program per array shape: ~10-40 ms
    each in a new process. ``device_put`` of a private copy compiles nothing; the copy matters,
    as ``device_put`` may share the memory of a NumPy array on the CPU.)"""
    import jax

    return jax.device_put(np.array(a, dtype=np.float64, copy=True))
