"""The parameter space of one fit (docs/fitting.md#parameter-space): bounds, fixed values, lobe order.

``ParameterSpace.build(model, bounds=, fixed=, physical=)`` resolves, per flat parameter entry:

1. the model's declared bounds (only what the formula needs; may be infinite, see
   ``brdffit.models.base``);
2. with ``physical=True``, the declared physical range instead (finite, plausible);
3. ``bounds={"name": (lo, hi)}``: the user's box for that parameter (replaces 1 and 2; ``None`` on
   a side keeps that side of 1, or of 2 with ``physical=True``). It must lie inside the declared
   bounds -- outside them the formula is not defined or not finite -- and it may be wider than the
   physical range;
4. ``fixed={"name": value}``: the parameter is held at ``value`` (a scalar, or one value per
   channel); the value must lie inside the declared bounds and any ``bounds=`` given for it
   (the physical range does not apply to a value the user fixes).

The result is data-independent and immutable: flat ``lo, hi`` (float64, may hold +-inf), the
``free`` mask (False = held at its value), ``values`` (the fixed values, NaN where free) and the
groups of interchangeable lobes (``order``). Solvers take ``lo, hi, free`` as arguments.

Lobe order: lobes of one kind are ordered narrowest first (``brdffit.models.compose``); the
solver works on the unordered box and ``canonical`` swaps whole lobes of a fitted vector into
order, which leaves f_r and the loss unchanged. Lobes are interchangeable for a fit only when
the user's constraints do not tell them apart: equal ``lo``, ``hi``, ``free`` and fixed values
entry by entry; otherwise a swap would break a constraint (and no mirror twin exists), so such
lobes are left as found.

Known limit: the box cannot express coupled criteria: ``physical=True`` bounds each albedo on its
own (kd <= 1, ks <= 1), not their sum.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping

import numpy as np

from ..errors import UsageError
from ..models.base import Lobe, Model
from ..models.compose import lobe_width

#: A parameter within this fraction of its span of a bound counts as on it (span: the finite
#: width of its box, or of ``Param.finite_range`` where the box is infinite).
AT_BOUND_RTOL = 1e-6
#: A lobe whose full width at half maximum is below this fraction of the sample spacing is a needle:
#: at most the exact mirror samples see it (a scale and a roughness that only trade against each
#: other there), so its shape is not fitted but left where the solve fell (:meth:`ParameterSpace.unseen_lobes`).
NEEDLE_FRACTION = 0.1


def _span(model: Model, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    width = hi - lo
    finite = np.concatenate([np.full(model.size(p), p.finite_range[1] - p.finite_range[0]) for p in model.params])
    return np.where(np.isfinite(width) & (width > 0), width, np.maximum(finite, 1e-300))


def _number(name: str, what: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{what} for {name!r}: {value!r} is not a number") from None
    if math.isnan(v):
        raise UsageError(f"{what} for {name!r}: NaN is not a value")
    return v


@dataclasses.dataclass(frozen=True, eq=False)
class ParameterSpace:
    """Where a fit may move: flat ``lo``/``hi`` (may be infinite), ``free`` mask, fixed ``values``,
    interchangeable lobe groups ``order`` (each group narrowest first after ``canonical``)."""

    model: Model
    lo: np.ndarray
    hi: np.ndarray
    free: np.ndarray
    values: np.ndarray
    order: tuple[tuple[Lobe, ...], ...]
    physical: bool = False
    #: Names given in ``bounds=`` (for messages).
    overridden: frozenset[str] = frozenset()
    #: The flat layout read from the model once, when the space is built: its default values (clipped
    #: into the box: the start "defaults", and the value of a held parameter a solve must not move) and
    #: the entries of its linear parameters (those a table's unit scales).
    anchor: np.ndarray | None = None
    linear: np.ndarray | None = None

    # -- construction -----------------------------------------------------------------------------
    @classmethod
    def build(cls, model: Model, bounds: Mapping | None = None, fixed: Mapping | None = None,
              physical: bool = False) -> "ParameterSpace":
        bounds = dict(bounds or {})
        fixed = dict(fixed or {})
        for what, given in (("bounds", bounds), ("fixed", fixed)):
            unknown = [k for k in given if k not in model.param_names]
            if unknown:
                raise UsageError(
                    f"{what}: model {model.name!r} has no parameter {unknown[0]!r}; it has {', '.join(model.param_names)}"
                )
        flat = model.flat
        lo_decl, hi_decl = flat.bounds()
        lo, hi = (a.copy() for a in flat.bounds(bool(physical)))
        free = np.ones(lo.shape, bool)
        values = np.full(lo.shape, np.nan)
        slices = dict(flat.slices)
        for name, box in bounds.items():
            s = slices[name]
            if isinstance(box, str) or not hasattr(box, "__len__") or len(box) != 2:
                raise UsageError(f"bounds for {name!r}: expected (lower, upper), got {box!r}")
            # None keeps that side of the box as resolved so far (the physical one with physical=True)
            a = lo[s][0] if box[0] is None else _number(name, "lower bound", box[0])
            b = hi[s][0] if box[1] is None else _number(name, "upper bound", box[1])
            if a > b:
                raise UsageError(f"bounds for {name!r}: lower {a:g} is above upper {b:g}")
            if a < lo_decl[s][0] or b > hi_decl[s][0]:
                raise UsageError(
                    f"bounds for {name!r}: ({a:g}, {b:g}) leaves the range the formula allows, "
                    f"[{lo_decl[s][0]:g}, {hi_decl[s][0]:g}]"
                )
            lo[s], hi[s] = a, b
        for name, value in fixed.items():
            s = slices[name]
            n = s.stop - s.start
            arr = np.atleast_1d(np.asarray(value, dtype=object))
            if arr.ndim != 1 or arr.size not in (1, n):
                raise UsageError(f"fixed value for {name!r}: expected 1 or {n} numbers, got {value!r}")
            v = np.broadcast_to(np.asarray([_number(name, "fixed value", x) for x in arr]), (n,))
            a, b = (lo[s], hi[s]) if name in bounds else (lo_decl[s], hi_decl[s])
            if np.any(v < a) or np.any(v > b):
                raise UsageError(f"fixed value for {name!r}: {value!r} outside its bounds [{a[0]:g}, {b[0]:g}]")
            lo[s] = hi[s] = values[s] = v
            free[s] = False
        space = cls(model, lo, hi, free, values, (), bool(physical), frozenset(bounds), None, flat.linear)
        return dataclasses.replace(space, order=space._interchangeable_groups(), anchor=space.clip(flat.defaults))

    def _interchangeable_groups(self) -> tuple[tuple[Lobe, ...], ...]:
        slices = dict(self.model.flat.slices)
        by_kind: dict[str, list[Lobe]] = {}
        for lobe in self.model.lobes:
            by_kind.setdefault(lobe.kind, []).append(lobe)

        def signature(lobe: Lobe):
            parts = []
            for name in lobe.params:
                s = slices[name]
                parts.append((tuple(self.lo[s]), tuple(self.hi[s]), tuple(self.free[s]),
                              tuple(np.nan_to_num(self.values[s], nan=-7.77e300))))
            return tuple(parts)

        groups = []
        for lobes in by_kind.values():
            # Lobes of one kind with equal constraints form a group; others stay where they are.
            classes: dict[tuple, list[Lobe]] = {}
            for lobe in lobes:
                classes.setdefault(signature(lobe), []).append(lobe)
            groups += [tuple(c) for c in classes.values() if len(c) > 1]
        return tuple(groups)

    # -- vectors ------------------------------------------------------------------------------------
    @property
    def n_free(self) -> int:
        return int(self.free.sum())

    def in_unit(self, unit: float) -> "ParameterSpace":
        """This space for the table divided by ``unit`` (``problem.data_unit``): the linear parameters'
        bounds and fixed values divided by it, the rest unchanged."""
        if unit == 1.0:
            return self
        scale = np.where(self.linear, 1.0 / unit, 1.0)
        scaled = dataclasses.replace(self, lo=self.lo * scale, hi=self.hi * scale, values=self.values * scale)
        return dataclasses.replace(scaled, anchor=scaled.clip(self.anchor))

    def start(self, init) -> np.ndarray:
        """A flat start in this space from "defaults", a params dict (missing parameters take their
        defaults) or a flat vector (P,) in the model's order."""
        model = self.model
        if isinstance(init, str):
            if init != "defaults":
                raise UsageError(f"init must be None, 'defaults', a params dict or a FitResult, not {init!r}")
            return self.anchor.copy()
        if isinstance(init, Mapping):
            try:
                return self.clip(model.flatten({**model.defaults(), **init}))
            except ValueError as exc:
                raise UsageError(f"init: {exc}") from None
        v = np.asarray(init, np.float64).reshape(-1)
        if v.shape[0] != model.n_free:
            raise UsageError(f"starts have {v.shape[0]} values, model {model.name} has {model.n_free}")
        return self.clip(v)

    def clip(self, v) -> np.ndarray:
        """A flat vector moved into the box, fixed entries at their values."""
        v = np.clip(np.asarray(v, dtype=np.float64), self.lo, self.hi)
        return np.where(self.free, v, self.values)

    def canonical_rows(self, v: np.ndarray, jtj: np.ndarray | None = None):
        """Fits' results (rows of ``v`` (n, P), and their J^T J (n, P, P) or None) with fixed entries exactly at
        their values and the lobes of one kind narrowest first (a swap of whole interchangeable lobes: f_r and
        the loss are unchanged; J^T J follows the swap)."""
        v = self.clip(v)
        if not self.order:
            return v, jtj
        perms = np.stack([self.canonical_order(row) for row in v])
        v = np.take_along_axis(v, perms, axis=1)
        if jtj is not None:
            jtj = np.stack([h[np.ix_(p, p)] for h, p in zip(jtj, perms)])
        return v, jtj

    def canonical(self, v) -> np.ndarray:
        """``v`` (float64) with the lobes of every interchangeable group sorted narrowest first
        (whole lobes swapped: f_r is unchanged). Stable: lobes of equal width keep their order."""
        v = np.asarray(v, dtype=np.float64)
        return v[self.canonical_order(v)]

    def canonical_order(self, v) -> np.ndarray:
        """The permutation of flat entries that :meth:`canonical` applies: ``canonical(v) ==
        v[perm]`` (and J^T J of the canonical vector is ``H[perm][:, perm]``)."""
        v = np.asarray(v, dtype=np.float64)
        perm = np.arange(v.shape[0])
        if not self.order:
            return perm
        slices = dict(self.model.flat.slices)
        params = {name: v[s] for name, s in slices.items()}
        source_perm = perm.copy()
        for group in self.order:
            blocks = [np.concatenate([source_perm[slices[q]] for q in lobe.params]) for lobe in group]
            widths = [lobe_width(self.model, lobe, params) for lobe in group]
            ranked = sorted(range(len(group)), key=lambda i: widths[i])
            for target, source in zip(group, ranked):
                i = 0
                for q in target.params:
                    n = slices[q].stop - slices[q].start
                    perm[slices[q]] = blocks[source][i : i + n]
                    i += n
        return perm

    def at_bound(self, v, data_scale: float | None = None) -> dict[str, str]:
        """Free parameters of ``v`` on a finite bound of this space: name -> "lower", "upper", or
        per channel ("lower in channel 0", "upper in channels 1, 2") where only some are.

        ``data_scale``: the mean |value| of the fitted data. A scale (linear parameter) with an open
        side carries the unit of the data, so its tolerance is taken relative to it (docs/fitting.md#hostile-but-valid-data: data
        x 1e-12 gave "kd 2e-13 ended on its lower bound 0" for a kd recovered exactly); without it,
        relative to the physical range as for every other parameter."""
        v = np.asarray(v, dtype=np.float64)
        span = _span(self.model, self.lo, self.hi)
        if data_scale is not None and data_scale > 0 and np.isfinite(data_scale):
            for p, (name, sl) in zip(self.model.params, self.model.flat.slices):
                if p.linear and not (np.isfinite(self.lo[sl]).all() and np.isfinite(self.hi[sl]).all()):
                    span[sl] = span[sl] * data_scale
        tol = AT_BOUND_RTOL * span
        on_lo = self.free & np.isfinite(self.lo) & (v <= self.lo + tol)
        on_hi = self.free & np.isfinite(self.hi) & (v >= self.hi - tol) & ~on_lo
        out = {}
        for name, s in self.model.flat.slices:
            lo_c, hi_c = np.flatnonzero(on_lo[s]), np.flatnonzero(on_hi[s])
            n = s.stop - s.start
            parts = []
            for side, idx in (("lower", lo_c), ("upper", hi_c)):
                if idx.size == n:
                    parts.append(side)
                elif idx.size:
                    word = "channel" if idx.size == 1 else "channels"
                    parts.append(f"{side} in {word} {', '.join(str(i) for i in idx)}")
            if parts:
                out[name] = "; ".join(parts)
        return out

    def scales_on_bounds(self, v) -> np.ndarray:
        """(n,) bool, rows ``v`` (n, P): every free scale (linear entry; every free entry where no scale is
        free) within AT_BOUND_RTOL of its span of a bound. False where nothing is free."""
        v = np.atleast_2d(np.asarray(v, dtype=np.float64))
        scales = self.free & self.linear
        scales = scales if scales.any() else self.free
        tol = AT_BOUND_RTOL * _span(self.model, self.lo, self.hi)
        on = (v <= self.lo + tol) | (v >= self.hi - tol)
        return np.all(on | ~scales, axis=1) & scales.any()

    def unseen_lobes(self, v, spacing: float | None) -> dict[tuple[str, ...], np.ndarray]:
        """lobe (``Model.lobes``: its parameter names) -> (n,) bool: the fits (rows of ``v`` (n, P)) whose lobe
        the data do not see, among lobes with free nonlinear parameters: every scale (linear parameter) on its
        lower bound 0 (the lobe is off, so its shape has no effect on the loss and a solver stopped there
        never tried it: lambert+ggx+ggx on an RGL paper stopped at ggx's own loss with ggx1.ks 0), or a needle
        (full width at half maximum below ``NEEDLE_FRACTION`` of the sample ``spacing``: a held-out yellow
        paint's ggx fit ended at alpha 1.2e-4, ks 3.5e-5, where alpha 0.0148, ks 0.5 fits better and shows its
        highlight). Where the fit driver tries them again (``driver.solve``)."""
        m = self.model
        v = np.asarray(v, dtype=np.float64).reshape(-1, m.n_free)
        slices = dict(m.flat.slices)
        widths = dict(lobe_halfwidths(m, v)) if spacing is not None else {}
        out = {}
        for lobe in m.lobes:
            scales = [slices[n] for n in lobe.params if m.flat.linear[slices[n]].all()]
            shapes = [slices[n] for n in lobe.params if not m.flat.linear[slices[n]].any()]
            if not scales or not any(self.free[s].any() for s in shapes):
                continue
            off = np.ones(len(v), bool)
            for s in scales:
                off &= np.all((v[:, s] <= self.lo[s]) & (self.lo[s] == 0.0), axis=1)
            # full width (twice the half width) against the spacing
            needle = 2.0 * widths[lobe] < NEEDLE_FRACTION * spacing if lobe in widths else np.zeros(len(v), bool)
            if (off | needle).any():
                out[tuple(lobe.params)] = off | needle
        return out

    def bound_origin(self, name: str, side: str) -> str:
        """Where a parameter's lower or upper bound comes from, for messages."""
        if name in self.overridden:
            return "set by bounds="
        p = self.model.param(name)
        declared = p.lower if side == "lower" else p.upper
        if self.physical and self.describe_bound(name, side) != declared:
            return "its physical range; fit without physical=True to allow more"
        return "the formula's limit"

    def describe_bound(self, name: str, side: str) -> float:
        s = dict(self.model.flat.slices)[name]
        return float((self.lo if side == "lower" else self.hi)[s][0])


