"""Fitting engine (SPEC 5): ``fit``, ``fit_batch``, ``FitResult``, ``compare``, ``Report``, ``select``.

Pipeline of one fit: ``problem.prepare`` (exclude and count invalid samples, normalise weights)
-> ``space.ParameterSpace`` (bounds, ``physical=``, ``bounds=``, ``fixed=``: flat lo, hi, free)
-> ``init.best_starts`` (variable-projection grid: nonlinear parameters on a small structure-aware
grid, linear ones by bounded least squares) -> one compiled, vmapped solve of the best starts
(exact forward-mode Jacobians, float64): ``lm``, brdffit's bounded Levenberg-Marquardt as an
optimistix solver class (``solve.BoundedLevenbergMarquardt``), or optimistix's stock ``optx_lm`` /
``gauss_newton`` / ``dogleg`` / ``bfgs`` on a transformed unconstrained variable, or scipy
``least_squares`` (TRF) as the reference -> ``FitResult`` with metrics, standard errors,
``at_bound`` and ``warnings`` (lobes of one kind put in order by ``space.canonical``).
Compiled code is kept on disk (``cache``).
"""

from __future__ import annotations

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from . import cache as _cache

_cache.enable()  # before anything compiles

from .api import fit  # noqa: E402
from .batch import fit_batch  # noqa: E402
from .compare import Report, compare  # noqa: E402
from .losses import LOSSES  # noqa: E402
from .result import FitResult  # noqa: E402
from .select import Selection, select  # noqa: E402
from .._fit_defaults import SOLVERS  # noqa: E402

__all__ = ["LOSSES", "SOLVERS", "FitResult", "Report", "Selection", "compare", "fit", "fit_batch", "select"]
