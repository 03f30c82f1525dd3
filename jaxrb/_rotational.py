"""Euler's rotational equation J w_dot + w x (J w) = M, body frame."""

import jax.numpy as jnp

from ._linalg import inverse3


def angular_acceleration(inertia, principal: bool, omega, moment, inverse=None):
    """Body-frame w_dot (rad/s^2) from J w_dot = M - w x (J w).

    **Arguments:**

    - `inertia`: principal moments (..., 3) if `principal`, else the full tensor (..., 3, 3)
      with products of inertia (the scalar form with all six entries, solved for w_dot).
    - `principal`: static flag selecting Euler's cheaper principal-axes equations.
    - `omega`, `moment`: body frame (rad/s, N m).
    - `inverse`: J^-1 of the full tensor where the caller has it already, else None.
    """
    if principal:
        return (moment - jnp.cross(omega, inertia * omega)) / inertia
    J_omega = jnp.einsum("...ij,...j->...i", inertia, omega)
    rhs = moment - jnp.cross(omega, J_omega)
    if inverse is None:
        inverse = inverse3(inertia)
    return jnp.einsum("...ij,...j->...i", inverse, rhs)
