"""Energy and angular momentum of a body in a scene (conserved quantities in tests)."""

import jax.numpy as jnp

from ._quaternion import quat_normalize, quat_rotate
from ._state import State


def energy(scene, state: State):
    """Kinetic + potential energy (J): 1/2 m v.v + 1/2 w.J w + sum of force potentials."""
    body = scene.body
    J = body.inertia_matrix
    kinetic = 0.5 * body.mass * jnp.sum(state.vel**2, axis=-1) + 0.5 * jnp.einsum(
        "...i,...ij,...j->...", state.omega, J, state.omega
    )
    potential = sum(
        (f.potential_energy(state, body) for f in scene.forces), jnp.zeros_like(kinetic)
    )
    return kinetic + potential


def angular_momentum(scene, state: State, point=None):
    """Angular momentum (kg m^2/s), world frame.

    About the mass centre (R J w) by default; about the world `point` if given
    (R J w + (pos - point) x m vel), e.g. a pivot's anchor.
    """
    body = scene.body
    spin_body = jnp.einsum("...ij,...j->...i", body.inertia_matrix, state.omega)
    spin = quat_rotate(quat_normalize(state.quat), spin_body)
    if point is None:
        return spin
    r = state.pos - jnp.asarray(point, state.pos.dtype)
    return spin + body.mass[..., None] * jnp.cross(r, state.vel)
