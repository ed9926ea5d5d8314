"""Fitting engine (SPEC 5): ``fit``, ``fit_batch``, ``FitResult``, ``compare``, ``Report``, ``select``.

Pipeline of one fit: ``problem.prepare`` (exclude and count invalid samples, normalise weights)
-> ``space.ParameterSpace`` (bounds, ``physical=``, ``bounds=``, ``fixed=``: flat lo, hi, free)
-> ``init.best_starts`` (variable-projection grid: nonlinear parameters on a coarse grid, linear
ones by bounded least squares) -> a compiled solve (exact forward-mode Jacobians, float64):
optimistix ``lm`` / ``gauss_newton`` / ``dogleg`` / ``bfgs`` on the fold-transformed axes with an
active set for optima on bounds, brdffit's own projected Levenberg-Marquardt ``lmb`` on the
bounded values (the fastest, see benchmarks/bench_fit.py), or scipy ``least_squares`` (TRF) as
the reference -> lobes put in order (``space.canonical``) -> ``FitResult`` with metrics, standard
errors, ``at_bound`` and ``warnings``.
"""

from __future__ import annotations

from .api import fit
from .batch import fit_batch
from .compare import Report, compare
from .losses import LOSSES
from .result import FitResult
from .select import Selection, select
from .solve import SOLVERS

__all__ = ["LOSSES", "SOLVERS", "FitResult", "Report", "Selection", "compare", "fit", "fit_batch", "select"]
