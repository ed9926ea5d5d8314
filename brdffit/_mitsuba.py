"""The one gate to Mitsuba 3 / Dr.Jit: pick a libLLVM that works, then a variant.

Mitsuba's LLVM back end needs libLLVM >= 16; with 14 or 15 alone it *aborts the process*
("Cannot select ... fmaximum") on the first kernel using max/min. Dr.Jit reads the library
path from ``DRJIT_LIBLLVM_PATH`` when it is imported, so this module must run before any
``import drjit``. Without a usable libLLVM we fall back to ``scalar_rgb`` with one warning.
Modules that render import Mitsuba through :func:`mitsuba` and nowhere else; :func:`eval_bsdf`
is the one way brdffit evaluates a Mitsuba BSDF outside a render (the RGL reader's ``measured``
plugin, the validation's reference table). This module imports no other part of brdffit: it stands
in the lowest layer, so that the reader (io) can import it.
"""

from __future__ import annotations

import contextlib
import glob
import os
import re
import sys
import warnings
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float

MIN_LLVM = 16
_LIB_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)
_state: dict = {}


def llvm_version(path: str) -> int | None:
    """Major version from a libLLVM file name (libLLVM-19.so, libLLVM.so.19.1, libLLVM-15.so.1)."""
    name = os.path.basename(path)
    m = re.match(r"libLLVM-(\d+)", name) or re.match(r"libLLVM\.(?:so|dylib)\.(\d+)", name)
    if m is None and "/llvm-" in path:
        m = re.search(r"/llvm-(\d+)/", path)
    return int(m.group(1)) if m else None


def _search_globs() -> tuple[str, ...]:
    # BRDFFIT_LLVM_GLOBS (os.pathsep-separated glob patterns) replaces the default search: tests use
    # it to play a machine that has only libLLVM 14/15.
    env = os.environ.get("BRDFFIT_LLVM_GLOBS")
    return tuple(env.split(os.pathsep)) if env else _LIB_GLOBS


def find_libllvm() -> str | None:
    """Path of the newest libLLVM >= 16 on this machine, or None."""
    found: list[tuple[int, str]] = []
    for pattern in _search_globs():
        for path in glob.glob(pattern):
            v = llvm_version(path)
            if v is not None and v >= MIN_LLVM and os.path.isfile(path):
                found.append((v, path))
    return max(found)[1] if found else None


def choose_variant(preferred: str = "llvm_ad_rgb") -> str:
    """Point Dr.Jit at a usable libLLVM and return the variant to use (decided once)."""
    if "variant" in _state:
        return _state["variant"]
    variant = preferred
    if preferred.startswith("llvm"):
        current = os.environ.get("DRJIT_LIBLLVM_PATH")
        if current and (llvm_version(current) or MIN_LLVM) < MIN_LLVM:
            current = None  # a known-bad choice would abort the process: look for a better one
        path = current or find_libllvm()
        if path is None:
            variant = "scalar_rgb"
            warnings.warn(
                "brdffit: no libLLVM >= 16 found (Mitsuba's LLVM back end aborts with 14/15); "
                "rendering with the slow scalar_rgb variant. Install libllvm19 (Debian) or set "
                "DRJIT_LIBLLVM_PATH to a newer libLLVM.",
                RuntimeWarning,
                stacklevel=3,
            )
        else:
            os.environ["DRJIT_LIBLLVM_PATH"] = path
    _state["variant"] = variant
    return variant


def mitsuba(preferred: str = "llvm_ad_rgb"):
    """Import Mitsuba with a safe variant set, and return the module."""
    variant = choose_variant(preferred)
    import mitsuba as mi  # noqa: PLC0415 - Mitsuba is imported only where it is needed

    if mi.variant() != variant:
        mi.set_variant(variant)
    return mi


