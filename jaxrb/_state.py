"""The state of one rigid body."""

import equinox as eqx
import jax.numpy as jnp

from ._checks import as_float_array
from ._typing import Quat, Vec3


class State(eqx.Module):
    """Position, attitude and velocities of a rigid body.

    **Fields:**

    - `pos`: mass-centre position, world frame (m).
    - `quat`: attitude, unit quaternion (e0, e1, e2, e3), scalar first, mapping body to world.
    - `vel`: mass-centre velocity, world frame (m/s).
    - `omega`: angular velocity in the body frame (rad/s), components on the body axes.

    Leaves may carry leading batch (or time) axes. The same class holds time derivatives
    (`vector_field` returns a `State` of rates).
    """

    pos: Vec3
    quat: Quat
    vel: Vec3
    omega: Vec3


def make_state(
    pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), omega=(0.0, 0.0, 0.0)
):
    """A `State` from array-likes, with defaults: at the origin, identity attitude, at rest.

    Shapes are checked (each argument is named in the error); leaves are broadcast to a
    common batch shape.
    """
    pos = as_float_array(pos, "pos", (3,))
    quat = as_float_array(quat, "quat", (4,))
    vel = as_float_array(vel, "vel", (3,))
    omega = as_float_array(omega, "omega", (3,))
    dtype = jnp.result_type(pos, quat, vel, omega)
    batch = jnp.broadcast_shapes(pos.shape[:-1], quat.shape[:-1], vel.shape[:-1], omega.shape[:-1])
    return State(
        pos=jnp.broadcast_to(pos.astype(dtype), batch + (3,)),
        quat=jnp.broadcast_to(quat.astype(dtype), batch + (4,)),
        vel=jnp.broadcast_to(vel.astype(dtype), batch + (3,)),
        omega=jnp.broadcast_to(omega.astype(dtype), batch + (3,)),
    )
