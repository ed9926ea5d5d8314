"""The element-wise operations of the translated formulas (:mod:`brdffit.render.drjit_formula`).

Each JAX element-wise primitive becomes a Python expression template of its arguments, for two back
ends: ``jit`` (the arguments are Dr.Jit arrays: ``select``, ``sqrt``... are Dr.Jit's) and ``scalar``
(plain Python floats: inline conditionals and arithmetic, ``math``'s functions, for speed). The
scalar templates also fold constants while translating, with NumPy's IEEE semantics (inf and NaN
where Python would raise), the semantics JAX and Dr.Jit compute with.
"""

from __future__ import annotations

import functools
import math

import numpy as np


class Var:
    """A variable of the generated program: its name and kind, "f" float, "b" bool or "i" integer."""

    __slots__ = ("name", "kind")

    def __init__(self, name: str, kind: str):
        self.name, self.kind = name, kind


def _kind(x) -> str:
    if isinstance(x, Var):
        return x.kind
    return "b" if isinstance(x, (bool, np.bool_)) else ("i" if isinstance(x, (int, np.integer)) else "f")


def literal(x) -> str:
    """A cell as source text: a variable's name or a number."""
    if isinstance(x, Var):
        return x.name
    if _kind(x) == "b":
        return "True" if x else "False"
    return str(int(x)) if _kind(x) == "i" else repr(float(x))


def _arith(op):
    return lambda backend, a, b: (f"({{0}} {op} {{1}})", "f" if "f" in (_kind(a), _kind(b)) else "i")


def _named(fn, jit=None, scalar=None):
    """A function of one float: ``fn(x)`` in both back ends unless one has its own template."""
    return lambda backend, a: ((jit if backend == "jit" else scalar) or f"{fn}({{0}})", "f")


def _select(backend, c, a, b):
    cond = "({0} != 0)" if _kind(c) == "i" else "{0}"
    kind = "f" if "f" in (_kind(a), _kind(b)) else _kind(a)
    if backend == "jit":
        return f"select({cond}, {{1}}, {{2}})", kind
    return f"({{1}} if {cond} else {{2}})", kind


def _extreme(backend, a, b, jit, cmp):
    kind = "f" if "f" in (_kind(a), _kind(b)) else _kind(a)
    return (f"{jit}({{0}}, {{1}})" if backend == "jit" else f"({{0}} if {{0}} {cmp} {{1}} else {{1}})"), kind


def _integer_pow(backend, a, y):
    if y == 0:
        return "1.0", "f"
    if abs(y) > 16:
        return f"pow_({{0}}, {float(y)!r})", "f"
    prod = "(" + " * ".join(["{0}"] * abs(y)) + ")"
    return (prod if y > 0 else f"(1.0 / {prod})"), _kind(a)


def _convert(backend, a, to):
    src = _kind(a)
    if src == to:
        return "{0}", to
    if to == "b":
        return "({0} != 0)", "b"
    if to == "f":
        if src == "b":
            return ("select({0}, 1.0, 0.0)" if backend == "jit" else "(1.0 if {0} else 0.0)"), "f"
        return ("to_float({0})" if backend == "jit" else "float({0})"), "f"
    if src == "b":
        return ("select({0}, 1, 0)" if backend == "jit" else "int({0})"), "i"
    return ("to_int({0})" if backend == "jit" else "int_({0})"), "i"


#: JAX's element-wise primitives (and "select", "convert"): ``(backend, *args, **params) ->
#: (template, kind)``, the template a Python expression of the arguments {0}, {1}, ...
ELEMENTWISE = {
    "add": _arith("+"), "sub": _arith("-"), "mul": _arith("*"),
    "div": lambda backend, a, b: ("({0} / {1})", "f"),
    "neg": lambda backend, a: ("(-{0})", _kind(a)),
    "max": lambda backend, a, b: _extreme(backend, a, b, "maximum", ">"),
    "min": lambda backend, a, b: _extreme(backend, a, b, "minimum", "<"),
    "pow": lambda backend, a, b: ("pow_({0}, {1})", "f"),
    "atan2": lambda backend, a, b: ("atan2({0}, {1})", "f"),
    **{name: (lambda op: lambda backend, a, b: (f"({{0}} {op} {{1}})", "b"))(op)
       for name, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="), ("eq", "=="), ("ne", "!="))},
    "and": lambda backend, a, b: ("({0} & {1})", _kind(a)),
    "or": lambda backend, a, b: ("({0} | {1})", _kind(a)),
    "not": lambda backend, a: ("(~{0})" if backend == "jit" else "(not {0})", "b"),
    "abs": lambda backend, a: ("abs_({0})", _kind(a)),
    **{fn: _named(fn) for fn in ("sqrt", "exp", "log", "sin", "cos", "tan", "tanh", "asin", "acos", "atan")},
    "rsqrt": _named("rsqrt", scalar="(1.0 / sqrt({0}))"),
    "floor": _named("floor", scalar="({0} // 1.0)"),
    "ceil": _named("ceil", scalar="(-((-{0}) // 1.0))"),
    "log1p": _named("log1p", jit="log(1.0 + {0})"),
    "expm1": _named("expm1", jit="(exp({0}) - 1.0)"),
    "logistic": _named("", jit="(1.0 / (1.0 + exp(-{0})))", scalar="(1.0 / (1.0 + exp(-{0})))"),
    "sign": _named("", jit="select({0} > 0, 1.0, select({0} < 0, -1.0, 0.0))",
                   scalar="(1.0 if {0} > 0 else (-1.0 if {0} < 0 else 0.0))"),
    "stop_gradient": lambda backend, a: ("{0}", _kind(a)),
    "square": lambda backend, a: ("({0} * {0})", _kind(a)),
    "integer_pow": _integer_pow,
    "select": _select,
    "convert": _convert,
}


def _safe_int(x):
    return int(x) if np.isfinite(x) else 0


def scalar_namespaces() -> tuple[dict, dict]:
    """The scalar back end's names: Python's ``math`` (fast; raises on a domain error or overflow),
    and NumPy's (IEEE: inf and NaN, what JAX and Dr.Jit compute), for the calls that raised."""
    fast = {fn: getattr(math, fn) for fn in ("sqrt", "exp", "log", "sin", "cos", "tan", "tanh", "asin", "acos",
                                             "atan", "atan2", "log1p", "expm1")}
    fast.update(abs_=abs, pow_=math.pow, int_=int, inf=math.inf, nan=math.nan)
    safe = {fn: getattr(np, name) for fn, name in (("sqrt", "sqrt"), ("exp", "exp"), ("log", "log"), ("sin", "sin"),
                                                   ("cos", "cos"), ("tan", "tan"), ("tanh", "tanh"), ("asin", "arcsin"),
                                                   ("acos", "arccos"), ("atan", "arctan"), ("atan2", "arctan2"),
                                                   ("log1p", "log1p"), ("expm1", "expm1"))}
    safe.update(abs_=np.abs, pow_=np.power, int_=_safe_int, inf=math.inf, nan=math.nan)
    return fast, safe


@functools.lru_cache(maxsize=None)
def _folder(template: str, n: int):
    return eval("lambda *a: " + template.format(*(f"a[{i}]" for i in range(n))), scalar_namespaces()[1])  # noqa: S307


def fold(template: str, kind: str, args):
    """The value of an operation on numbers, with IEEE semantics (as JAX and Dr.Jit)."""
    with np.errstate(all="ignore"):
        out = _folder(template, len(args))(*(np.float64(a) if _kind(a) == "f" else a for a in args))
    return bool(out) if kind == "b" else (int(out) if kind == "i" else float(out))
