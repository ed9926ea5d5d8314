"""The state a solve continues from between rounds (``stages.round_stage``, ``solver_lm``), and what every
lane's solve ends with (:class:`Rounds`: the compiled solvers' rounds and scipy's lanes give the same).

A module of its own, importing JAX and NumPy alone: a compiled round kept on disk names this type in its
signature, and loading the program must import neither optimistix nor the solver.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np


class Resume(NamedTuple):
    """What a solve continues from (``options["resume"]`` of ``solver_lm``): the last round's loss ``c``, the
    start's loss ``c0``, the gradient and Gauss-Newton matrix at the point, and the damping ``lam``, ``nu``.
    A fit is solved in rounds of a few steps (``stages.round_stage``): between rounds the fits that are done
    leave the batch, the others go on from here, as one long solve would."""

    c: jax.Array
    c0: jax.Array
    g: jax.Array
    H: jax.Array
    lam: jax.Array
    nu: jax.Array


class Rounds(NamedTuple):
    """Every lane's solve after ``stages.solve_rounds`` (or ``solver_scipy.solve_lanes``) (NumPy, the lane axis first)."""

    v: np.ndarray  # (L, P) the solution
    loss: np.ndarray  # (L,) the loss at v (the solver's route)
    start_loss: np.ndarray  # (L,) the loss at the lane's start
    jtj: np.ndarray  # (L, P, P) J^T J at v
    code: np.ndarray  # (L,) status code
    steps: np.ndarray  # (L,)
    compile_s: float
    run_s: float
