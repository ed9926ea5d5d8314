"""One definition, two tracers: a model's JAX formula evaluated in Dr.Jit (SPEC 8, issue 27).

The ``brdffit`` plugin must render a fit in any Mitsuba scene, also where Dr.Jit records calls
symbolically (Mitsuba's default) and there is no way back to Python or JAX per lane. Rather than a
second copy of every formula in Dr.Jit (which could drift from the fitted one), the formula is
traced once by JAX (``jax.make_jaxpr`` of ``model.eval``) and its program -- a few dozen element-wise
primitives -- is *interpreted* with Dr.Jit arrays: the same definition, run by a second tracer.

How values are carried. JAX traces the formula on ``LANES`` direction pairs; an array whose leading
axis is that lane axis (derived from the directions) is a *lane* value, held as a NumPy object
array of its remaining shape whose cells are Dr.Jit ``Float``s (one per cell, each as wide as the
rays Mitsuba evaluates). Other values (parameters and constants) have no lane axis: cells are
Dr.Jit values of width 1 (the parameters, so that Mitsuba's ``prb`` can differentiate them) or
Python floats. JAX's element-wise primitives then act cell by cell; shape primitives (slice,
broadcast, reshape, reduce_sum, concatenate) rearrange cells. A formula that uses a primitive not
listed in ``_UNARY``/``_BINARY``/``_SHAPE`` raises ``Unsupported`` when the plugin is made, and
the plugin falls back to the evaluated-call path (which needs ``brdffit.evaluated_calls()``).

The program is traced in float32 (what Mitsuba computes in), so float32-dependent constants of the
formulas (``_math.log_cap``) take their single-precision values.
"""

from __future__ import annotations

import functools
import math
import operator

import numpy as np

#: Length of the lane axis JAX traces with: a prime no parameter or channel count equals.
LANES = 7


class Unsupported(Exception):
    """The formula uses a JAX primitive this interpreter does not translate."""


class _Value:
    __slots__ = ("cells", "lane")

    def __init__(self, cells: np.ndarray, lane: bool):
        self.cells = cells
        self.lane = lane


def _obj(shape) -> np.ndarray:
    return np.empty(shape, dtype=object)


def _is_num(x) -> bool:
    return isinstance(x, (int, float, bool, np.number, np.bool_))


def _dr():
    import drjit as dr

    return dr


def _select(c, a, b):
    if _is_num(c):
        return a if c else b
    return _dr().select(c, a, b)


def _fn(name, numeric):
    """An element function: ``numeric`` on Python numbers, Dr.Jit's ``name`` otherwise."""

    def f(*args):
        if all(_is_num(a) for a in args):
            return numeric(*args)
        return getattr(_dr(), name)(*args)

    return f


def _ipow(x, y: int):
    if y == 0:
        return 1.0
    out = x
    for _ in range(abs(y) - 1):
        out = out * x
    return 1.0 / out if y < 0 else out


def _to_float(x):
    if _is_num(x):
        return float(x)
    dr = _dr()
    if dr.is_mask_v(x):
        return dr.select(x, 1.0, 0.0)
    return x


_UNARY = {
    "neg": operator.neg,
    "abs": _fn("abs", abs),
    "sqrt": _fn("sqrt", math.sqrt),
    "rsqrt": _fn("rsqrt", lambda x: 1.0 / math.sqrt(x)),
    "exp": _fn("exp", math.exp),
    "log": _fn("log", math.log),
    "sin": _fn("sin", math.sin),
    "cos": _fn("cos", math.cos),
    "tan": _fn("tan", math.tan),
    "floor": _fn("floor", math.floor),
    "ceil": _fn("ceil", math.ceil),
    "log1p": lambda x: _UNARY["log"](1.0 + x),
    "expm1": lambda x: _UNARY["exp"](x) - 1.0,
    "logistic": lambda x: 1.0 / (1.0 + _UNARY["exp"](-x)),
    "not": lambda x: (not x) if _is_num(x) else ~x,
    "sign": lambda x: _select(x > 0, 1.0, _select(x < 0, -1.0, 0.0)),
    "stop_gradient": lambda x: x,
}

_BINARY = {
    "add": operator.add,
    "sub": operator.sub,
    "mul": operator.mul,
    "div": operator.truediv,
    "pow": _fn("power", math.pow),
    "max": _fn("maximum", max),
    "min": _fn("minimum", min),
    "atan2": _fn("atan2", math.atan2),
    "gt": operator.gt,
    "ge": operator.ge,
    "lt": operator.lt,
    "le": operator.le,
    "eq": operator.eq,
    "ne": operator.ne,
    "and": operator.and_,
    "or": operator.or_,
}


def _map(fn, *arrays: np.ndarray) -> np.ndarray:
    assert all(isinstance(a, np.ndarray) for a in arrays)  # never a bare Dr.Jit cell (see _reduce)
    arrays = np.broadcast_arrays(*arrays)
    out = _obj(arrays[0].shape)
    for idx in np.ndindex(out.shape):
        out[idx] = fn(*(a[idx] for a in arrays))
    return out


