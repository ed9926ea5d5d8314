"""brdffit.fitting.linalg (the fit programs' small SPD solves without LAPACK) against NumPy's
LAPACK. What it exists for (a process that loads a fit program from the disk cache does not import
scipy.linalg) is tested in test_program_cache.py."""

from __future__ import annotations


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import brdffit  # noqa: F401  (float64)
from brdffit.fitting.linalg import back_substitution, cholesky, forward_substitution, inverse_quadratic_form, spd_solve

def _spd(n: int, seed: int, cond: float = 1e3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return (Q * np.geomspace(1.0, 1.0 / cond, n)) @ Q.T


@pytest.mark.parametrize("n", [1, 2, 3, 8, 13, 21])
def test_against_numpy_lapack(n):
    A = _spd(n, n)
    b = np.random.default_rng(100 + n).normal(size=n)
    L = np.asarray(jax.jit(cholesky)(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-13)
    assert np.all(np.triu(L, 1) == 0.0)
    np.testing.assert_allclose(np.asarray(jax.jit(spd_solve)(A, b)), np.linalg.solve(A, b), rtol=1e-9)
    np.testing.assert_allclose(float(jax.jit(inverse_quadratic_form)(A, b)), b @ np.linalg.solve(A, b), rtol=1e-9)
    Ln = np.linalg.cholesky(A)
    np.testing.assert_allclose(np.asarray(forward_substitution(Ln, b)), np.linalg.solve(Ln, b), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(back_substitution(Ln, b)), np.linalg.solve(Ln.T, b), rtol=1e-9)


def test_reads_the_lower_triangle_only_and_vmaps():
    A = np.stack([_spd(5, s) for s in range(4)])
    upper_garbage = A + np.triu(np.full((5, 5), 7.0), 1)
    L = np.asarray(jax.vmap(cholesky)(jnp.asarray(upper_garbage)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-13)


def test_not_positive_definite_gives_nan_like_jax():
    A = np.diag([1.0, -1.0, 2.0])
    assert np.isnan(np.asarray(cholesky(jnp.asarray(A)))).any()
    assert np.isnan(np.asarray(jnp.linalg.cholesky(jnp.asarray(A)))).any()
    assert not np.all(np.isfinite(np.asarray(spd_solve(jnp.asarray(A), jnp.ones(3)))))
