"""Lafortune: sums of generalised cosine lobes.

E. P. F. Lafortune, S.-C. Foo, K. E. Torrance, D. P. Greenberg, "Non-Linear Approximation of
Reflectance Functions", SIGGRAPH 1997.

Parameters (one lobe: ``get("lafortune")``)
-------------------------------------------
====  ========  ==============  =========  =======  ========  ========================================
name  channels  bounds          physical   default  role      meaning
====  ========  ==============  =========  =======  ========  ========================================
kd    3         [0, inf)        [0, 1]     0.1      albedo    diffuse albedo (linear)
rho   3         [0, inf)        [0, 1600]  1        albedo    lobe scale (linear; not normalised)
cx    1         [-2, 2]         [-2, 2]    -1       shape     C_x = C_y (isotropic lobe); < 0 forward,
                                                              > 0 retro-reflection
cz    1         [0, 2]          [0, 2]     1        shape     C_z
n     1         [1, inf) (log)  [1, 1e4]   20       exponent  lobe exponent
====  ========  ==============  =========  =======  ========  ========================================

Bounds (what the formula needs): kd, rho >= 0, no upper bound (the lobe is not normalised); n >= 1
(as for ``phong``), no upper bound; cx in [-2, 2], cz in [0, 2]: the lobe is rho |C|^n times a
function of the direction of C, so the length of C trades against rho and this box holds every
lobe direction with cz >= 0 while keeping |C|^n within the cap (see Numerics). Physical range
(``physical=True``): kd <= 1; n <= 1e4; rho <= 1.6e3: a lobe with |C| = 1 has albedo about
rho 2 pi/(n + 2) at normal incidence, so energy conservation couples rho with n (no box); the
physical box holds every rho that allows for n <= 1e4 (1592); C as its bounds.

Formula::

    f_r = kd/pi + sum_j rho_j max(0, cx_j (l_x v_x + l_y v_y) + cz_j l_z v_z)^n_j

Several lobes: ``get("lafortune", lobes=3)`` or ``get("lafortune3")`` is the model named
``lafortune3`` with parameters kd, rho1, cx1, cz1, n1, rho2, cx2, cz2, n2, rho3, ... (lobe j's
parameters carry the suffix j; default exponents ..., 2000, 200, 20, a decade apart so that the
lobes start distinct, the narrowest first as ``compose`` orders lobes); ``lafortune`` itself is
one lobe with the names of docs/models.md#models. Composition ("lambert+lafortune+lafortune") also works and names
lobes lafortune1.rho, lafortune2.rho, ...

With cx = -1, cz = 1 a lobe is Phong's (r.v)^n, the lecture's specular term without its 1/(n.l)
(see ``phong``); Lafortune's lobes generalise it to off-specular and retro-reflective peaks. The
lobe is not normalised: its albedo at normal incidence is about rho 2 pi/(n + 2) for
|C| = 1. Reciprocal (the lobe is symmetric in l and v).

Numerics: where |C| > 1 the lobe grows like |C|^n; with n up to 1e4 that overflows, so the lobe
value is capped at e^100 (float64) / e^35 (float32) -- far beyond any measured reflectance, so
the cap only touches corners of the box that no material occupies.
"""

from __future__ import annotations

import functools
import math

import jax.numpy as jnp
import numpy as np

from . import _math as m
from .base import Lobe, Model, Param, Proposal

INF = math.inf

KD = Param("kd", 3, 0.0, INF, 0.1, "albedo", linear=True, doc="diffuse albedo", physical=(0.0, 1.0))


#: The default start's values of (cx, cz): lobe directions (mirror cx = -cz with its peak value 1,
#: grazing-forward, towards the normal, retro-reflective). The length of C trades against rho, so the
#: box's far corners add no direction; there |C|^n reaches the formula's cap at the grid's
#: exponents, where the solver finds no gradient (docs/fitting.md#hostile-but-valid-data: a noise-free mirror lobe, n 50, was
#: started at (-1.84, 1.92), n 160, and stopped there at rel_rmse 0.087).
C_GRID = ((-1.0, -0.5, 0.0, 0.5, 1.0), (0.7, 1.0))


