"""The defaults of a fit, in one place (no heavy imports), shared by ``brdffit.fit``,
``brdffit.fit_batch`` and ``brdffit fit`` / ``brdffit compare`` on the command line."""

LOSSES = ("l2", "cosine_l2", "log", "cbrt", "relative")
SOLVERS = ("lm", "optx_lm", "gauss_newton", "dogleg", "bfgs", "scipy")
DEFAULT_LOSS = "log"
DEFAULT_SOLVER = "lm"
DEFAULT_MAX_STEPS = 200
#: Relative tolerance on the loss (see solver_lm.BoundedLevenbergMarquardt). 1e-6, not smaller:
#: a lobe narrower than the sample spacing (ks, alpha -> 0 with ks/alpha^2 fixed) lets the loss
#: creep down by ~1e-7 per step for a hundred steps (lambert+ggx+ggx on cc_ibiza_sunset).
DEFAULT_RTOL = 1e-6
#: lm's damping of its first step (lam on the Jacobi-scaled system, whose diagonal is 1: unitless): START_DAMPING from
#: a start that is a guess (the grid's points), NEAR_START_DAMPING from one that lies near its optimum (a BTF
#: texel's fitted neighbours' results where they agree: ``driver.solve(near=True)``), a first step closer to
#: Gauss-Newton's. Madsen, Nielsen & Tingleff (Methods for Non-Linear Least Squares Problems, 2004, 3.2) advise
#: tau = 1e-3 for a guess and 1e-6 for a good start. Measured on generated ggx BTFs (1 % noise, steps a texel,
#: start damping 1e-3 / 1e-4 / 1e-5 / 1e-6): smooth maps 1.96 / 1.75 / 1.75 / 1.75; blocks of one texel of four
#: materials at random 3.45 / 3.61 / 3.75 / 3.86 (agreeing neighbours of another material: an undamped step
#: overshoots); 3 x 3 blocks 1.75 / 1.76 / 1.80 / 1.83. The grid's points with 1e-2 / 1e-3 / 1e-6: 4.25 / 3.38 / 4.74.
START_DAMPING = 1e-3
NEAR_START_DAMPING = 1e-4
#: Absolute floor on the loss below which a fit stops; 0 = none (convergence must not depend on
#: the data's scale).
DEFAULT_ATOL = 0.0
#: Starts of a composite with several lobes of one kind (``lambert+ggx+ggx``), solved at once
#: (see fitting.options.default_starts for the measurement behind 1).
COMPOSITE_STARTS = 1
#: Solvers that ``brdffit compare`` runs by default.
COMPARE_SOLVERS = ("lm", "optx_lm", "dogleg", "bfgs", "scipy")

#: A fit's status code (FitResult.status_code, every solver's result) and its text (FitResult.status).
STATUS_TEXT = {
    0: "converged",
    1: "did not converge: maximum number of steps reached",
    2: "did not converge: the solve diverged",
    3: "did not converge: non-finite values during the solve",
    4: "did not converge: the solver failed",
    5: "did not converge: the model cannot reach the data",
    6: "did not converge: the default start reaches a lower loss",
}
