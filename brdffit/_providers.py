"""Functions a lower layer calls and a higher layer provides.

brdffit is layered (``[tool.importlinter]`` in pyproject.toml): a module imports only the layers
below its own. Where a lower layer needs something a higher one does, it asks for it here by
name, ``provider(name)(...)``, and the higher layer's function is registered under that name by
``brdffit/_wiring.py``, which ``import brdffit`` runs before any of brdffit's modules:

- ``rgl_eval(path, light, view)``: f_r of an RGL ``.bsdf`` file, (N, 3). SPEC 3 evaluates these
  data with Mitsuba's ``measured`` plugin (the renderer layer); the reader (io) imports no renderer.
- ``fit_png(fit)``, ``fit_to_mitsuba(fit)``, ``fit_convert(fit, model, **options)``,
  ``fit_export(fit, path, **options)``: a FitResult (fitting) drawn by plot, rendered by the
  renderer, converted and written by materials.
- ``report_plot(report, metric)``, ``figure_png(figure)``: a compare Report's figure and its PNG.

This module imports nothing: it is the lowest layer's.
"""

from __future__ import annotations

from collections.abc import Callable

_PROVIDERS: dict[str, Callable] = {}


def provide(name: str, fn: Callable) -> None:
    """Register ``fn`` as what ``provider(name)`` returns."""
    _PROVIDERS[name] = fn


def provider(name: str) -> Callable:
    """The function a higher layer registered under ``name``."""
    try:
        return _PROVIDERS[name]
    except KeyError:
        raise LookupError(f"nothing provides {name!r} (brdffit/_wiring.py registers it when brdffit is imported)") from None