def lobe_params(suffix: str = "", n: float = 20.0, rho: float = 1.0) -> tuple[Param, ...]:
    return (
        Param("rho" + suffix, 3, 0.0, INF, rho, "albedo", linear=True, doc="lobe scale", physical=(0.0, 1.6e3)),
        Param("cx" + suffix, 1, -2.0, 2.0, -1.0, "shape", doc="C_x = C_y", grid=C_GRID[0]),
        Param("cz" + suffix, 1, 0.0, 2.0, 1.0, "shape", doc="C_z", grid=C_GRID[1]),
        Param("n" + suffix, 1, 1.0, INF, n, "exponent", doc="lobe exponent", physical=(1.0, 1e4)),
    )


def _lobe_defaults(j: int, lobes: int) -> tuple[float, float]:
    """Default (n, rho) of lobe j (1-based) of ``lobes``: exponents a decade apart, the narrowest
    first (..., 2000, 200, 20: the order ``compose.order_lobes`` keeps), so that the lobes start
    distinct, and rho such that each lobe's albedo at normal incidence is about 0.3 / lobes."""
    if lobes == 1:
        return 20.0, 1.0
    n = min(20.0 * 10.0 ** (lobes - j), 1e4)
    return n, round((n + 2.0) / (2.0 * math.pi) * 0.3 / lobes, 4)


def lobe(wi, wo, cx, cz, n):
    """max(0, cx (l_x v_x + l_y v_y) + cz l_z v_z)^n, (N, 1), capped (see module doc)."""
    base = cx * (wi[..., 0:1] * wo[..., 0:1] + wi[..., 1:2] * wo[..., 1:2]) + cz * wi[..., 2:3] * wo[..., 2:3]
    return m.capped_pow(base, n)


def _formula(suffixes, p, wi, wo):
    f = p["kd"] / jnp.pi
    for s in suffixes:  # a loop over lobes (a handful), not over samples
        f = f + p["rho" + s] * lobe(wi, wo, p["cx" + s], p["cz" + s], p["n" + s])
    return f


def halfwidth(p):
    """A lobe with |C| = 1 is (cos psi)^n: 1/2 at psi = acos(2^(-1/n)) (|C| != 1 trades against rho)."""
    return np.arccos(2.0 ** (-1.0 / np.asarray(p["n"], np.float64)))


def _sampling(suffixes, p):
    """A cosine lobe for kd and a cos^n lobe about each C (importance sampling)."""
    return (Proposal("cosine", scales=("kd",)),) + tuple(
        Proposal("power", (p("n" + x), p("cx" + x), p("cz" + x)), ("rho" + x,)) for x in suffixes)


@functools.lru_cache(maxsize=None)
def lafortune(lobes: int = 1) -> Model:
    """The Lafortune model with ``lobes`` lobes (see module doc for the parameter names)."""
    lobes = int(lobes)
    if lobes < 1:
        raise ValueError(f"lafortune needs at least one lobe, got {lobes}")
    suffixes = ("",) if lobes == 1 else tuple(str(j) for j in range(1, lobes + 1))
    params = (KD,) + tuple(
        q for j, s in enumerate(suffixes, 1) for q in lobe_params(s, *_lobe_defaults(j, lobes))
    )
    return Model(
        name="lafortune" if lobes == 1 else f"lafortune{lobes}",
        params=params,
        formula=functools.partial(_formula, suffixes),
        citation="E. P. F. Lafortune, S.-C. Foo, K. E. Torrance, D. P. Greenberg, "
        "Non-Linear Approximation of Reflectance Functions, SIGGRAPH 1997",
        reciprocal=True,
        doc=__doc__,
        halfwidth=halfwidth,
        lobes=tuple(Lobe("lafortune", tuple(q + s for q in ("rho", "cx", "cz", "n"))) for s in suffixes),
        sampling=functools.partial(_sampling, suffixes),
    )


MODEL = lafortune(1)
