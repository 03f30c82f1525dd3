"""Small dense linear algebra written in plain jnp operations.

No LAPACK here: under `jax.vmap` a LAPACK call becomes a batched call that splits its batch
over XLA's CPU thread pool and waits for the parts; two such calls running at once (XLA runs
independent operations concurrently) can each hold a pool thread while waiting for parts
queued behind the other, which deadlocks on a machine with two cores. These systems are
small (3 x 3 to 12 x 12), so elimination written out is also quick.
"""

import functools
import operator

import jax
import jax.numpy as jnp


def _eliminate(M, rows, k):
    """Column k of the augmented matrix M eliminated below the diagonal, after swapping up
    the row with the largest entry (partial pivoting). Written so that XLA makes two
    kernels of it: the pivot search, and the swap with the elimination."""
    col = M[:, k]
    p = jnp.argmax(jnp.where(rows >= k, jnp.abs(col), -1.0)).astype(rows.dtype)
    pivot_row, row_k = M[p], M[k]
    # column k after the swap, and the factors that clear it below the diagonal
    swapped_col = jnp.where(rows == k, col[p], jnp.where(rows == p, col[k], col))
    factors = jnp.where(rows > k, swapped_col / col[p], 0.0)
    swapped = jnp.where((rows == k)[:, None], pivot_row, jnp.where((rows == p)[:, None], row_k, M))
    return swapped - factors[:, None] * pivot_row


def solve(A, b, unroll: bool = False):
    """x with A x = b, for a small square `A` (n, n) and `b` (n,) or (n, m): Gaussian
    elimination with partial pivoting, then back substitution.

    The elimination and the back substitution are loops over the n columns (one column's
    operations in the compiled program instead of n: with the elimination's loop a die's
    contact program compiled in 12.2 s instead of 14.4 s on a 2-core x86 CPU), or, with
    `unroll`, written out column by column. The impact law unrolls: its normal equations
    are nearly singular (a face's four corners give 12 rows of rank 6), and only the
    unrolled elimination gave the same impulses for every numbering of the corners to
    roundoff (through the loop they differed by up to 1e-5, relative, with XLA's legacy
    CPU emitters)."""
    n = A.shape[-1]
    vector = b.ndim == 1
    B = b[:, None] if vector else b
    M = jnp.concatenate([A, B], axis=1)
    rows = jnp.arange(n)
    x = jnp.zeros(B.shape, M.dtype)
    if unroll:
        for k in range(n):
            M = _eliminate(M, rows, k)
        for k in reversed(range(n)):
            x = x.at[k].set((M[k, n:] - M[k, :n] @ x) / M[k, k])
    else:
        M = jax.lax.fori_loop(0, n, lambda k, M: _eliminate(M, rows, k), M)

        def substitute(j, x):  # row k = n - 1 - j; the entries of x above k are still 0
            k = n - 1 - j
            Mk = M[k]
            return x.at[k].set((Mk[n:] - jnp.sum(Mk[:n, None] * x, axis=0)) / Mk[k])

        x = jax.lax.fori_loop(0, n, substitute, x)
    return x[:, 0] if vector else x


def dot(a, b):
    """a . b over the last axis (..., n; broadcast)."""
    return jnp.sum(a * b, axis=-1)


def matvec(A, x):
    """A x for small matrices A (..., m, n) and vectors x (..., n) (broadcast), written out
    column by column: elementwise work, which XLA fuses with what comes before and after,
    where a dot of a 3 x 3 matrix is a kernel of its own in the compiled program (a die's
    throw ran tens of thousands of them). The other products here are a product and a sum:
    as quick in the contact programs, and smaller to compile."""
    terms = (A[..., :, i] * x[..., None, i] for i in range(A.shape[-1]))
    return functools.reduce(operator.add, terms)


def vecmat(x, A):
    """x A (..., n) for vectors x (..., m) and small matrices A (..., m, n)."""
    return jnp.sum(x[..., :, None] * A, axis=-2)


def matmul(A, B):
    """A B for small matrices A (..., m, k) and B (..., k, n)."""
    return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)


def inverse3(J):
    """Inverse of 3 x 3 matrices (..., 3, 3) by cofactors: with rows r0, r1, r2 of J, the
    columns of J^-1 are r1 x r2, r2 x r0, r0 x r1 over det J = r0 . (r1 x r2)."""
    rows_next = jnp.concatenate([J[..., 1:, :], J[..., :1, :]], axis=-2)  # r1, r2, r0
    rows_after = jnp.concatenate([J[..., 2:, :], J[..., :2, :]], axis=-2)  # r2, r0, r1
    cof = cross(rows_next, rows_after)  # row i: r_{i+1} x r_{i+2}
    det = jnp.sum(J[..., 0, :] * cof[..., 0, :], axis=-1)
    return jnp.swapaxes(cof, -1, -2) / det[..., None, None]


def cross(a, b):
    """a x b over the last axis (..., 3; broadcast), written out by components (XLA fuses
    the components' products and their stacking into one kernel: a cross product by
    cyclic shifts of whole vectors took three)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


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

    def sweep(_, A):  # a loop, not unrolled: every compiled program that checks an
        # inertia tensor holds one sweep instead of six
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
        return A

    A = jax.lax.fori_loop(0, JACOBI_SWEEPS, sweep, A)
    return jnp.sort(jnp.diagonal(A, axis1=-2, axis2=-1), axis=-1)
