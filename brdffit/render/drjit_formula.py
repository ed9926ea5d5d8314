"""One definition, two tracers: a model's JAX formula as straight-line code for Dr.Jit or Python floats (docs/materials.md#a-fit-in-any-mitsuba-scene).

The ``brdffit`` plugin must render a fit in any Mitsuba scene and variant: where Dr.Jit records calls
symbolically (the JIT variants' default: no way back to Python or JAX per lane) and where Mitsuba calls
the BSDF once per ray with plain numbers (the scalar variants). Rather than a second copy of every
formula (which could drift from the fitted one), the formula is traced once by JAX (``jax.make_jaxpr``
of ``model.eval``) and its program -- a few dozen to a few hundred element-wise primitives -- is
*translated* into the source of one Python function of scalar cells: the same definition, written out
for a second tracer. Two back ends read that program:

- ``jit``: each cell is a Dr.Jit array (a ray per lane), operations are Dr.Jit's; traced by Dr.Jit
  into Mitsuba's kernel, at Mitsuba's own speed, differentiable by ``prb``.
- ``scalar``: each cell is a Python float and operations are inline Python arithmetic and ``math``:
  no interpreter, no NumPy per call (the scalar variants call it for every ray). Where Python raises
  instead of returning inf/NaN (a division by zero, ``math.sqrt`` of a negative), the call is
  repeated with NumPy's IEEE semantics.

How values are carried. JAX traces the formula on ``LANES`` direction pairs; an array whose leading
axis is that lane axis (derived from the directions) is a *lane* value, held as a NumPy object array of
its remaining shape whose cells are the generated program's variables (:class:`Var`). Other values
(parameters and constants) have no lane axis; constants are Python numbers, folded while translating.
JAX's element-wise primitives act cell by cell, shape primitives (slice, broadcast, reshape, reduce,
concatenate) rearrange cells, and ``gather`` from a constant table (Cycles' lookup tables) becomes an
indexed read of that table. A primitive not listed here raises ``Unsupported`` when the formula is
translated. The formula is traced for the channel count of the variant (3 RGB, 4 wavelengths, 1 mono):
formulas are channel-separable (``Model``'s contract), so the same program serves every variant.

The program is traced in float32 (what Mitsuba computes in), so float32-dependent constants of the
formulas (``_math.log_cap``) take their single-precision values.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .formula_ops import ELEMENTWISE, Var, fold, literal, scalar_namespaces

#: Length of the lane axis JAX traces with: a prime no parameter or channel count equals.
LANES = 7


class Unsupported(Exception):
    """The formula uses a JAX primitive this translation does not cover."""


class _Value:
    __slots__ = ("cells", "lane")

    def __init__(self, cells: np.ndarray, lane: bool):
        self.cells = cells
        self.lane = lane


def _obj(shape) -> np.ndarray:
    return np.empty(shape, dtype=object)


def _vars(names: list[str]) -> np.ndarray:
    out = _obj((len(names),))
    for i, name in enumerate(names):
        out[i] = Var(name, "f")
    return out


class _Writer:
    """The generated program: ``name = expression`` lines, constants folded, repeated expressions
    written once, and (at the end) lines no output depends on left out."""

    def __init__(self, backend: str):
        self.backend = backend
        self.lines: list[tuple[str, str, tuple[str, ...]]] = []
        self._memo: dict[str, Var] = {}
        self.tables: list[np.ndarray] = []

    def op(self, name: str, *args, **params):
        if all(not isinstance(a, Var) for a in args):  # constants: folded with the scalar semantics
            return fold(*ELEMENTWISE[name]("scalar", *args, **params), args)
        template, kind = ELEMENTWISE[name](self.backend, *args, **params)
        if template == "{0}":
            return args[0]
        expr = template.format(*(literal(a) for a in args))
        if expr in self._memo:
            return self._memo[expr]
        var = Var(f"v{len(self.lines)}", kind)
        self.lines.append((var.name, expr, tuple(a.name for a in args if isinstance(a, Var))))
        self._memo[expr] = var
        return var

    def gather(self, table: np.ndarray, flat_index):
        if not isinstance(flat_index, Var):
            return float(table.reshape(-1)[int(flat_index)])
        self.tables.append(np.asarray(table, np.float32).reshape(-1))
        name = f"T{len(self.tables) - 1}"
        expr = f"{name}[{flat_index.name}]" if self.backend == "scalar" else f"gather({name}, {flat_index.name})"
        var = Var(f"v{len(self.lines)}", "f")
        self.lines.append((var.name, expr, (flat_index.name,)))
        return var

    def source(self, args: list[str], outputs: list) -> str:
        used = {o.name for o in outputs if isinstance(o, Var)}
        kept = []
        for name, expr, deps in reversed(self.lines):
            if name in used:
                kept.append(f"    {name} = {expr}")
                used.update(deps)
        body = list(reversed(kept)) + ["    return (" + "".join(literal(o) + ", " for o in outputs) + ")"]
        return "def formula(" + ", ".join(args) + "):\n" + "\n".join(body) + "\n"


def _elementwise(w: _Writer, fn, vals: list[_Value]) -> _Value:
    lane = any(v.lane for v in vals)
    rank = max((v.cells.ndim + 1 for v in vals if v.lane), default=0)
    cells = []
    for v in vals:
        c = v.cells
        if lane and not v.lane and c.ndim == rank and rank > 0:
            # a non-lane operand of full rank has a leading axis of size 1 (JAX broadcasts size-1
            # axes in element-wise primitives) or of the lane length but constant: one row serves all
            c = c[0:1].reshape(c.shape[1:])
        cells.append(c)
    arrays = np.broadcast_arrays(*cells)
    out = _obj(arrays[0].shape)
    for idx in np.ndindex(out.shape):
        out[idx] = fn(*(a[idx] for a in arrays))
    return _Value(out, lane)


def _broadcast_in_dim(v: _Value, shape, broadcast_dimensions) -> _Value:
    shape, dims = tuple(shape), tuple(broadcast_dimensions)
    cells = v.cells
    if v.lane:  # the lane axis maps to output axis 0 and stays the lane axis
        if not dims or dims[0] != 0:
            raise Unsupported("broadcast moving the lane axis")
        out_shape, cells_dims = shape[1:], [d - 1 for d in dims[1:]]
        lane = True
    elif shape and shape[0] == LANES and (0 not in dims or cells.shape[dims.index(0)] == 1):
        lane = True  # broadcast across the lanes: drop the (size-1 or new) axis 0
        src_dims = dims
        if 0 in dims:
            k = dims.index(0)
            cells = cells.reshape(cells.shape[:k] + cells.shape[k + 1:])
            src_dims = dims[:k] + dims[k + 1:]
        out_shape, cells_dims = shape[1:], [d - 1 for d in src_dims]
    else:
        lane, out_shape, cells_dims = False, shape, list(dims)
    new = [1] * len(out_shape)
    for i, d in enumerate(cells_dims):
        new[d] = cells.shape[i]
    return _Value(np.array(np.broadcast_to(cells.reshape(new), out_shape), dtype=object), lane)


def _reduce(w: _Writer, v: _Value, axes, op: str) -> _Value:
    if v.lane and 0 in axes:
        raise Unsupported("reduction over the lane axis")
    cells = v.cells
    for a in sorted((x - 1 for x in axes) if v.lane else axes, reverse=True):
        rest = cells.shape[:a] + cells.shape[a + 1:]
        parts = [np.take(cells, [i], axis=a).reshape(rest) for i in range(cells.shape[a])]
        acc = parts[0]
        for p in parts[1:]:
            acc = _elementwise(w, lambda x, y: w.op(op, x, y), [_Value(acc, False), _Value(p, False)]).cells
        cells = acc
    return _Value(cells, v.lane)


def _reshape(v: _Value, new_sizes) -> _Value:
    new_sizes = tuple(new_sizes)
    if v.lane:
        if not new_sizes or new_sizes[0] != LANES:
            raise Unsupported("reshape mixing the lane axis")
        return _Value(v.cells.reshape(new_sizes[1:]), True)
    return _Value(v.cells.reshape(new_sizes), False)


def _concatenate(vals: list[_Value], dimension: int) -> _Value:
    if any(v.lane for v in vals):
        if dimension == 0 or not all(v.lane for v in vals):
            raise Unsupported("concatenation along or across the lane axis")
        return _Value(np.concatenate([v.cells for v in vals], axis=dimension - 1), True)
    return _Value(np.concatenate([v.cells for v in vals], axis=dimension), False)


def _gather(w: _Writer, operand: _Value, indices: _Value, params) -> _Value:
    """A point gather (``table[i, j, k]`` with integer arrays) from a constant table."""
    dn = params["dimension_numbers"]
    table = operand.cells
    if operand.lane or any(isinstance(c, Var) for c in table.reshape(-1)):
        raise Unsupported("gather from an array that depends on the parameters or the directions")
    k = table.ndim
    if (dn.offset_dims or tuple(dn.collapsed_slice_dims) != tuple(range(k)) or tuple(dn.start_index_map) != tuple(range(k))
            or tuple(params["slice_sizes"]) != (1,) * k or indices.cells.shape[-1] != k):
        raise Unsupported("gather other than a point lookup")
    values = np.asarray(table.astype(np.float64))
    strides = [int(np.prod(table.shape[i + 1:])) for i in range(k)]
    out = _obj(indices.cells.shape[:-1])
    for idx in np.ndindex(out.shape):
        flat = 0
        for i in range(k):
            j = w.op("min", w.op("max", indices.cells[idx + (i,)], 0), table.shape[i] - 1)  # JAX clamps, so do we
            flat = w.op("add", flat, w.op("mul", j, strides[i])) if i else w.op("mul", j, strides[i])
        out[idx] = w.gather(values, flat)
    return _Value(out, indices.lane)


def _const(x) -> _Value:
    a = np.asarray(x)
    cells = _obj(a.shape)
    for idx in np.ndindex(a.shape):
        cells[idx] = a[idx].item()
    return _Value(cells, False)


_CALLS = ("pjit", "jit", "closed_call", "core_call", "remat", "checkpoint", "custom_jvp_call", "custom_vjp_call",
          "custom_vjp_call_jaxpr")


def _run(w: _Writer, jaxpr, consts, args: list[_Value]) -> list[_Value]:
    from jax.extend.core import Literal

    env = {}

    def read(var):
        return _const(var.val) if isinstance(var, Literal) else env[var]

    for var, c in zip(jaxpr.constvars, consts):
        env[var] = _const(c)
    for var, a in zip(jaxpr.invars, args):
        env[var] = a
    for eqn in jaxpr.eqns:
        name, params = eqn.primitive.name, eqn.params
        ins = [read(v) for v in eqn.invars]
        if name in ELEMENTWISE:
            extra = {"y": params["y"]} if name == "integer_pow" else {}
            out = [_elementwise(w, lambda *a, n=name, e=extra: w.op(n, *a, **e), ins)]
        elif name == "convert_element_type":
            kind = "b" if np.dtype(params["new_dtype"]) == np.bool_ else (
                "i" if np.issubdtype(np.dtype(params["new_dtype"]), np.integer) else "f")
            out = [_elementwise(w, lambda a, k=kind: w.op("convert", a, to=k), ins)]
        elif name == "clamp":
            out = [_elementwise(w, lambda lo, x, hi: w.op("min", w.op("max", x, lo), hi), ins)]
        elif name == "select_n":
            if len(ins) != 3:
                raise Unsupported("select_n with more than two cases")
            out = [_elementwise(w, lambda c, a, b: w.op("select", c, b, a), ins)]
        elif name == "broadcast_in_dim":
            out = [_broadcast_in_dim(ins[0], params["shape"], params["broadcast_dimensions"])]
        elif name == "slice":
            strides = params["strides"] or (1,) * len(params["start_indices"])
            index = tuple(slice(a, b, s) for a, b, s in zip(params["start_indices"], params["limit_indices"], strides))
            out = [_Value(ins[0].cells[index[1:]] if ins[0].lane else ins[0].cells[index], ins[0].lane)]
        elif name == "reshape":
            out = [_reshape(ins[0], params["new_sizes"])]
        elif name == "squeeze":
            shape = [s for i, s in enumerate(eqn.invars[0].aval.shape) if i not in params["dimensions"]]
            out = [_reshape(ins[0], shape)]
        elif name in ("reduce_sum", "reduce_max", "reduce_min"):
            out = [_reduce(w, ins[0], params["axes"], {"reduce_sum": "add", "reduce_max": "max", "reduce_min": "min"}[name])]
        elif name == "concatenate":
            out = [_concatenate(ins, params["dimension"])]
        elif name == "gather":
            out = [_gather(w, ins[0], ins[1], params)]
        elif name in _CALLS:
            sub = params.get("jaxpr") or params.get("call_jaxpr") or params.get("fun_jaxpr")
            out = _run(w, sub.jaxpr, sub.consts, ins) if hasattr(sub, "consts") else _run(w, sub, [], ins)
        else:
            raise Unsupported(f"JAX primitive {name!r}")
        for var, val in zip(eqn.outvars, out):
            shape = tuple(var.aval.shape)
            if val.cells.shape != (shape[1:] if val.lane else shape):  # the lane bookkeeping went astray
                raise Unsupported(f"{name}: cannot follow the lane axis through shape {shape}")
            env[var] = val
    return [read(v) for v in jaxpr.outvars]


class DrjitFormula:
    """``model.eval`` for ``channels`` channels (the model's own by default) as a function of cells:
    ``__call__(params, wi, wo)`` with ``params`` mapping each parameter name to a list of its cells
    (Dr.Jit arrays or numbers, its ``size``), ``wi``/``wo`` triples (the light and the view, docs/conventions.md#conventions),
    returns the ``channels`` cells of f_r (Dr.Jit back end); :meth:`scalar` is the same program on
    Python floats. Raises ``Unsupported`` on construction where the formula cannot be translated."""

    def __init__(self, model, channels: int | None = None):
        import jax
        import jax.numpy as jnp

        if channels is not None and channels != model.channels:
            model = model.with_channels(channels)
        self.model, self.channels = model, model.channels
        params = {p.name: jnp.full((model.size(p),), p.default, jnp.float32) for p in model.params}
        self._order = sorted(params)  # a dict's pytree leaves come in sorted key order
        pole = jnp.tile(jnp.asarray([[0.1, 0.2, 0.97]], jnp.float32), (LANES, 1))
        closed = jax.make_jaxpr(model.eval)(params, pole, pole)
        #: argument names of the generated function: each parameter's cells (in ``model.params``
        #: order), then wi and wo
        self.args = [f"p{k}_{i}" for k, p in enumerate(model.params) for i in range(model.size(p))]
        self.args += ["wi0", "wi1", "wi2", "wo0", "wo1", "wo2"]
        self.source, self.tables = {}, {}
        for backend in ("jit", "scalar"):
            w = _Writer(backend)
            index = {p.name: k for k, p in enumerate(model.params)}
            ins = []
            for name in self._order:
                k, size = index[name], model.size(model.param(name))
                ins.append(_Value(_vars([f"p{k}_{i}" for i in range(size)]), False))
            ins += [_Value(_vars([f"{prefix}{i}" for i in range(3)]), True) for prefix in ("wi", "wo")]
            (out,) = _run(w, closed.jaxpr, closed.consts, ins)
            if not out.lane or out.cells.shape != (self.channels,):
                raise Unsupported(f"formula output of shape {out.cells.shape} (lane {out.lane})")
            self.source[backend] = w.source(self.args, list(out.cells))
            self.tables[backend] = w.tables
        self.scalar = _scalar_function(self.source["scalar"], self.tables["scalar"], model.name)

    def jit(self, dr_float):
        """The generated function on Dr.Jit arrays of type ``dr_float`` (the variant's ``mi.Float``)."""
        return _jit_function(self.source["jit"], tuple(map(bytes, self.tables["jit"])), dr_float, self.model.name)

    def __call__(self, params, wi, wo) -> list:
        cells = [c for p in self.model.params for c in params[p.name]]
        dr_float = next((type(c) for c in [*cells, *wi, *wo] if not isinstance(c, (int, float))), None)
        if dr_float is None:
            return list(self.scalar(*cells, *wi, *wo))
        return list(self.jit(dr_float)(*cells, *wi, *wo))


def _compile(source: str, namespace: dict, name: str):
    exec(compile(source, f"<brdffit formula {name}>", "exec"), namespace)  # noqa: S102 - our own generated code
    return namespace["formula"]


def _scalar_function(source: str, tables: list[np.ndarray], name: str):
    fast_ns, safe_ns = scalar_namespaces()
    tables_ns = {f"T{i}": [float(x) for x in t] for i, t in enumerate(tables)}
    fast = _compile(source, {**fast_ns, **tables_ns}, name)
    safe = _compile(source, {**safe_ns, **tables_ns}, name)

    def formula(*args):
        try:
            return fast(*args)
        except (ArithmeticError, ValueError):  # Python raised where IEEE arithmetic gives inf or NaN
            with np.errstate(all="ignore"):
                return tuple(float(x) for x in safe(*(np.float64(a) for a in args)))

    formula.source = source
    return formula


@functools.lru_cache(maxsize=None)
def _jit_function(source: str, tables: tuple[bytes, ...], dr_float, name: str):
    import drjit as dr

    int_type = dr.int32_array_t(dr_float)
    namespace = {
        "select": dr.select, "sqrt": dr.sqrt, "rsqrt": dr.rsqrt, "exp": dr.exp, "log": dr.log, "sin": dr.sin,
        "cos": dr.cos, "tan": dr.tan, "atan2": dr.atan2, "floor": dr.floor, "ceil": dr.ceil, "abs_": dr.abs,
        "pow_": dr.power, "maximum": dr.maximum, "minimum": dr.minimum, "inf": math.inf, "nan": math.nan,
        "to_int": lambda x: int_type(x) if not isinstance(x, (int, float)) else int(x),
        "to_float": lambda x: dr_float(x) if not isinstance(x, (int, float)) else float(x),
        "gather": lambda table, index: dr.gather(dr_float, table, index),
    }
    for i, t in enumerate(tables):
        namespace[f"T{i}"] = dr_float(np.frombuffer(t, np.float32))
    return _compile(source, namespace, name)


@functools.lru_cache(maxsize=None)
def drjit_formula(model, channels: int | None = None) -> DrjitFormula:
    """The translated formula of ``model`` for ``channels`` channels (once per model, channel count
    and process)."""
    return DrjitFormula(model, channels)