# -- warnings (docs/fitting.md#fitting: one sentence each) ------------------------------------------------------------
def parameter_space(model: Model, bounds=None, fixed=None, physical: bool = False) -> ParameterSpace:
    """Where a fit of ``model`` may move: flat ``lo``/``hi`` (may be infinite) and ``free`` mask, the
    runtime arguments of the start grid and of every solver."""
    if not bounds and not fixed:
        return _default_space(model, bool(physical))
    return ParameterSpace.build(model, bounds, fixed, physical)


@functools.lru_cache(maxsize=64)
def _default_space(model: Model, physical: bool) -> ParameterSpace:
    """The space of a fit without overrides, built once per model (its arrays are read-only)."""
    space = ParameterSpace.build(model, None, None, physical)
    for a in (space.lo, space.hi, space.free, space.values):
        a.flags.writeable = False
    return space


def sample_spacing(wo, max_directions: int = 2048) -> float:
    """Typical angular spacing (radians) of the distinct view directions ``wo`` (N, 3): the median
    angle from each to its nearest neighbour. 14.5 degrees on the UBO-81 grid (theta rings 15
    degrees apart, azimuth steps of 14.5 to 18 degrees of arc on the outer rings). Beyond
    ``max_directions`` distinct directions a fixed random subset is used (an upper estimate).

    Every fit asks this (for its warnings), and a batch or a BTF asks it of the same directions
    for every texel: the result is kept per distinct direction set."""
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    return _sample_spacing(wo.tobytes(), wo.shape, max_directions)


