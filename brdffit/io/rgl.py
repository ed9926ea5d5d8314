"""RGL-EPFL material database files (Dupuy & Jakob 2018), Mitsuba ``tensor_file`` ``.bsdf``.

The data are evaluated through Mitsuba's own ``measured`` plugin, exactly as the authors intended,
in the order Mitsuba renders them (SPEC 3)::

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

from ..errors import InputError
from ..measurement import Measurement
from ._common import query_directions

MAGIC = b"tensor_file\0"
#: Mitsuba ``Struct::Type`` codes -> bytes per element: Invalid = 0, UInt8, Int8, UInt16, Int16,
#: UInt32, Int32, UInt64, Int64, Float16, Float32, Float64 (the RGL files store 1, 5 and 10).
_DTYPE_SIZE = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 8, 8: 8, 9: 2, 10: 4, 11: 8}
#: fields the ``measured`` plugin reads in an RGB variant
REQUIRED = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb", "valid")


def check_tensor_file(path: Path) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Validate a tensor_file's header and field table; return name -> (dtype, shape)."""
    data = Path(path).read_bytes()
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
    if not 0 < n_fields < 1000:
        raise InputError(path, f"implausible tensor_file field count {n_fields}")
    fields: dict[str, tuple[int, tuple[int, ...]]] = {}
    for _ in range(n_fields):
        (name_len,) = take("<H")
        if pos + name_len > size:
            raise InputError(path, f"truncated tensor_file header at byte {pos} of {size}")
        name = data[pos : pos + name_len].decode("ascii", errors="replace")
        pos += name_len
        ndim, dtype, offset = take("<HBQ")
        shape = take(f"<{ndim}Q") if ndim else ()
        if dtype not in _DTYPE_SIZE:
            raise InputError(path, f"field {name!r} has unknown element type {dtype}")
        nbytes = _DTYPE_SIZE[dtype] * int(np.prod(shape, dtype=np.float64))
        if offset + nbytes > size:
            raise InputError(path, f"truncated: field {name!r} needs bytes {offset}..{offset + nbytes}, file has {size}")
        fields[name] = (dtype, tuple(int(s) for s in shape))
    missing = [f for f in REQUIRED if f not in fields]
    if missing:
        raise InputError(path, f"tensor_file lacks the field(s) {', '.join(missing)} of an RGL RGB material")
    rgb = fields["rgb"][1]
    if len(rgb) != 5 or rgb[2] != 3:
        raise InputError(path, f"field 'rgb' has shape {rgb}, expected (phi_i, theta_i, 3, n, n)")
    # shapes the plugin indexes with one another: a mismatch would read out of bounds in C++
    n_phi, n_theta = rgb[0], rgb[1]
    expected = {
        "phi_i": (n_phi,),
        "theta_i": (n_theta,),
        "luminance": (n_phi, n_theta, rgb[3], rgb[4]),
    }
    for field, shape in expected.items():
        if fields[field][1] != shape:
            raise InputError(path, f"field {field!r} has shape {fields[field][1]}, expected {shape} to match 'rgb' {rgb}")
    if fields["vndf"][1][:2] != (n_phi, n_theta) or len(fields["vndf"][1]) != 4:
        raise InputError(path, f"field 'vndf' has shape {fields['vndf'][1]}, expected ({n_phi}, {n_theta}, n, n)")
    if int(np.prod(fields["valid"][1])) != rgb[3] * rgb[4]:
        raise InputError(path, f"field 'valid' has shape {fields['valid'][1]}, expected {rgb[3] * rgb[4]} entries")
    return fields


def eval_mitsuba(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """f_r(light, view), (N, 3), with one batched ``measured`` evaluation for all pairs."""
    from .._mitsuba import mitsuba

    mi = mitsuba()
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    si = mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    si.wi = mi.Vector3f(np.ascontiguousarray(view.T, dtype=np.float32))
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(np.ascontiguousarray(light.T, dtype=np.float32)))
    f_cos = np.array(value, dtype=np.float64).reshape(3, light.shape[0]).T  # Color3f -> (3, N)
    cos_light = light[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(cos_light[:, None] > 0, f_cos / cos_light[:, None], 0.0)
    return f


def read(path, *, wi=None, wo=None, name: str | None = None) -> Measurement:
    """Sample an RGL ``.bsdf`` at ``wi`` (light), ``wo`` (view): the UBO-81 pairs by default."""
    path = Path(path)
    fields = check_tensor_file(path)
    light, view, grid = query_directions(wi, wo)
    try:
        f = eval_mitsuba(path, light, view)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - Mitsuba's own parse errors become one line
        raise InputError(path, f"Mitsuba's measured plugin cannot read it: {' '.join(str(exc).split())[:300]}") from exc
    ok = (light[:, 2] > 0) & (view[:, 2] > 0) & np.all(np.isfinite(f), axis=1)
    f = np.where(ok[:, None], f, 0.0)
    return Measurement(
        wi=light,
        wo=view,
        values=f,
        weights=ok.astype(np.float64),
        name=name or path.stem,
        source=str(path),
        grid=grid,
        extra={
            "format": "rgl",
            "evaluation": "mitsuba measured: f_r(light, view) = eval(si.wi=view, wo=light) / cos(theta_light)",
            "fields": tuple(sorted(fields)),
        },
    )
