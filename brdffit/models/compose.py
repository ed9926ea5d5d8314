"""Composition: a sum of models is a model (``get("lambert+ggx+ggx")``).

Naming scheme (what users and fit files address parameters by)
--------------------------------------------------------------
* One shared diffuse albedo ``kd``. It belongs to the diffuse component (``lambert`` or
  ``oren_nayar``) if there is one, else to the first component that has a ``kd``. Every other
  component's ``kd`` is dropped (held at 0): a second Lambertian term would be redundant with the
  first, and a fit could not tell them apart. At most one diffuse component is allowed.
* Every other parameter is named ``<component><k>.<param>``, k being the 1-based index among the
  components of the same name, counted left to right -- also when a name occurs once::

      lambert+ggx+ggx     -> kd, ggx1.ks, ggx1.alpha, ggx1.f0, ggx2.ks, ggx2.alpha, ggx2.f0
      oren_nayar+ward     -> kd, oren_nayar1.sigma, ward1.ks, ward1.alpha_x, ward1.alpha_y
      ggx+blinn_phong     -> kd (ggx's), ggx1.ks, ..., blinn_phong1.ks, blinn_phong1.n
      lambert+ashikhmin_shirley -> kd, ashikhmin_shirley1.rd, ashikhmin_shirley1.rs, ...

* A single model (no '+') is the model itself, with the docs/models.md#models names.

The composite's formula is the sum of its components' formulas; it is reciprocal when every
component is; a parameter stays ``linear`` in the sum when it was linear in its component (the
components share no parameter but kd, which enters each sum term linearly).

Lobe order (docs/fitting.md#fitting: no mirror-image twin)
-----------------------------------------
Lobes of one kind (the specular lobes of repeated components, ``ggx1`` and ``ggx2``; the lobes of
a multi-lobe Lafortune model) are interchangeable: swapping all their parameters leaves f_r
unchanged, so every fit would have a twin. Fits are therefore reported with the lobes of one
kind ordered **narrowest first** by ``lobe_width``: roughness ascending, exponent descending --
``ggx1.alpha <= ggx2.alpha``, ``blinn_phong1.n >= blinn_phong2.n``, for two-parameter lobes the
product (``ward1.alpha_x * ward1.alpha_y <= ward2.alpha_x * ward2.alpha_y``, ``nu * nv``
descending). The solver works on the unordered space (an order constraint is no box); the fit's
result is put in order by swapping whole lobes (``brdffit.fitting.space``), which changes no
value of f_r, hence no loss. Lobes that ``fixed=`` or ``bounds=`` tell apart (a fixed
``ggx1.f0``, a bound on ``ggx2.alpha`` only) are not interchangeable for that fit: a swap would
break the user's constraint, and no twin exists, so they are left as the solver found them.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import math

import jax.numpy as jnp

from .base import Lobe, Model

#: Components that are a diffuse term (own the shared kd; at most one per composite).
DIFFUSE = ("lambert", "oren_nayar")


@dataclasses.dataclass(frozen=True)
class _Part:
    formula: object
    #: (component parameter name, composite parameter name or None when held at 0)
    names: tuple[tuple[str, str | None], ...]


def _sum_formula(parts: tuple[_Part, ...], p, wi, wo):
    total = None
    for part in parts:  # a loop over a few components, not over samples
        sub = {}
        for own, shared in part.names:
            sub[own] = p[shared] if shared is not None else jnp.zeros_like(p["kd"])
        f = part.formula(sub, wi, wo)
        total = f if total is None else total + f
    return total


def lobe_width(model: Model, lobe: Lobe, values) -> float:
    """The ordering key of a lobe (smaller = narrower): sum of log roughness minus sum of log
    exponent over the lobe's parameters, ``values`` mapping names to arrays (first element used)."""
    key = 0.0
    for name in lobe.params:
        role = model.param(name).role
        v = float(values[name].reshape(-1)[0])
        if role == "roughness":
            key += math.log(max(v, 1e-300))
        elif role == "exponent":
            key -= math.log(max(v, 1e-300))
    return key


def compose(components: Sequence[Model]) -> Model:
    """The sum of ``components`` with the naming scheme of this module."""
    components = tuple(components)
    if not components:
        raise ValueError("compose needs at least one model")
    if len(components) == 1:
        return components[0]
    native = [c.name for c in components if c.is_native]
    if native:
        raise ValueError(
            f"native models do not compose with '+': {', '.join(native)} is a renderer's own BSDF as a whole"
        )
    diffuse = [i for i, c in enumerate(components) if c.name in DIFFUSE]
    if len(diffuse) > 1:
        raise ValueError(
            "a composite has one diffuse term: "
            + " and ".join(components[i].name for i in diffuse)
            + " would both be diffuse"
        )
    with_kd = [i for i, c in enumerate(components) if "kd" in c.param_names]
    owner = diffuse[0] if diffuse else (with_kd[0] if with_kd else None)
    seen: dict[str, int] = {}
    params, parts, lobes = [], [], []
    if owner is not None:
        params.append(components[owner].param("kd"))
    for i, c in enumerate(components):
        seen[c.name] = seen.get(c.name, 0) + 1
        prefix = f"{c.name}{seen[c.name]}."
        names = []
        for q in c.params:
            if q.name == "kd":
                names.append(("kd", "kd" if i == owner else None))
            else:
                params.append(q.renamed(prefix + q.name))
                names.append((q.name, prefix + q.name))
        parts.append(_Part(c.formula, tuple(names)))
        lobes += [Lobe(lobe.kind, tuple(prefix + q for q in lobe.params)) for lobe in c.lobes]
    name = "+".join(c.name for c in components)
    doc = (
        f"Composite model {name}: the sum of its components' BRDFs.\n\n"
        + (__doc__ or "")
        + "\n\nComponents\n----------\n"
        + "\n".join(f"{c.name}: {c.citation}" for c in components)
    )
    return Model(
        name=name,
        params=tuple(params),
        formula=functools.partial(_sum_formula, tuple(parts)),
        citation="; ".join(dict.fromkeys(c.citation for c in components)),
        reciprocal=all(c.reciprocal for c in components),
        float32_jacobian=all(c.float32_jacobian for c in components),
        channels=components[0].channels,
        doc=doc,
        components=components,
        lobes=tuple(lobes),
    )
