"""Solving one start (docs/fitting.md#fitting): the solve by its solver family (the constants it reads:
``objective.fit_constants``; the check of its result: ``driver.result_check``).

Solver families, one per file: ``lm`` (the default, brdffit's bounded Levenberg-Marquardt:
``solver_lm``), optimistix's stock ``optx_lm`` / ``gauss_newton`` / ``dogleg`` / ``bfgs``
(``solver_optx``), and ``scipy`` (``solver_scipy``, run in Python by the driver). ``atol`` is an
optional absolute floor on the loss (0 by default). Every solve returns a status code
(``_fit_defaults.STATUS_TEXT``); its result is never NaN.
"""

from __future__ import annotations

from collections.abc import Callable

from .objective import Objective
from .solver_lm import BoundedLevenbergMarquardt, solve_lm
from .solver_optx import solve_stock, stock_solver


def make_solver(name: str, rtol: float, atol: float, normal_equations: Callable | None = None):
    """The optimistix solver object behind a solver name (not ``scipy``)."""
    if name == "lm":
        return BoundedLevenbergMarquardt(rtol=rtol, atol=atol, normal_equations=normal_equations)
    return stock_solver(name, rtol, atol)


def solve_one(objective: Objective, solver_name: str, rtol: float, atol: float, max_steps: int):
    """The jit-able solve of one start, at most ``max_steps`` steps. ``lm``: run(v0 (P,), data, lo, hi,
    free, consts, resume=None) -> (v, Resume, done, code, steps) (``solver_lm.solve_lm``: it continues
    from a previous round's ``resume``); a stock solver: run(v0, data, lo, hi, free, consts) -> the same,
    its ``Resume`` holding the loss at v (``c``), at v0 (``c0``) and J^T J at v (``H``). ``consts``:
    ``objective.fit_constants`` of the data. The caller checks the result (:func:`result_check`)."""
    if solver_name == "lm":
        return solve_lm(objective, rtol, atol, max_steps)
    return solve_stock(objective, solver_name, rtol, atol, max_steps)
