"""Small symmetric positive definite solves inside the fit programs, without LAPACK.

The matrices a fit solves with are tiny (the Gauss-Newton matrix of one fit: P x P with P <= ~20;
the Gram matrix of a model's linear parameters: 1-4). On CPU, ``jnp.linalg.cholesky`` and
``jnp.linalg.solve`` become LAPACK calls, whose entry points JAX takes from SciPy: a process that
runs such a program must import ``scipy.linalg`` first (~0.2-0.3 s here, most of it SciPy's
array-API and docstring machinery), even when the program itself is loaded ready-compiled from
the disk cache (``cache.load_or_compile``). For n this small the textbook algorithm, written with
``lax.fori_loop`` over columns, costs microseconds, and the fit programs need no LAPACK at all.

Cholesky without pivoting is backward stable for a symmetric positive definite matrix (Higham,
*Accuracy and Stability of Numerical Algorithms*, 2nd ed., Thm. 10.3). A matrix that is not
positive definite gives NaN, as ``jnp.linalg.cholesky`` does; the callers test for it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Float


def cholesky(A: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Lower triangular L with L L^T = A (only A's lower triangle is read); NaN where A is not
    positive definite. Column j: v = A[:, j] - L[:, :j] L[j, :j]; L[j, j] = sqrt(v[j]); L[i, j] =
    v[i] / L[j, j] below it."""
    A = jnp.asarray(A)
    n = A.shape[-1]
    rows = jnp.arange(n)
    L = jnp.zeros_like(A)
    for j in range(n):
        v = A[:, j] - L @ L[j, :]  # L[j, k] is still 0 for k >= j: the sum runs over k < j
        d = jnp.sqrt(v[j])
        L = L.at[:, j].set(jnp.where(rows >= j, v / d, 0.0))
    return L


def forward_substitution(L: Float[Array, "n n"], b: Float[Array, " n"]) -> Float[Array, " n"]:
    """y with L y = b, L lower triangular."""
    L, b = jnp.asarray(L), jnp.asarray(b)
    y = jnp.zeros_like(b)
    for i in range(L.shape[-1]):
        y = y.at[i].set((b[i] - L[i, :] @ y) / L[i, i])  # y[k] is still 0 for k >= i
    return y


def back_substitution(L: Float[Array, "n n"], y: Float[Array, " n"]) -> Float[Array, " n"]:
    """x with L^T x = y, L lower triangular."""
    L, y = jnp.asarray(L), jnp.asarray(y)
    x = jnp.zeros_like(y)
    for i in reversed(range(L.shape[-1])):
        x = x.at[i].set((y[i] - L[:, i] @ x) / L[i, i])  # x[k] is still 0 for k <= i
    return x


def spd_solve(A: Float[Array, "n n"], b: Float[Array, " n"]) -> Float[Array, " n"]:
    """x = A^-1 b for a symmetric positive definite A (NaN where it is not)."""
    L = cholesky(A)
    return back_substitution(L, forward_substitution(L, b))


def inverse_quadratic_form(A: Float[Array, "n n"], b: Float[Array, " n"]) -> Float[Array, ""]:
    """b^T A^-1 b = |L^-1 b|^2 for a symmetric positive definite A (one triangular solve)."""
    y = forward_substitution(cholesky(A), b)
    return y @ y


__all__ = ["back_substitution", "cholesky", "forward_substitution", "inverse_quadratic_form", "spd_solve"]
