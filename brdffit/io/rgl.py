"""RGL-EPFL material database files (Dupuy & Jakob 2018), Mitsuba ``tensor_file`` ``.bsdf``.

The data are evaluated through Mitsuba's own ``measured`` plugin, exactly as the authors intended,
in the order Mitsuba renders them (docs/formats.md#readers-and-writers; :func:`eval_measured`, through the lowest Mitsuba layer,
:mod:`brdffit._mitsuba`, which imports Mitsuba when a file is first read)::

    f_r(light, view) = eval(si.wi = view, wo = light) / cos(theta_light)

(Mitsuba's ``BSDF.eval`` returns f_r * cos(theta_o), and ``wo`` is the light here.) These data are
not exactly reciprocal, so swapping the two would change the values by up to a few percent.

Before Mitsuba sees a file we check its header and field table ourselves: a truncated or foreign
file must become a clean ``InputError``, never a crash inside the plugin.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from .._files import read_input
from .._mitsuba import eval_bsdf, mitsuba
from ..errors import InputError
from ..measurement import Measurement
from ._common import query_directions, sampled

MAGIC = b"tensor_file\0"
#: Mitsuba ``Struct::Type`` codes -> numpy dtype: Invalid = 0, UInt8, Int8, UInt16, Int16, UInt32,
#: Int32, UInt64, Int64, Float16, Float32, Float64 (the RGL files store 1, 5 and 10).
_DTYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8", 9: "<f2", 10: "<f4", 11: "<f8"}
_UINT8, _FLOAT32 = 1, 10
#: what Mitsuba's ``measured`` plugin (RGB variant) reads: field -> (element type, number of axes).
#: The plugin indexes these arrays with one another's sizes and builds sampling tables (Marginal2D)
#: from them, in C++, without bounds checks: anything it reads must be verified here first.
REQUIRED = {
    "description": (_UINT8, 1),
    "theta_i": (_FLOAT32, 1),
    "phi_i": (_FLOAT32, 1),
    "ndf": (_FLOAT32, 2),
    "sigma": (_FLOAT32, 2),
    "vndf": (_FLOAT32, 4),
    "luminance": (_FLOAT32, 4),
    "rgb": (_FLOAT32, 5),
    "jacobian": (_UINT8, 1),
}
#: distributions the plugin turns into CDFs: finite and non-negative (``rgb`` may dip slightly below 0)
_NON_NEGATIVE = ("ndf", "sigma", "vndf", "luminance")
_MAX_FIELDS = 1000


def check_tensor_file(path: str | Path) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Verify an RGL ``.bsdf`` completely before Mitsuba's ``measured`` plugin may read it.

    Header (magic, version 1.0), the field table (names, element types, axes, shapes that agree
    with one another as the plugin assumes), every field's bytes inside the file, and the values
    the plugin computes with (finite; distributions non-negative; angles sorted and in range).
    Returns name -> (type code, shape); raises ``InputError`` naming the file otherwise.
    """
    path = Path(path)
    data = read_input(path, "an RGL tensor_file .bsdf")
    size = len(data)
    if size == 0:
        raise InputError(path, "empty file (expected an RGL tensor_file .bsdf)")
    if not data.startswith(MAGIC):
        raise InputError(path, "not a Mitsuba tensor_file (wrong magic; expected 'tensor_file\\0')")
    pos = len(MAGIC)

    def take(fmt: str):
        nonlocal pos
        n = struct.calcsize(fmt)
        if pos + n > size:
            raise InputError(path, f"truncated tensor_file header at byte {pos} of {size}")
        out = struct.unpack_from(fmt, data, pos)
        pos += n
        return out

    major, minor = take("<BB")
    if (major, minor) != (1, 0):
        raise InputError(path, f"unsupported tensor_file version {major}.{minor} (expected 1.0)")
    (n_fields,) = take("<I")
    if not 0 < n_fields < _MAX_FIELDS:
        raise InputError(path, f"implausible tensor_file field count {n_fields}")
    table: dict[str, tuple[int, tuple[int, ...], int]] = {}
    for _ in range(n_fields):
        (name_len,) = take("<H")
        if pos + name_len > size:
            raise InputError(path, f"truncated tensor_file header at byte {pos} of {size}")
        try:
            name = data[pos : pos + name_len].decode("ascii")
        except UnicodeDecodeError:
            raise InputError(path, f"garbled tensor_file field table (non-ASCII field name at byte {pos})") from None
        pos += name_len
        ndim, dtype, offset = take("<HBQ")
        if ndim > 8:
            raise InputError(path, f"field {name!r} declares {ndim} axes (garbled field table?)")
        shape = tuple(int(s) for s in take(f"<{ndim}Q")) if ndim else ()
        if dtype not in _DTYPES:
            raise InputError(path, f"field {name!r} has unknown element type {dtype}")
        if name in table:
            raise InputError(path, f"field {name!r} appears twice in the field table")
        table[name] = (dtype, shape, offset)
    header_end = pos
    for name, (dtype, shape, offset) in table.items():
        # Python integers: a garbled shape cannot overflow (it is just far larger than the file)
        nbytes = np.dtype(_DTYPES[dtype]).itemsize * _product(shape)
        if offset < header_end or offset + nbytes > size:
            raise InputError(path, f"truncated or garbled: field {name!r} declares bytes {offset}..{offset + nbytes}, "
                                   f"the file has {size} (header ends at {header_end})")
    spans = sorted((offset, offset + np.dtype(_DTYPES[dtype]).itemsize * _product(shape), name)
                   for name, (dtype, shape, offset) in table.items())
    for (_, end, name), (start, _, following) in zip(spans, spans[1:]):
        if start < end:
            raise InputError(path, f"garbled field table: fields {name!r} and {following!r} overlap")
    missing = [f for f in REQUIRED if f not in table]
    if missing:
        raise InputError(path, f"tensor_file lacks the field(s) {', '.join(missing)} of an RGL RGB material")
    for name, (dtype, ndim) in REQUIRED.items():
        got_type, shape, _ = table[name]
        if got_type != dtype or len(shape) != ndim:
            raise InputError(path, f"field {name!r} is {_DTYPES[got_type]} with shape {shape}, expected "
                                   f"{_DTYPES[dtype]} with {ndim} axes")
    shapes = {name: table[name][1] for name in REQUIRED}
    n_phi, n_theta = shapes["phi_i"][0], shapes["theta_i"][0]
    rgb = shapes["rgb"]
    n = rgb[3]
    expected = {
        "rgb": (n_phi, n_theta, 3, n, n),
        "luminance": (n_phi, n_theta, n, n),
        "vndf": (n_phi, n_theta) + shapes["vndf"][2:],
        "jacobian": (1,),
    }
    for name, shape in expected.items():
        if shapes[name] != shape:
            raise InputError(path, f"field {name!r} has shape {shapes[name]}, expected {shape} (from phi_i, theta_i, rgb)")
    too_small = [name for name in ("ndf", "sigma", "vndf", "luminance")
                 if min(shapes[name][-2:]) < 2] + (["theta_i"] if n_theta < 2 else []) + (["phi_i"] if n_phi < 1 else [])
    if too_small:
        raise InputError(path, f"field(s) {', '.join(too_small)} too small to interpolate")

    def values(name: str) -> np.ndarray:
        dtype, shape, offset = table[name]
        return np.frombuffer(data, dtype=_DTYPES[dtype], count=_product(shape), offset=offset)

    for name in ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb"):
        v = values(name)
        if not np.all(np.isfinite(v)):
            raise InputError(path, f"field {name!r} holds {int(np.sum(~np.isfinite(v)))} non-finite value(s)")
        if name in _NON_NEGATIVE and v.min() < 0:
            raise InputError(path, f"field {name!r} holds negative values (min {float(v.min()):.4g}); it is a distribution")
    theta, phi = values("theta_i").astype(np.float64), values("phi_i").astype(np.float64)
    if theta.min() < 0 or theta.max() > np.pi / 2 + 1e-4 or np.any(np.diff(theta) <= 0):
        raise InputError(path, "field 'theta_i' must rise strictly within 0..pi/2")
    if phi.min() < -np.pi - 1e-4 or phi.max() > 2 * np.pi + 1e-4 or np.any(np.diff(phi) <= 0):
        raise InputError(path, "field 'phi_i' must rise strictly within -pi..2pi")
    if n_phi > 2 and round(2 * np.pi / (phi[-1] - phi[0])) > 4:
        raise InputError(path, "field 'phi_i' covers too small a range of azimuths")
    return {name: (dtype, shape) for name, (dtype, shape, _) in table.items()}