def _elementwise(fn, vals: list[_Value]) -> _Value:
    lane = any(v.lane for v in vals)
    rank = max((v.cells.ndim + 1 for v in vals if v.lane), default=0)
    cells = []
    for v in vals:
        c = v.cells
        if lane and not v.lane and c.ndim == rank and rank > 0:
            # a non-lane operand of full rank has a leading axis of size 1 (JAX broadcasts size-1
            # axes in element-wise primitives) or of the lane length but constant: one row serves all
            c = c[0:1].reshape(c.shape[1:])  # slicing keeps an object array (c[0] could be a bare cell)
        cells.append(c)
    return _Value(_map(fn, *cells), lane)


def _broadcast_in_dim(v: _Value, shape, broadcast_dimensions) -> _Value:
    shape, dims = tuple(shape), tuple(broadcast_dimensions)
    cells = v.cells
    if v.lane:  # the lane axis maps to output axis 0 and stays the lane axis
        if not dims or dims[0] != 0:
            raise Unsupported("broadcast moving the lane axis")
        src_dims, out_shape, cells_dims = dims[1:], shape[1:], [d - 1 for d in dims[1:]]
        lane = True
    elif shape and shape[0] == LANES and (0 not in dims or cells.shape[dims.index(0)] == 1):
        lane = True  # broadcast across the lanes: drop the (size-1 or new) axis 0
        if 0 in dims:
            k = dims.index(0)
            cells = cells.reshape(cells.shape[:k] + cells.shape[k + 1:])
            src_dims = dims[:k] + dims[k + 1:]
        else:
            src_dims = dims
        out_shape, cells_dims = shape[1:], [d - 1 for d in src_dims]
    else:
        lane, out_shape, cells_dims = False, shape, list(dims)
    new = [1] * len(out_shape)
    for i, d in enumerate(cells_dims):
        new[d] = cells.shape[i]
    cells = np.broadcast_to(cells.reshape(new), out_shape)
    return _Value(np.array(cells, dtype=object), lane)


def _axes(v: _Value, axes) -> tuple[int, ...]:
    if v.lane:
        if 0 in axes:
            raise Unsupported("reduction over the lane axis")
        return tuple(a - 1 for a in axes)
    return tuple(axes)


def _reduce(v: _Value, axes, fn) -> _Value:
    cells = v.cells
    for a in sorted(_axes(v, axes), reverse=True):
        rest = cells.shape[:a] + cells.shape[a + 1:]
        # take [i] and reshape: a bare Dr.Jit cell must never reach NumPy (it would evaluate it)
        parts = [np.take(cells, [i], axis=a).reshape(rest) for i in range(cells.shape[a])]
        acc = parts[0]
        for p in parts[1:]:
            acc = _map(fn, acc, p)
        cells = np.asarray(acc, dtype=object).reshape(acc.shape)
    return _Value(cells, v.lane)


def _slice(v: _Value, start, limit, strides) -> _Value:
    strides = strides or (1,) * len(start)
    index = tuple(slice(a, b, s) for a, b, s in zip(start, limit, strides))
    return _Value(v.cells[index[1:]] if v.lane else v.cells[index], v.lane)


def _reshape(v: _Value, new_sizes) -> _Value:
    new_sizes = tuple(new_sizes)
    if v.lane:
        if not new_sizes or new_sizes[0] != LANES:
            raise Unsupported("reshape mixing the lane axis")
        return _Value(v.cells.reshape(new_sizes[1:]), True)
    return _Value(v.cells.reshape(new_sizes), False)


def _concatenate(vals: list[_Value], dimension: int) -> _Value:
    lane = any(v.lane for v in vals)
    if lane:
        if dimension == 0:
            raise Unsupported("concatenation along the lane axis")
        if not all(v.lane for v in vals):
            raise Unsupported("concatenating lane and non-lane arrays")
        return _Value(np.concatenate([v.cells for v in vals], axis=dimension - 1), True)
    return _Value(np.concatenate([v.cells for v in vals], axis=dimension), False)


def _const(x) -> _Value:
    a = np.asarray(x)
    cells = _obj(a.shape)
    for idx in np.ndindex(a.shape):
        cells[idx] = a[idx].item()
    return _Value(cells, False)


