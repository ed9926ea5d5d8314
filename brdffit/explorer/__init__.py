"""Interactive exploration in Jupyter (docs/explorer.md#the-explorer): ``brdffit.explore(source)`` is a widget that shows
a fit over its measurement and changes with it.

Views, updated together: the measured and fitted 81x81 tables and their log residual; in-plane
and cross-plane polar slices at the light (measured dots over the model's curve, per channel); the
model's sphere beside the measured one under a movable light (a preview from the model and the
table, a Mitsuba render on request); the fit's loss, ``rel_rmse`` and ``log_rmse``, live, and the
fit's warnings. Controls: the model, a slider per parameter value, the light (sliders, or a click
on a table row), the exposure, and Fit, Multistart, Compare, Export and Render buttons.

The modules: :mod:`.controls` (sliders and parameter checks), :mod:`.lighting` (what depends on the
light: slices' geometry, sphere directions, the measured sphere), :mod:`.compute` (the view of one
parameter set), :mod:`.widget` (the :class:`Explorer` widget; its front end is ``explorer.js``).
The images and the static figure are drawn by :mod:`brdffit.plot.explorer`.
"""

from __future__ import annotations

import os

from ..errors import UsageError


def explore(source, *, model="ggx", fit=None):
    """An :class:`~brdffit.explorer.widget.Explorer` of ``source`` (a UBO-81 ``Measurement``, or
    anything ``brdffit.load`` reads; other grids are resampled to UBO-81 by ``brdffit.resample``).

    ``model``: the model shown first (any name ``brdffit.models.get`` takes), at its defaults.
    ``fit``: a ``FitResult`` or a fit.json path to start from instead (its model and parameters;
    ``model`` is then not used). Display it (the last expression of a cell) to use it."""
    try:
        from .widget import Explorer
    except ModuleNotFoundError as exc:  # anywidget and its Jupyter packages: the notebook extra
        raise UsageError(f"brdffit.explore needs {exc.name}: pip install 'brdffit[notebook]'") from None
    from ..fitting.result import FitResult
    from ..io import resample

    if isinstance(fit, str | os.PathLike):
        fit = FitResult.from_json(fit)
    elif fit is not None and not isinstance(fit, FitResult):
        raise UsageError(f"fit must be a FitResult or a fit.json path, not {type(fit).__name__}")
    return Explorer(resample(source), model=model, fit=fit)


def __getattr__(name: str):
    if name == "Explorer":
        from .widget import Explorer

        return Explorer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Explorer", "explore"]
