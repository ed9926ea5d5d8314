"""The defaults of a fit, in one place (no heavy imports), shared by ``brdffit.fit``,
``brdffit.fit_batch`` and ``brdffit fit`` / ``brdffit compare`` on the command line."""

LOSSES = ("l2", "cosine_l2", "log", "cbrt", "relative")
SOLVERS = ("lm", "optx_lm", "gauss_newton", "dogleg", "bfgs", "scipy")
DEFAULT_LOSS = "log"
DEFAULT_SOLVER = "lm"
DEFAULT_MAX_STEPS = 200
DEFAULT_RTOL = 1e-7
#: Absolute floor on the loss below which a fit stops; 0 = none (convergence must not depend on
#: the data's scale).
DEFAULT_ATOL = 0.0
#: Starts of a composite with several lobes of one kind (``lambert+ggx+ggx``), solved at once.
COMPOSITE_STARTS = 4
#: Solvers that ``brdffit compare`` runs by default.
COMPARE_SOLVERS = ("lm", "optx_lm", "dogleg", "bfgs", "scipy")