def _product(shape: tuple[int, ...]) -> int:
    out = 1
    for s in shape:
        out *= int(s)
    return out


def load_measured(path: str | Path):
    """Mitsuba's ``measured`` BSDF for an RGL file, verified first (the one door to the plugin)."""
    path = Path(path)
    check_tensor_file(path)
    mi = mitsuba()
    try:
        return mi.load_dict({"type": "measured", "filename": str(path)})
    except Exception as exc:  # noqa: BLE001 - Mitsuba's own parse errors become one line
        raise InputError(path, f"Mitsuba's measured plugin cannot read it: {' '.join(str(exc).split())[:300]}") from None


#: How far (radians) a direction is moved off a pole of the plugin's parametrisation, towards azimuth 0.
POLE_NUDGE = 1e-6


def _towards_azimuth_0(d: np.ndarray, rows: np.ndarray) -> None:
    """Turn ``d[rows]`` by POLE_NUDGE about the y axis, towards +x, in place: y is kept exactly, so a
    vector at the pole (or a half vector there) leaves it along azimuth 0 exactly, which is the way
    the plugin's interpolation is approached (its value at a pole depends on the way)."""
    x, z = d[rows, 0], d[rows, 2]
    c, s = np.cos(POLE_NUDGE), np.sin(POLE_NUDGE)
    d[rows, 0], d[rows, 2] = x * c + z * s, z * c - x * s


