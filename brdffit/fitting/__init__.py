"""Fitting engine (docs/fitting.md#fitting): ``fit``, ``fit_batch``, ``FitResult``, ``compare``, ``Report``, ``select``.

The modules, in the order a fit uses them (read them so):

1. the data and the objective: ``problem`` (a Measurement -> ``Data``: excluded samples, weights, the
   data's unit; a batch of them), ``losses`` (the five losses and their residuals), ``objective`` (the
   residual, loss values and metrics, a fit's constants, the structured normal equations of a step),
   ``linalg``;
2. where a fit may move: ``space`` (``ParameterSpace``: bounds, ``physical=``, ``bounds=``,
   ``fixed=``, lobes of one kind in order, ``at_bound`` and warnings);
3. starts: ``init`` (the variable-projection grid: nonlinear parameters on a small structure-aware
   grid, linear ones by bounded least squares; a switched-off lobe re-seeded);
4. solvers, one family per file: ``solve`` (the solve of one start by its family), ``solver_lm``
   (``lm``, brdffit's bounded Levenberg-Marquardt as an optimistix solver), ``solver_optx``
   (optimistix's stock ``optx_lm``, ``gauss_newton``, ``dogleg``, ``bfgs`` on an unconstrained
   variable), ``solver_scipy`` (scipy's TRF, the reference);
5. compiled programs: ``stages`` (start, round and finish, one lane per start), ``lanes`` (how a backend
   runs them: chunks, lanes, rounds), ``state``, ``cache`` (kept per process and on disk);
6. the driver: ``options`` (``FitOptions``, checked once), ``driver`` (every fit runs there:
   ``solve`` -> ``Solved``, one row per fit with its status code), ``measurements``
   (``fit_measurements``: measurements in, FitResults out), ``api`` (the public ``fit`` and
   ``fit_batch``; ``brdffit.fit_btf`` calls the driver too);
7. results: ``result`` (``FitResult``), ``fitfile`` (the fit file's checks);
8. choosing: ``compare`` (error against run time), ``select``.
"""

from __future__ import annotations

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from . import cache as _cache

_cache.enable()  # before anything compiles

from .api import fit, fit_batch  # noqa: E402
from .compare import Report, compare  # noqa: E402
from .losses import LOSSES  # noqa: E402
from .result import FitResult  # noqa: E402
from .select import Selection, select  # noqa: E402
from .._fit_defaults import SOLVERS  # noqa: E402

__all__ = ["LOSSES", "SOLVERS", "FitResult", "Report", "Selection", "compare", "fit", "fit_batch", "select"]
