"""Small dense linear algebra written in plain jnp operations.

No LAPACK here: under `jax.vmap` a LAPACK call becomes a batched call that splits its batch
over XLA's CPU thread pool and waits for the parts; two such calls running at once (XLA runs
independent operations concurrently) can each hold a pool thread while waiting for parts
queued behind the other, which deadlocks on a machine with two cores. These systems are
small (3 x 3 to 12 x 12), so elimination written out is also quick.
"""

import jax
import jax.numpy as jnp


def _eliminate(M, rows, k):
    """Column k of the augmented matrix M eliminated below the diagonal, after swapping up
    the row with the largest entry (partial pivoting)."""
    col = jnp.where(rows >= k, jnp.abs(M[:, k]), -1.0)
    p = jnp.argmax(col).astype(rows.dtype)
    M = jnp.where((rows == k)[:, None], M[p], jnp.where((rows == p)[:, None], M[k], M))
    factors = jnp.where(rows > k, M[:, k] / M[k, k], 0.0)
    return M - factors[:, None] * M[k]


def solve(A, b, unroll: bool = False):
    """x with A x = b, for a small square `A` (n, n) and `b` (n,) or (n, m): Gaussian
    elimination with partial pivoting, then back substitution.

    The elimination is a loop over the n columns (one column's operations in the compiled
    program instead of n: a die's contact program compiled in 12.2 s instead of 14.4 s on
    a 2-core x86 CPU), or, with `unroll`, written out column by column. The impact law
    unrolls: its normal equations are nearly singular (a face's four corners give 12 rows
    of rank 6), and only the unrolled elimination gave the same impulses for every
    numbering of the corners to roundoff (through the loop they differed by up to 1e-5,
    relative, with XLA's legacy CPU emitters)."""
    n = A.shape[-1]
    vector = b.ndim == 1
    B = b[:, None] if vector else b
    M = jnp.concatenate([A, B], axis=1)
    rows = jnp.arange(n)
    if unroll:
        for k in range(n):
            M = _eliminate(M, rows, k)
    else:
        M = jax.lax.fori_loop(0, n, lambda k, M: _eliminate(M, rows, k), M)
    x = jnp.zeros(B.shape, M.dtype)
    for k in reversed(range(n)):
        x = x.at[k].set((M[k, n:] - M[k, :n] @ x) / M[k, k])
    return x[:, 0] if vector else x


def inverse3(J):
    """Inverse of 3 x 3 matrices (..., 3, 3) by cofactors."""
    a, b, c = J[..., 0, 0], J[..., 0, 1], J[..., 0, 2]
    d, e, f = J[..., 1, 0], J[..., 1, 1], J[..., 1, 2]
    g, h, i = J[..., 2, 0], J[..., 2, 1], J[..., 2, 2]
    cof = jnp.stack(
        [
            jnp.stack([e * i - f * h, c * h - b * i, b * f - c * e], -1),
            jnp.stack([f * g - d * i, a * i - c * g, c * d - a * f], -1),
            jnp.stack([d * h - e * g, b * g - a * h, a * e - b * d], -1),
        ],
        -2,
    )
    det = a * cof[..., 0, 0] + b * cof[..., 1, 0] + c * cof[..., 2, 0]
    return cof / det[..., None, None]


JACOBI_SWEEPS = 6  # cyclic sweeps; a 3 x 3 matrix converges to roundoff in about 4


def symmetric_eigenvalues3(S):
    """Eigenvalues, ascending (..., 3), of symmetric 3 x 3 matrices (..., 3, 3), by a fixed
    number of cyclic Jacobi sweeps in plain jnp (accurate to roundoff relative to the
    largest eigenvalue, also where eigenvalues coincide; no LAPACK call). For checks, not
    for gradients."""
    dtype = S.dtype
    tiny = jnp.finfo(dtype).tiny
    eye = jnp.eye(3, dtype=dtype)
    A = 0.5 * (S + jnp.swapaxes(S, -1, -2))
    for _ in range(JACOBI_SWEEPS):
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = A[..., p, q]
            rotate = jnp.abs(apq) > tiny
            theta = (A[..., q, q] - A[..., p, p]) / (2 * jnp.where(rotate, apq, 1.0))
            t = jnp.where(theta >= 0, 1.0, -1.0) / (jnp.abs(theta) + jnp.sqrt(theta**2 + 1))
            t = jnp.where(rotate, t, 0.0)
            c = 1 / jnp.sqrt(t**2 + 1)
            s = t * c
            G = jnp.broadcast_to(eye, A.shape)
            G = G.at[..., p, p].set(c).at[..., q, q].set(c)
            G = G.at[..., p, q].set(s).at[..., q, p].set(-s)
            A = jnp.swapaxes(G, -1, -2) @ A @ G
    return jnp.sort(jnp.diagonal(A, axis1=-2, axis2=-1), axis=-1)