@functools.lru_cache(maxsize=8)
def _sample_spacing(wo_bytes: bytes, shape: tuple[int, ...], max_directions: int) -> float:
    w = np.unique(np.round(np.frombuffer(wo_bytes, dtype=np.float64).reshape(shape), 9), axis=0)
    w = w[w[:, 2] > 0]
    if len(w) < 2:
        return math.pi / 2
    if len(w) > max_directions:
        w = w[np.random.default_rng(0).choice(len(w), max_directions, replace=False)]
    cos = np.clip(w @ w.T, -1.0, 1.0)
    np.fill_diagonal(cos, -1.0)
    return float(np.median(np.arccos(cos.max(axis=1))))


def lobe_halfwidths(model: Model, v) -> list[tuple[Lobe, float | np.ndarray]]:
    """(lobe, half width at half maximum in radians) for every lobe whose kind declares one: a float for a
    flat vector ``v`` (P,), an array (n,) for rows (n, P) (every fit at once: the kinds' widths take arrays)."""
    from ..models import get

    v = np.asarray(v, dtype=np.float64)
    rows = v.reshape(-1, v.shape[-1])
    params = {name: rows[:, s.start] for name, s in model.flat.slices}  # a lobe's shape: one value per fit
    out = []
    for lobe in model.lobes:
        try:
            base = get(lobe.kind)
        except KeyError:
            continue
        if base.halfwidth is None or not base.lobes:
            continue
        own = dict(zip(base.lobes[0].params, (params[q] for q in lobe.params)))
        width = np.broadcast_to(np.asarray(base.halfwidth(own), np.float64), (len(rows),))
        out.append((lobe, float(width[0]) if v.ndim == 1 else width))
    return out


