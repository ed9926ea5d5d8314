"""Reading and writing measurements (docs/formats.md#readers-and-writers): ``load``, ``save``, ``resample``.

``load(path, **options)`` picks the reader from the file or folder:

============================  ==========  =================================================
source                        format      reader module
============================  ==========  =================================================
folder of images              ``images``  :mod:`brdffit.io.images` (UBO / UTIA / Bonn BTF)
``*.exr`` (81x81 table)       ``exr``     :mod:`brdffit.io.exr`
``*.npz``                     ``npz``     :mod:`brdffit.io.npz`
``*.bsdf`` (tensor_file)      ``rgl``     :mod:`brdffit.io.rgl` (through Mitsuba ``measured``)
``*.brdf`` (Cornell/pbrt-v2)  ``cornell`` :mod:`brdffit.io.cornell`
``*.binary`` (MERL)           ``merl``    :mod:`brdffit.io.merl`
``*.bin`` (UTIA BRDF)         ``utia``    :mod:`brdffit.io.utia`
============================  ==========  =================================================

Every failure inside a reader reaches the caller as ``InputError(path, "<one line>")``: readers
raise it themselves for problems they recognise, and anything unexpected from a parser is wrapped
here, so that the CLI can always print one line that names the file (docs/cli.md#bad-input).
"""

from __future__ import annotations

import contextvars
import importlib
import os
from pathlib import Path

import numpy as np

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from ..errors import InputError, UsageError
from ..measurement import Measurement

#: extension -> format name (lower-case, with the dot)
EXTENSIONS: dict[str, str] = {
    ".exr": "exr",
    ".npz": "npz",
    ".bsdf": "rgl",
    ".brdf": "cornell",
    ".binary": "merl",
    ".bin": "utia",
}
#: format name -> reader module (each defines ``read(path, **options) -> Measurement``)
READERS: dict[str, str] = {
    "images": "brdffit.io.images",
    "exr": "brdffit.io.exr",
    "npz": "brdffit.io.npz",
    "rgl": "brdffit.io.rgl",
    "cornell": "brdffit.io.cornell",
    "merl": "brdffit.io.merl",
    "utia": "brdffit.io.utia",
}
#: whether readers with long loops (image folders) show a progress bar; set by ``load(progress=True)``
PROGRESS: contextvars.ContextVar[bool] = contextvars.ContextVar("brdffit_io_progress", default=False)
#: formats a measurement can be saved in (extension -> writer module)
WRITERS: dict[str, str] = {".exr": "brdffit.io.exr", ".npz": "brdffit.io.npz"}


