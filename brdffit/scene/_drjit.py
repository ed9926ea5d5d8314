"""LOCAL Dr.Jit handling for scene renders with a Python BSDF (issue 12; to be unified with the
general mechanism the "export" work builds in ``brdffit._mitsuba`` / ``brdffit.render``).

Two facts, measured with Mitsuba 3.9.1 / Dr.Jit 1.5.0 (llvm_ad_rgb):

1. A scene holding a Python ``mi.BSDF`` (brdffit's callback BSDF) renders only with Dr.Jit's
   symbolic calls and loops off: the Python ``eval`` leaves Dr.Jit for NumPy / JAX, which needs
   concrete arrays.
2. While such an instance is *alive*, every later render in symbolic mode, of any scene, fails
   ("jit_var_schedule: not permitted" inside ``drjit.custom(_RenderOp)``): a symbolic virtual call
   over the BSDF domain records every registered instance, the Python one included. Once the last
   reference is gone the instance leaves the registry and symbolic renders work again.

So: :func:`python_bsdf_render` turns the two flags off for the duration of a render only and, on
the way out, drops the caller's scene / BSDF references it was handed and collects garbage, so
that nothing of brdffit's stays registered after the public function returns.
"""

from __future__ import annotations

import contextlib
import gc

from .._mitsuba import mitsuba


@contextlib.contextmanager
def python_bsdf_render():
    """Symbolic calls and loops off while the block runs; previous flags and a clean registry after.

    The block must not let a Python BSDF escape (keep it in local variables of the block's owner,
    which go out of scope before this context exits); the final ``gc.collect`` frees cycles between
    nanobind's Python wrapper and the C++ object so the instance leaves Dr.Jit's registry now.
    """
    mi = mitsuba()
    if mi.variant().startswith("scalar"):
        try:
            yield
        finally:
            gc.collect()
        return
    import drjit as dr

    flags = (dr.JitFlag.SymbolicCalls, dr.JitFlag.SymbolicLoops)
    old = [dr.flag(f) for f in flags]
    for f in flags:
        dr.set_flag(f, False)
    try:
        yield
    finally:
        for f, v in zip(flags, old):
            dr.set_flag(f, v)
        gc.collect()
