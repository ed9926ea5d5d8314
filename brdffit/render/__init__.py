"""Validation rendering in Mitsuba 3 (docs/validation.md#validation-rendering): spheres under a sweep of lights, panels, metrics.

``render_sphere(source, lights, size, irradiance)`` renders one image per light with the
framing of docs/validation.md#validation-rendering; ``validate(source, fit, ...)`` renders a fit and its reference side by side and writes
EXRs, PNG panels and metrics. Mitsuba is imported only in this package (through
``brdffit._mitsuba.mitsuba()``).
"""

from __future__ import annotations

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from .bsdf import Source, as_source
from .renderers import render_sphere
from .validate import Validation, default_lights, validate

__all__ = ["Source", "Validation", "as_source", "default_lights", "render_sphere", "validate"]
