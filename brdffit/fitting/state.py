"""The state a solve continues from between rounds (``stages.round_stage``, ``solver_lm``).

A module of its own, importing JAX alone: a compiled round kept on disk names this type in its
signature, and loading the program must import neither optimistix nor the solver.
"""

from __future__ import annotations

from typing import NamedTuple

import jax


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
