"""Unconstrained parameterisations that keep every optimiser iterate physically valid.

- positive quantities (drag coefficients, heights): `x = exp(z)`;
- quantities in (0, 1) (restitution): `x = sigmoid(z)`;
- inertia tensors: log-Cholesky of the centroidal pseudo-inertia (second-moment matrix)
  `S = integral r r^T dm = L L^T`, `L` lower triangular with `diag(L) = exp(d)`. Then
  `J = tr(S) 1 - S` (kg m^2, body axes, about the mass centre). Every real vector gives a
  symmetric positive-definite `J` that satisfies the strict triangle inequality (the
  principal second moments `s_i > 0` and `I_1 = s_2 + s_3` etc.), products of inertia
  included, with no singular point at symmetric tops (unlike principal moments plus a
  rotation);
- attitudes: `q = q_ref (x) exp(rotvec / 2)` (scalar-first quaternions, body -> world), a
  local chart around a reference attitude.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._quaternion import quat_multiply

# numpy, not jax, arrays: importing the package must not start JAX's backend
_TRIL_ROWS = np.array([1, 2, 2])
_TRIL_COLS = np.array([0, 0, 1])


def positive_to_unconstrained(x):
    """`log(x)`: the inverse of `unconstrained_to_positive`."""
    return jnp.log(x)


def unconstrained_to_positive(z):
    """`exp(z) > 0`."""
    return jnp.exp(z)


def unit_to_unconstrained(x):
    """`logit(x)` for x in (0, 1)."""
    return jnp.log(x) - jnp.log1p(-x)


def unconstrained_to_unit(z):
    """`sigmoid(z)` in (0, 1)."""
    return jax.nn.sigmoid(z)


def pseudo_inertia(inertia):
    """Second-moment matrix `S = integral r r^T dm = tr(J)/2 1 - J` (kg m^2) of a tensor `J`."""
    inertia = jnp.asarray(inertia)
    tr = jnp.trace(inertia, axis1=-2, axis2=-1)
    return 0.5 * tr[..., None, None] * jnp.eye(3, dtype=inertia.dtype) - inertia


def inertia_from_pseudo(second_moment):
    """Inertia tensor `J = tr(S) 1 - S` from the second-moment matrix `S`."""
    tr = jnp.trace(second_moment, axis1=-2, axis2=-1)
    return tr[..., None, None] * jnp.eye(3, dtype=second_moment.dtype) - second_moment


def log_cholesky_to_inertia(theta):
    """Inertia tensor (3, 3) from 6 log-Cholesky parameters `(d0, d1, d2, l10, l20, l21)`.

    `L = [[e^d0, 0, 0], [l10, e^d1, 0], [l20, l21, e^d2]]`, `S = L L^T`, `J = tr(S) 1 - S`.
    """
    theta = jnp.asarray(theta)
    chol = jnp.diag(jnp.exp(theta[:3]))
    chol = chol.at[_TRIL_ROWS, _TRIL_COLS].set(theta[3:])
    return inertia_from_pseudo(chol @ chol.T)


def inertia_to_log_cholesky(inertia):
    """The 6 log-Cholesky parameters of a physically valid inertia tensor (inverse map).

    Raises (through NaN) nothing: the caller validates `inertia` first.
    """
    chol = jnp.linalg.cholesky(pseudo_inertia(jnp.asarray(inertia)))
    return jnp.concatenate([jnp.log(jnp.diagonal(chol)), chol[_TRIL_ROWS, _TRIL_COLS]])


def perturb_quat(q_ref, rotvec):
    """`q_ref (x) exp(rotvec / 2)`: the attitude reached by rotating `q_ref` by the body-frame
    rotation vector `rotvec` (rad). AD-safe at `rotvec = 0` (double-where norm, `jnp.sinc`)."""
    angle2 = jnp.sum(rotvec**2, axis=-1)
    nonzero = angle2 > 0
    angle = jnp.where(nonzero, jnp.sqrt(jnp.where(nonzero, angle2, 1.0)), 0.0)
    scale = 0.5 * jnp.sinc(angle / (2 * jnp.pi))  # sin(angle / 2) / angle
    dq = jnp.concatenate([jnp.cos(0.5 * angle)[..., None], scale[..., None] * rotvec], axis=-1)
    return quat_multiply(q_ref, dq)
