"""Dr.Jit handling for scene renders with a Python BSDF (docs/scene.md#scene-aware-fitting), on the one mechanism of
``brdffit._mitsuba.evaluated_calls`` (symbolic calls and loops off while brdffit's Python BSDFs
are called; they return zeros when traced symbolically, so other scenes render in symbolic mode
whatever brdffit BSDFs exist).

Measured with Mitsuba 3.9.1 / Dr.Jit 1.5.0 (llvm_ad_rgb): a scene holding a Python ``mi.BSDF``
renders only with symbolic calls and loops off (its ``eval`` leaves Dr.Jit for NumPy / JAX).
:func:`python_bsdf_render` is that scope plus a garbage collection on the way out, so that the
scene's BSDF instances leave Dr.Jit's registry when the public function returns.
"""

from __future__ import annotations

import contextlib
import gc



@contextlib.contextmanager
def python_bsdf_render():
    """Symbolic calls and loops off while the block runs; previous flags and a clean registry after.

    The block must not let a Python BSDF escape (keep it in local variables of the block's owner,
    which go out of scope before this context exits); the final ``gc.collect`` frees cycles between
    nanobind's Python wrapper and the C++ object so the instance leaves Dr.Jit's registry now.
    """
    from .._mitsuba import evaluated_calls

    try:
        with evaluated_calls():
            yield
    finally:
        gc.collect()
