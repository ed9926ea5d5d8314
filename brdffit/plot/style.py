"""How brdffit's figures look and are written: colours, channel names, PNG compression.

A leaf: it imports no matplotlib (and nothing of brdffit), so that the data of a figure can be
made, and these names read, in a process that never draws (``brdffit.plot.FigureData``).
"""

from __future__ import annotations

import io

EXCLUDED_COLOUR = (1.0, 0.0, 1.0)  # magenta: not a colour of any map used here
CHANNEL_NAMES = {1: ("Y",), 3: ("R", "G", "B")}
CHANNEL_COLOURS = {"R": "tab:red", "G": "tab:green", "B": "tab:blue", "Y": "black"}

#: zlib level of the PNGs brdffit's figures write. PIL's default (6) took 120 ms to encode
#: ``brdffit fit``'s fit.png (1428 x 962), level 3 takes 52 ms for a 9 % larger file.
PNG_COMPRESS_LEVEL = 3


def channel_names(c: int) -> tuple[str, ...]:
    return CHANNEL_NAMES.get(c, tuple(f"channel {k}" for k in range(c)))


def png_bytes(fig, dpi: float = 90) -> bytes:
    """``fig`` as PNG bytes (at :data:`PNG_COMPRESS_LEVEL`: every figure here is a
    ``brdffit.plot.Figure``, whose ``savefig`` applies it)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
