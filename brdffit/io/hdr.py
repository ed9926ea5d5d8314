"""Radiance ``.hdr`` (RGBE) images, as the Bonn database ships its ATRIUM BTFs.

Written from the format's public description (Greg Ward, "Real Pixels", Graphics Gems II, 1991,
and the Radiance file-format notes): a text header starting ``#?RADIANCE`` (or ``#?RGBE``) with
``KEY=value`` lines (``FORMAT=32-bit_rle_rgbe``; ``EXPOSURE=`` multiplies the stored values), an
empty line, a resolution line (``-Y H +X W``: rows top to bottom, columns left to right; the
other orientations are rejected), then the pixels: four bytes (r, g, b, e) each, value =
(byte + 0.5) * 2^(e - 136) and 0 where e = 0 (Radiance's ``colr_color``). Each scanline is either
flat or "new" run-length encoded (it starts with 2, 2 and the width: then each of the four
components follows, as runs: a count > 128 repeats the next byte count - 128 times, a count
<= 128 copies that many bytes). Old-style RLE (repeat markers 1,1,1) is not read.

No library of the field fits: Pillow has no HDR decoder, imageio's needs the FreeImage binary
(downloaded at run time), OpenCV is a large dependency for one codec.
"""

from __future__ import annotations

import io
import os
import re

import numpy as np

_RES = re.compile(rb"^-Y (\d+) \+X (\d+)$")


def decode_hdr(data: bytes) -> np.ndarray:
    """Linear (H, W, 3) float32 of the bytes of an ``.hdr`` file; ValueError on anything else."""
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise ValueError("not a Radiance HDR image (no #?RADIANCE / #?RGBE signature)")
    pos, exposure = 0, 1.0
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            raise ValueError("truncated header")
        line = data[pos:end].strip()
        pos = end + 1
        if not line:
            break
        if line.startswith(b"FORMAT=") and line[7:] != b"32-bit_rle_rgbe":
            raise ValueError(f"unsupported pixel format {line[7:].decode(errors='replace')} (only 32-bit_rle_rgbe)")
        if line.startswith(b"EXPOSURE="):
            exposure *= float(line[9:])
    end = data.find(b"\n", pos)
    match = _RES.match(data[pos:end].strip()) if end >= 0 else None
    if match is None:
        raise ValueError("unsupported or missing resolution line (expected '-Y H +X W')")
    h, w = int(match[1]), int(match[2])
    pos = end + 1
    out = np.empty((h, w, 4), np.uint8)
    buf = memoryview(data)
    n = len(data)
    for row in range(h):
        rle = 8 <= w < 32768 and pos + 4 <= n and data[pos] == 2 and data[pos + 1] == 2 and not data[pos + 2] & 0x80
        if rle:
            if (data[pos + 2] << 8 | data[pos + 3]) != w:
                raise ValueError(f"scanline {row}: run-length width does not match the image width {w}")
            pos += 4
            for c in range(4):
                x = 0
                while x < w:
                    if pos >= n:
                        raise ValueError(f"truncated pixel data in scanline {row}")
                    count = data[pos]
                    if count > 128:
                        count -= 128
                        if pos + 1 >= n:
                            raise ValueError(f"truncated pixel data in scanline {row}")
                        if x + count > w:
                            raise ValueError(f"scanline {row}: run overflows the line")
                        out[row, x : x + count, c] = data[pos + 1]
                        pos += 2
                    else:
                        if pos + 1 + count > n:
                            raise ValueError(f"truncated pixel data in scanline {row}")
                        if count == 0 or x + count > w:
                            raise ValueError(f"scanline {row}: bad run")
                        out[row, x : x + count, c] = np.frombuffer(buf[pos + 1 : pos + 1 + count], np.uint8)
                        pos += 1 + count
                    x += count
        else:
            if pos + 4 * w > n:
                raise ValueError(f"truncated pixel data in scanline {row}")
            px = np.frombuffer(buf[pos : pos + 4 * w], np.uint8).reshape(w, 4)
            if np.any((px[:, 0] == 1) & (px[:, 1] == 1) & (px[:, 2] == 1)):
                raise ValueError("old-style run-length encoding is not supported")
            out[row] = px
            pos += 4 * w
    e = out[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(np.float32(1.0), e - 136), 0.0).astype(np.float32)
    return (out[..., :3].astype(np.float32) + 0.5) * scale[..., None] / np.float32(exposure)


def read_hdr(f) -> np.ndarray:
    """(H, W, 3) float64 from a path or an open binary file."""
    if hasattr(f, "read"):
        data = f.read()
    else:
        with open(f, "rb") as fh:
            data = fh.read()
    return decode_hdr(data).astype(np.float64)


def encode_hdr(img: np.ndarray) -> bytes:
    """RGBE bytes of a linear (H, W, 3) image (negative values clipped to 0), run-length encoded
    per component (for writing test and sample BTFs; readers everywhere accept this form)."""
    a = np.clip(np.asarray(img, np.float64), 0.0, None)
    h, w, _ = a.shape
    peak = a.max(axis=-1)
    mant, exp = np.frexp(peak)  # peak = mant * 2^exp, mant in [0.5, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(peak > 1e-32, 256.0 / np.ldexp(1.0, exp), 0.0)
    rgbe = np.zeros((h, w, 4), np.uint8)
    rgbe[..., :3] = np.clip(np.floor(a * factor[..., None]), 0, 255).astype(np.uint8)
    rgbe[..., 3] = np.where(peak > 1e-32, np.clip(exp + 128, 0, 255), 0).astype(np.uint8)
    out = io.BytesIO()
    out.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for row in range(h):
        if not 8 <= w < 32768:
            out.write(rgbe[row].tobytes())
            continue
        out.write(bytes([2, 2, w >> 8, w & 255]))
        for c in range(4):
            line = rgbe[row, :, c].tobytes()
            # literal chunks only (count <= 128): simple and valid
            for s in range(0, w, 128):
                chunk = line[s : s + 128]
                out.write(bytes([len(chunk)]) + chunk)
    return out.getvalue()


def write_hdr(img: np.ndarray, path: str | os.PathLike) -> None:
    with open(path, "wb") as f:
        f.write(encode_hdr(img))
