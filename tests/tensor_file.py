"""Writer of small Mitsuba ``tensor_file`` materials for the ``measured`` plugin (tests only).

Layout (Mitsuba ``TensorFile``): ``tensor_file\\0``, version (u8 1, u8 0), u32 field count, then per
field u16 name length, name, u16 ndim, u8 type (1 UInt8, 10 Float32), u64 byte offset, ndim x u64
shape; the data follow, each field 8-byte aligned.

``isotropic_material`` builds an RGL-like RGB material whose ``eval`` has a closed form: one phi_i
(isotropic), no Jacobian factor, uniform NDF/VNDF/luminance, and an RGB value that depends on the
incident elevation only, linearly between the two theta_i nodes (0 and pi/2):
``eval(si.wi, wo) = rgb0 + (rgb1 - rgb0) * theta(si.wi) / (pi/2)`` for both directions above the
horizon (Mitsuba's ``measured`` eval returns the stored value, which includes the cosine).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

_TYPES = {np.dtype(np.uint8): 1, np.dtype(np.float32): 10}


def write_tensor_file(path: Path, fields: dict[str, np.ndarray]) -> Path:
    header = b"tensor_file\0" + struct.pack("<BBI", 1, 0, len(fields))
    entries = [(name, np.ascontiguousarray(a)) for name, a in fields.items()]
    size = len(header) + sum(2 + len(n) + 2 + 1 + 8 + 8 * a.ndim for n, a in entries)
    offset = (size + 7) // 8 * 8
    table, blobs = b"", b""
    for name, a in entries:
        raw = a.tobytes()
        table += struct.pack("<H", len(name)) + name.encode() + struct.pack("<HBQ", a.ndim, _TYPES[a.dtype], offset)
        table += struct.pack(f"<{a.ndim}Q", *a.shape)
        pad = (-len(raw)) % 8
        blobs += raw + b"\0" * pad
        offset += len(raw) + pad
    body = header + table
    body += b"\0" * ((len(body) + 7) // 8 * 8 - len(body))
    Path(path).write_bytes(body + blobs)
    return Path(path)


def isotropic_material(path: Path, rgb0, rgb1, n: int = 8, **replace: np.ndarray) -> Path:
    """``replace``: fields written instead of the generated ones, or left out where None (to make a
    malformed material)."""
    f32 = np.float32
    rgb = np.empty((1, 2, 3, n, n), f32)
    rgb[0, 0] = np.asarray(rgb0, f32)[:, None, None]
    rgb[0, 1] = np.asarray(rgb1, f32)[:, None, None]
    fields = {**{
        "description": np.frombuffer(b"brdffit test material", np.uint8),
        "jacobian": np.array([0], np.uint8),
        "theta_i": np.array([0.0, np.pi / 2], f32),
        "phi_i": np.array([0.0], f32),
        "ndf": np.ones((n, n), f32),
        "sigma": np.ones((n, n), f32),
        "vndf": np.ones((1, 2, n, n), f32),
        "luminance": np.ones((1, 2, n, n), f32),
        "rgb": rgb,
        "valid": np.ones((n * n,), np.uint8),
    }, **replace}
    return write_tensor_file(path, {name: a for name, a in fields.items() if a is not None})