def user_mitsuba():
    """Mitsuba with the caller's variant when one is already set (a user's own scene), else brdffit's.

    ``mitsuba()`` switches to brdffit's variant; code that hands objects to a *user's* scene
    (``FitResult.to_mitsuba``, the ``brdffit`` plugin) must not change the variant under them.
    """
    import sys

    mi = sys.modules.get("mitsuba")
    if mi is not None:
        try:
            if mi.variant() is not None:
                return mi
        except Exception:  # noqa: BLE001 - an old Mitsuba without variant(): fall through
            pass
    return mitsuba()


def symbolic_scope() -> bool:
    """True while Dr.Jit records a symbolic call or loop (no array may be read back then)."""
    import drjit as dr

    return bool(dr.flag(dr.JitFlag.SymbolicScope))


@contextlib.contextmanager
def evaluated_calls():
    """Render scenes that hold one of brdffit's *Python-callback* BSDFs: Dr.Jit virtual calls and
    loops run *evaluated*.

    A fit's BSDF (``FitResult.to_mitsuba()``, the ``brdffit`` plugin, parameter maps) needs none of
    this: its formula runs in Dr.Jit, in Mitsuba's default symbolic mode. What needs it is a BSDF whose
    ``eval`` hands Mitsuba's arrays to NumPy and back -- a measured UBO-81 table rendered by its
    interpolator (``brdffit.render.bsdf.CallbackBSDF``), which Dr.Jit allows only when it evaluates
    calls (the default, symbolic mode records them into one kernel and forbids reading arrays back).
    brdffit's own renders run inside it, and so may a user's::

        with brdffit.evaluated_calls():
            image = mi.render(scene, spp=64)

    The flags are restored on exit (also after an error), so other scenes render as before, in
    symbolic mode. Scenes *without* such a BSDF need nothing: one that merely exists while another
    scene is rendered symbolically is traced by Dr.Jit (every registered BSDF is) and answers with
    zeros that no ray of that scene can reach. Nesting is allowed.
    """
    mi = sys.modules.get("mitsuba")
    if mi is None or (mi.variant() or "").startswith("scalar"):
        yield  # no Dr.Jit JIT in use (or the scalar variant: nothing is recorded)
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


def render(scene, **kwargs):
    """``mi.render(scene, **kwargs)`` inside :func:`evaluated_calls` (works for any scene)."""
    mi = user_mitsuba()
    with evaluated_calls():
        return mi.render(scene, **kwargs)


def eval_bsdf(bsdf, wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> Float[np.ndarray, "N 3"]:
    """f_r(wi = light, wo = view) of any Mitsuba BSDF at local directions, in 1/sr (cosine removed).

    This is how a ``measured`` RGL file is read (:mod:`brdffit.io.rgl`) and how a reference is
    evaluated outside a render (the 81x81 table panel, the closed-form agreement test), in the
    order Mitsuba renders it (docs/formats.md#readers-and-writers).
    """
    mi = mitsuba()
    wi = np.asarray(wi, np.float64).reshape(-1, 3)
    wo = np.asarray(wo, np.float64).reshape(-1, 3)
    n = wi.shape[0]
    if mi.variant().startswith("scalar"):
        out = np.zeros((n, 3))
        ctx = mi.BSDFContext()
        for k in range(n):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo[k])
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            v = bsdf.eval(ctx, si, mi.Vector3f(*wi[k]))
            out[k] = np.array([v[0], v[1], v[2]], np.float64)
    else:
        import drjit as dr

        si = dr.zeros(mi.SurfaceInteraction3f, n)  # every field defined, at the batch's width
        si.wi = mi.Vector3f(*(mi.Float(wo[:, c].astype(np.float32)) for c in range(3)))
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        with evaluated_calls():
            v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(mi.Float(wi[:, c].astype(np.float32)) for c in range(3))))
        out = np.stack([np.asarray(v[c], np.float64) for c in range(3)], -1).reshape(n, 3)
    cos_l = wi[:, 2:3]
    return np.where(cos_l > 0, out / np.where(cos_l > 0, cos_l, 1.0), 0.0)