def detect_format(path: str | os.PathLike) -> str:
    """The reader name for ``path`` (a folder is an image folder), or InputError."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such file or folder")
    if path.is_dir():
        return "images"
    fmt = EXTENSIONS.get(path.suffix.lower())
    if fmt is None:
        known = ", ".join(sorted(EXTENSIONS))
        raise InputError(path, f"unknown format (extension {path.suffix or 'none'!r}; known: {known}, or an image folder)")
    return fmt


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def load(path: str | os.PathLike, *, format: str | None = None, progress: bool = False, **options) -> Measurement:  # noqa: A002
    """Read any supported source into a :class:`~brdffit.Measurement` (docs/conventions.md#conventions conventions).

    ``format`` overrides the detection; ``options`` go to the reader (see each reader's ``read``):
    e.g. ``region=(r0, r1, c0, c1)``, ``includes_cos=True``, ``scale=`` for image folders, ``wi=, wo=``
    for sources that can be evaluated anywhere (RGL, MERL, UTIA; UBO-81 pairs by default).
    ``progress=True`` shows a progress bar on a terminal for long reads (image folders).
    """
    path = Path(path)
    fmt = format or detect_format(path)
    if fmt not in READERS:
        raise UsageError(f"unknown format {fmt!r}; known: {', '.join(sorted(READERS))}")
    if not path.exists():
        raise InputError(path, "no such file or folder")
    reader = importlib.import_module(READERS[fmt])
    token = PROGRESS.set(bool(progress))
    try:
        m = reader.read(path, **options)
    except InputError:
        raise
    except TypeError as exc:
        if "unexpected keyword" in str(exc) or "got an unexpected" in str(exc):
            raise UsageError(f"{fmt} reader: {_one_line(exc)}") from exc
        raise InputError(path, f"cannot read as {fmt}: {type(exc).__name__}: {_one_line(exc)}") from exc
    except MemoryError as exc:
        raise InputError(path, f"cannot read as {fmt}: out of memory (corrupt size field?)") from exc
    except Exception as exc:  # noqa: BLE001 - any parser failure is a bad input, reported on one line
        raise InputError(path, f"cannot read as {fmt}: {type(exc).__name__}: {_one_line(exc)}") from exc
    finally:
        PROGRESS.reset(token)
    check_measurement(m, path)
    return m


def check_measurement(m: Measurement, path) -> None:
    """The one acceptance rule for what every reader returns (``info``, ``convert`` and ``fit``
    agree): at least one usable sample (``Measurement.valid_mask``), else ``InputError``; data
    that can be used but look wrong get one :class:`~brdffit.errors.BrdffitWarning`."""
    import warnings

    from ..errors import BrdffitWarning

    valid = m.valid_mask()
    if not valid.any():
        raise InputError(path, f"no usable sample among {m.n_samples}: every value is NaN/inf, has weight 0 "
                               "or a direction below the horizon")
    values = np.asarray(m.values)[valid]
    if np.all(values < 0):
        warnings.warn(BrdffitWarning(f"{path}: every valid value is negative (min {values.min():.4g}): "
                                     "a BRDF is >= 0; wrong sign or offset?"), stacklevel=2)
    elif np.all(values == 0):
        warnings.warn(BrdffitWarning(f"{path}: every valid value is 0"), stacklevel=2)


def save(m: Measurement, path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write ``m`` as EXR (a UBO-81 table) or NPZ (any samples), picked by extension; atomic."""
    path = Path(path)
    writer = WRITERS.get(path.suffix.lower())
    if writer is None:
        raise UsageError(f"{path}: cannot write {path.suffix or 'files without extension'!r}; use .exr or .npz")
    importlib.import_module(writer).write(m, path, force=force)
    return path


def resample(source, grid: str = "ubo81", *, reciprocal: bool = True, progress: bool = False, **options) -> Measurement:
    """A UBO-81 Measurement from a Measurement or a path (see :mod:`brdffit.io.resampling`)."""
    # (the module is not called ``resample``: importing it would shadow this function)
    from .resampling import EVALUABLE, interpolate_scattered

    if grid != "ubo81":
        raise UsageError(f"unknown grid {grid!r}; supported: 'ubo81'")
    if isinstance(source, str | os.PathLike):
        fmt = detect_format(source)
        m = load(source, progress=progress, **options)  # evaluable sources come back on the UBO-81 grid
        if fmt in EVALUABLE and m.grid == "ubo81":
            return m
    elif isinstance(source, Measurement):
        if options:
            raise UsageError(f"options {sorted(options)} apply only when resampling a path")
        m = source
    else:
        raise UsageError(f"resample() takes a Measurement or a path, not {type(source).__name__}")
    if m.grid == "ubo81":
        return m
    return interpolate_scattered(m, reciprocal=reciprocal)


def summary(m: Measurement) -> dict:
    """What ``brdffit info`` shows, as plain data (ranges over valid samples, per channel)."""
    from ..grid import cartesian_to_spherical

    values = np.asarray(m.values, dtype=np.float64)
    valid = m.valid_mask()
    ti, _ = cartesian_to_spherical(np.asarray(m.wi))
    to, _ = cartesian_to_spherical(np.asarray(m.wo))
    channels = []
    names = ("R", "G", "B") if m.n_channels == 3 else tuple(f"c{i}" for i in range(m.n_channels))
    for c, name in enumerate(names):
        v = values[valid, c]
        channels.append(
            {
                "channel": name,
                "min": float(v.min()) if v.size else float("nan"),
                "max": float(v.max()) if v.size else float("nan"),
                "mean": float(v.mean()) if v.size else float("nan"),
                "negative": int(np.sum(v < 0)),
            }
        )
    deg = np.degrees
    return {
        "name": m.name,
        "format": m.meta.get("format", "?"),
        "source": m.source,
        "samples": m.n_samples,
        "grid": m.grid,
        "channels": m.n_channels,
        "colour_space": m.colour_space,
        "units": m.units,
        "invalid": int(m.n_samples - valid.sum()),
        "zero_weight": int(np.sum(np.asarray(m.weights) <= 0)),
        "non_finite": int(np.sum(~np.all(np.isfinite(values), axis=1))),
        "theta_light_deg": (float(deg(ti.min())), float(deg(ti.max()))),
        "theta_view_deg": (float(deg(to.min())), float(deg(to.max()))),
        "ranges": channels,
    }


__all__ = ["EXTENSIONS", "READERS", "check_measurement", "detect_format", "load", "resample", "save", "summary"]
