"""f_r of an analytic model as NumPy, the one evaluator outside a fit: ``FitResult.eval``, the
renderers' callback BSDF, the sampler's lobe weights and the 81x81 table panels all call
:func:`eval_model`.

The model's JAX ``eval`` runs as one compiled program per model and length, kept in the process
and on disk like the fit programs (``cache.compiled``): a second process (``brdffit fit`` drawing
fit.png, ``brdffit validate``) loads it without tracing or lowering it. Inputs go through in padded
chunks of two fixed lengths (:data:`SMALL` for a few directions, :data:`CHUNK` otherwise), so one
compilation serves every array length and parameter set (a renderer hands over a different number
of lanes for each light).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

from ..models.base import Model

#: Fixed lengths of the arrays handed to the compiled model: calls with at most SMALL directions
#: (a single pair, Mitsuba's scalar variant) use the small one.
CHUNK = 1 << 16
SMALL = 16

#: Models whose CHUNK program is being compiled or loaded in the background (:func:`warm`).
_WARM: dict[Model, threading.Thread] = {}


def _program(model: Model, length: int):
    from .cache import compiled  # JAX: not needed to read a fit file

    example = ({p.name: np.zeros(model.size(p)) for p in model.params}, np.zeros((length, 3)), np.zeros((length, 3)))
    fn, _ = compiled(("eval", model), lambda: model.eval, *example)
    return fn


def _checked(model: Model, params) -> dict[str, np.ndarray]:
    """``params`` as float64 NumPy arrays of the declared sizes. In NumPy: ``model.check_params``
    works in jax.numpy, whose small programs a second process would lower again (``brdffit fit``
    drawing fit.png); it runs only to word the error of parameters that do not fit."""
    out = {}
    if set(params) == set(model.param_names):
        for p in model.params:
            v = np.atleast_1d(np.asarray(params[p.name], np.float64))
            n = model.size(p)
            if v.shape == (1,) and n > 1:
                v = np.broadcast_to(v, (n,))
            if v.shape != (n,):
                break
            out[p.name] = v
        else:
            return out
    return {k: np.asarray(v, np.float64).reshape(-1) for k, v in model.check_params(params).items()}


def eval_model(model: Model, params, wi, wo) -> np.ndarray:
    """(N, channels) f_r of ``model`` at ``params`` for light ``wi`` and view ``wo`` (N, 3), as the
    formula gives it (no horizon test: callers that need one apply it)."""
    warming = _WARM.get(model)
    if warming is not None and warming.is_alive():
        warming.join()  # one compilation, not two racing ones
    params = _checked(model, params)
    wi = np.asarray(wi, np.float64).reshape(-1, 3)
    wo = np.asarray(wo, np.float64).reshape(-1, 3)
    n = wi.shape[0]
    out = np.empty((n, model.channels))
    length = SMALL if n <= SMALL else CHUNK
    fn = _program(model, length)
    for start in range(0, n, length):
        stop = min(n, start + length)
        if stop - start == length:
            a, b = wi[start:stop], wo[start:stop]
        else:  # padded with the normal (a valid direction for every formula)
            a = np.tile(np.array([[0.0, 0.0, 1.0]]), (length, 1))
            b = a.copy()
            a[: stop - start], b[: stop - start] = wi[start:stop], wo[start:stop]
        out[start:stop] = np.asarray(fn(params, a, b))[: stop - start]
    return out


def warm(model: Model, on_compiled: Callable[[float], None] | None = None) -> None:
    """Compile (or load) ``model``'s CHUNK program in a background thread now, once per model: XLA
    compiles without the GIL, so this overlaps with whatever comes next (in a validation: rendering
    the reference). ``on_compiled(seconds)`` is called from that thread when it is done."""
    if model in _WARM:
        return

    def compile_now():
        t = time.perf_counter()
        _program(model, CHUNK)
        if on_compiled is not None:
            on_compiled(time.perf_counter() - t)

    # Not a daemon thread: the interpreter joins it before tearing down. A daemon thread still
    # compiling at exit comes back to a finalising interpreter, which ends it by unwinding through
    # XLA's C++ frames: "terminate called after throwing an instance of ''" and exit status -6.
    thread = _WARM[model] = threading.Thread(target=compile_now, name="brdffit-jit", daemon=False)
    thread.start()
