"""f_r of any Mitsuba BSDF at given directions: :func:`brdffit._mitsuba.eval_bsdf` (the lowest
Mitsuba layer holds it, since the RGL reader evaluates Mitsuba's ``measured`` plugin with it);
importable from here, where the renderer's modules and tests look for it."""

from __future__ import annotations

from .._mitsuba import eval_bsdf  # noqa: F401
