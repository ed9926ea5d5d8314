"""What the higher layers provide to the lower ones (brdffit/_providers.py), registered when
brdffit is imported.

Each function imports the module that does the work when it is first called: ``import brdffit``
stays without JAX, Mitsuba and matplotlib. This module stands above every layer (the layers:
``[tool.importlinter]`` in pyproject.toml).
"""

from __future__ import annotations

from ._providers import provide


def rgl_eval(path, light, view):
    from .render.measured import eval_measured

    return eval_measured(path, light, view)


def fit_png(fit) -> bytes:
    """The fitted model on the UBO-81 grid (:func:`brdffit.plot.table`), as PNG bytes."""
    from .plot import png_bytes, table

    return png_bytes(table(fit))


def fit_to_mitsuba(fit) -> dict:
    from .render.export import mitsuba_bsdf

    return mitsuba_bsdf(fit)


def fit_convert(fit, model, **options):
    from .materials import convert

    return convert(fit, model, **options)


def fit_export(fit, path, **options):
    from .materials import export

    return export(fit, path, **options)


def report_plot(report, metric: str):
    from .plot import pareto

    return pareto(report, metric)


def figure_png(figure) -> bytes:
    from .plot import png_bytes

    return png_bytes(figure)


for _fn in (rgl_eval, fit_png, fit_to_mitsuba, fit_convert, fit_export, report_plot, figure_png):
    provide(_fn.__name__, _fn)
del _fn
