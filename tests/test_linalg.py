"""The small dense linear algebra of `jaxrb._linalg` against numpy (float64)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrb._linalg import (
    cross,
    dot,
    inverse3,
    matmul,
    matvec,
    solve,
    symmetric_eigenvalues3,
    vecmat,
)

solve_jit = jax.jit(solve, static_argnames="unroll")


@pytest.mark.parametrize("unroll", [False, True])
@pytest.mark.parametrize("n", [1, 3, 6, 12])
def test_solve_matches_numpy(n, unroll):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) + n * np.eye(n)
    b = rng.normal(size=n)
    B = rng.normal(size=(n, 5))
    for rhs in (b, B):
        np.testing.assert_allclose(
            solve_jit(A, rhs, unroll=unroll), np.linalg.solve(A, rhs), rtol=1e-12, atol=1e-12
        )


def test_solve_pivots_past_a_zero_diagonal():
    """Every diagonal entry is 0: elimination without row exchanges would divide by 0."""
    rng = np.random.default_rng(1)
    P = np.eye(6)[[3, 0, 5, 1, 2, 4]]
    A = P @ np.diag(rng.uniform(1.0, 2.0, 6))
    assert np.all(np.diag(A) == 0)
    b = rng.normal(size=6)
    x = solve_jit(A, b)
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-13, atol=1e-13)


def test_solve_derivatives_match_the_implicit_ones():
    """Forward and reverse derivatives of x(A, b) against dx = A^-1 (db - dA x)."""
    rng = np.random.default_rng(2)
    n = 6
    A = rng.normal(size=(n, n)) + n * np.eye(n)
    b = rng.normal(size=n)
    dA, db = rng.normal(size=(n, n)), rng.normal(size=n)
    x = np.linalg.solve(A, b)
    expected = np.linalg.solve(A, db - dA @ x)
    _, tangent = jax.jvp(
        solve, (jnp.asarray(A), jnp.asarray(b)), (jnp.asarray(dA), jnp.asarray(db))
    )
    np.testing.assert_allclose(tangent, expected, rtol=1e-11, atol=1e-12)
    # reverse mode: <w, dx> = <gA, dA> + <gb, db>
    w = rng.normal(size=n)
    gA, gb = jax.grad(lambda A, b: jnp.dot(w, solve(A, b)), argnums=(0, 1))(A, b)
    np.testing.assert_allclose(
        np.sum(gA * dA) + np.dot(gb, db), np.dot(w, expected), rtol=1e-11, atol=1e-12
    )


def test_inverse3_and_eigenvalues3_match_numpy():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(4, 3, 3)) + 3 * np.eye(3)
    np.testing.assert_allclose(inverse3(J), np.linalg.inv(J), rtol=1e-12, atol=1e-12)
    S = J + np.swapaxes(J, -1, -2)
    S[0] = np.diag([2.0, 2.0, 5.0])  # a repeated eigenvalue
    np.testing.assert_allclose(
        symmetric_eigenvalues3(S), np.linalg.eigvalsh(S), rtol=1e-12, atol=1e-12
    )


def test_small_products_match_numpy():
    """The small products (`cross`, `dot`, `matvec`, `vecmat`, `matmul`) with leading axes
    and broadcasting, against numpy's, in float64."""
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=3)
    R, M6 = rng.normal(size=(3, 3)), rng.normal(size=(6, 6))
    P = rng.normal(size=(8, 3))
    products = jax.jit(
        lambda a, b, R, M6, P: (
            cross(a, b),
            dot(a, b),
            matvec(R, P),  # R p for each row p of P
            matvec(M6, M6[0]),
            vecmat(a, R),
            matmul(R, R.T),
            matmul(M6, M6.T),
        )
    )(a, b, R, M6, P)
    expected = (np.cross(a, b), a @ b, P @ R.T, M6 @ M6[0], a @ R, R @ R.T, M6 @ M6.T)
    for got, want in zip(products, expected, strict=True):
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-14)