def _lobe_label(lobe: Lobe) -> str:
    prefix = lobe.params[0].rsplit(".", 1)[0] if "." in lobe.params[0] else ""
    return f"lobe {prefix}" if prefix else f"the {lobe.kind} lobe"


def _bound_sentence(space: ParameterSpace, name: str, sides: str) -> str:
    """The warning of one ``at_bound`` entry ("lower", "upper in channel 0", "lower in channel 2;
    upper in channel 0", see :meth:`ParameterSpace.at_bound`), a clause per side:
    "kd ended on its lower bound 0 in channel 2 (the formula's limit) and on its upper bound 1 in
    channel 0 (set by bounds=)."."""
    clauses = []
    for part in sides.split("; "):
        side, _, channels = part.partition(" in ")
        where = f" in {channels}" if channels else ""
        clauses.append(f"its {side} bound {space.describe_bound(name, side):g}{where} ({space.bound_origin(name, side)})")
    return f"{name} ended on " + " and on ".join(clauses) + "."


def fit_warnings(space: ParameterSpace, v, at_bound: Mapping[str, str], stderr: Mapping[str, object],
                 spacing: float | None) -> list[str]:
    """One sentence per problem of a fitted vector ``v``:

    * a parameter on a bound (``at_bound``): the data pull it beyond, the constraint decides;
    * a lobe narrower than the sample spacing: its full width at half maximum in reflected
      directions (2 x ``Model.halfwidth``) below ``spacing``, so the lobe can fall between samples
      and only its peak's product with the scale (e.g. ks / alpha^2 for GGX) is measured; on the
      UBO-81 grid (14.5 degrees) that is GGX alpha < 0.098, Beckmann alpha < 0.076, Phong n > 86;
    * a free parameter with no standard error that is not on a bound: the data do not determine
      it (a near-null direction of J'J, see ``brdffit.fitting.measurements.standard_errors``).
    """
    out = [_bound_sentence(space, name, sides) for name, sides in at_bound.items()]
    if spacing is not None:
        for lobe, hw in lobe_halfwidths(space.model, v):
            if 2.0 * hw < spacing:
                out.append(
                    f"{_lobe_label(lobe)} is narrower than the sample spacing (width {math.degrees(2 * hw):.2g} degrees "
                    f"at half maximum, samples {math.degrees(spacing):.3g} degrees apart): the samples see "
                    "little more than its peak, so its width and scale are poorly determined."
                )
    free_names = {name for name, s in space.model.flat.slices if space.free[s].any()}
    for name in space.model.param_names:
        if name in free_names and name not in at_bound and name in stderr and stderr[name] is None:
            out.append(f"{name} is not determined by the data (it trades off against other parameters; no standard error).")
    return out