def off_the_poles(light: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(light, view) (N, 3) read at azimuth 0 where the plugin's parametrisation has a pole.

    The plugin reads the view's azimuth and the half vector's as atan2(y, x). Where that vector is at
    the pole (x = y = 0: a view along the normal; a light and view mirrored about it, whose half
    vector is the normal) atan2 gives 0 or pi by the sign of a zero, and Dr.Jit's fast-math kernels
    do not keep that sign the same from one compiled kernel to another: the UBO table came out with
    rows mirrored, or mirrored pairs swapped, after other renders in the same process. So such a view
    is turned POLE_NUDGE towards +x, and so is the light of a pair whose half vector is at the pole:
    the value read is the limit along azimuth 0, the same in every process (on the shared RGL files
    it differs from a fresh process's old exact-pole reading by up to 6 % at mirrored pairs, and by a
    mirrored light azimuth in the rows with the view at the pole). Elsewhere nothing moves."""
    # as the kernel sees them: in float32 (two directions that are not quite mirrored in float64 can
    # be, once rounded)
    light = np.asarray(light, np.float32).reshape(-1, 3).astype(np.float64)
    view = np.asarray(view, np.float32).reshape(-1, 3).astype(np.float64)
    at_pole = (view[:, 0] == 0) & (view[:, 1] == 0)
    view[at_pole, 1] = 0.0  # +0: its sign is what the kernels lose
    _towards_azimuth_0(view, at_pole)
    half = light + view
    _towards_azimuth_0(light, (half[:, 0] == 0) & (half[:, 1] == 0))
    return light, view


def eval_plugin(bsdf, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """f_r(light, view), (N, 3), of a loaded ``measured`` plugin (:func:`load_measured`), all pairs at
    once by :func:`brdffit._mitsuba.eval_bsdf`, off the poles of its parametrisation
    (:func:`off_the_poles`): how the reader reads a file and how the validation's reference table
    is evaluated."""
    return eval_bsdf(bsdf, *off_the_poles(light, view))


def eval_measured(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """f_r(light, view), (N, 3), of the RGL file ``path`` (:func:`eval_plugin`)."""
    return eval_plugin(load_measured(path), light, view)


def read(path, *, wi=None, wo=None, name: str | None = None) -> Measurement:
    """Sample an RGL ``.bsdf`` at ``wi`` (light), ``wo`` (view): the UBO-81 pairs by default."""
    path = Path(path)
    light, view, grid = query_directions(wi, wo)
    fields = check_tensor_file(path)
    try:
        f = eval_measured(path, light, view)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - Mitsuba's own parse errors become one line
        raise InputError(path, f"Mitsuba's measured plugin cannot read it: {' '.join(str(exc).split())[:300]}") from exc
    ok = (light[:, 2] > 0) & (view[:, 2] > 0) & np.all(np.isfinite(f), axis=1)
    return sampled(
        path, light, view, f, ok, name=name, grid=grid,
        extra={
            "format": "rgl",
            "evaluation": "mitsuba measured: f_r(light, view) = eval(si.wi=view, wo=light) / cos(theta_light)",
            "fields": tuple(sorted(fields)),
        },
    )