def _run(jaxpr, consts, args: list[_Value]) -> list[_Value]:
    from jax.extend.core import Literal

    env = {}

    def read(var):
        if isinstance(var, Literal):
            return _const(var.val)
        return env[var]

    for var, c in zip(jaxpr.constvars, consts):
        env[var] = _const(c)
    for var, a in zip(jaxpr.invars, args):
        env[var] = a
    for eqn in jaxpr.eqns:
        name, params = eqn.primitive.name, eqn.params
        ins = [read(v) for v in eqn.invars]
        if name in _BINARY:
            out = [_elementwise(_BINARY[name], ins)]
        elif name in _UNARY:
            out = [_elementwise(_UNARY[name], ins)]
        elif name == "integer_pow":
            out = [_elementwise(lambda x, y=params["y"]: _ipow(x, y), ins)]
        elif name == "square":
            out = [_elementwise(lambda x: x * x, ins)]
        elif name == "convert_element_type":
            to_bool = np.dtype(params["new_dtype"]) == np.bool_
            out = [ins[0] if to_bool else _elementwise(_to_float, ins)]
        elif name == "select_n":
            if len(ins) != 3:
                raise Unsupported("select_n with more than two cases")
            out = [_elementwise(lambda c, a, b: _select(c, b, a), ins)]
        elif name == "clamp":
            lo, x, hi = ins
            out = [_elementwise(lambda a, x_, b: _BINARY["min"](_BINARY["max"](x_, a), b), [lo, x, hi])]
        elif name == "broadcast_in_dim":
            out = [_broadcast_in_dim(ins[0], params["shape"], params["broadcast_dimensions"])]
        elif name == "slice":
            out = [_slice(ins[0], params["start_indices"], params["limit_indices"], params["strides"])]
        elif name == "reshape":
            out = [_reshape(ins[0], params["new_sizes"])]
        elif name == "squeeze":
            shape = [s for i, s in enumerate(eqn.invars[0].aval.shape) if i not in params["dimensions"]]
            out = [_reshape(ins[0], shape)]
        elif name == "reduce_sum":
            out = [_reduce(ins[0], params["axes"], operator.add)]
        elif name == "reduce_max":
            out = [_reduce(ins[0], params["axes"], _BINARY["max"])]
        elif name == "reduce_min":
            out = [_reduce(ins[0], params["axes"], _BINARY["min"])]
        elif name == "concatenate":
            out = [_concatenate(ins, params["dimension"])]
        elif name in ("pjit", "jit", "closed_call", "core_call", "remat", "checkpoint"):
            sub = params.get("jaxpr") or params.get("call_jaxpr")
            out = _run(sub.jaxpr, sub.consts, ins) if hasattr(sub, "consts") else _run(sub, [], ins)
        elif name in ("custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr"):
            sub = params.get("call_jaxpr") or params.get("fun_jaxpr")
            out = _run(sub.jaxpr, sub.consts, ins)
        else:
            raise Unsupported(f"JAX primitive {name!r}")
        for var, val in zip(eqn.outvars, out):
            shape = tuple(var.aval.shape)
            if val.cells.shape != (shape[1:] if val.lane else shape):  # the lane bookkeeping went astray
                raise Unsupported(f"{name}: cannot follow the lane axis through shape {shape}")
            env[var] = val
    return [read(v) for v in jaxpr.outvars]


class DrjitFormula:
    """``model.eval`` as a function of Dr.Jit arrays: ``__call__(params, wi, wo)`` with ``params``
    mapping each parameter name to a list of Dr.Jit/Python values (its ``size``), ``wi``/``wo``
    triples of Dr.Jit Floats (the light and the view, SPEC 1), returns the ``channels`` values of f_r.
    Raises ``Unsupported`` on construction where the formula cannot be translated."""

    def __init__(self, model):
        import jax
        import jax.numpy as jnp

        self.model = model
        params = {p.name: jnp.full((model.size(p),), p.default, jnp.float32) for p in model.params}
        leaves, self._treedef = jax.tree_util.tree_flatten(params)
        self._order = [k for k in sorted(params)]  # a dict's pytree leaves come in sorted key order
        if len(leaves) != len(self._order):
            raise Unsupported("unexpected parameter structure")
        pole = jnp.tile(jnp.asarray([[0.1, 0.2, 0.97]], jnp.float32), (LANES, 1))
        closed = jax.make_jaxpr(model.eval)(params, pole, pole)
        self._jaxpr = closed.jaxpr
        self._consts = closed.consts
        # a dry run with plain numbers: every primitive must be one this module translates
        self(
            {p.name: [p.default] * model.size(p) for p in model.params},
            (0.1, 0.2, 0.97), (0.3, -0.1, 0.95),
        )

    def __call__(self, params, wi, wo) -> list:
        args = []
        for name in self._order:
            cells = _obj((len(params[name]),))
            for i, v in enumerate(params[name]):
                cells[i] = v
            args.append(_Value(cells, False))
        for w in (wi, wo):
            cells = _obj((3,))
            for i in range(3):
                cells[i] = w[i]
            args.append(_Value(cells, True))
        (out,) = _run(self._jaxpr, self._consts, args)
        if not out.lane or out.cells.shape != (self.model.channels,):
            raise Unsupported(f"formula output of shape {out.cells.shape} (lane {out.lane})")
        return list(out.cells)


@functools.lru_cache(maxsize=None)
def drjit_formula(model) -> DrjitFormula:
    """The translated formula of ``model`` (once per model and process)."""
    return DrjitFormula(model)
