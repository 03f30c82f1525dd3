"""Jitted forms of library functions for host-side code: the models' constructors, a scene
file's checks, the command line's summary, the plots and the saved files.

Called eagerly, a function of a dozen array operations makes a dozen small programs, each
lowered and compiled (or read back from the persistent cache) on its own: about 9 ms apiece
in a new process on a 2-core CPU. Jitted, the function is one program. The engine's traced
code calls the plain functions.
"""

import equinox as eqx
import jax

from . import _euler, _quaternion
from ._invariants import energy as _energy
from ._quaternion import quat_normalize, quat_rotate

# a Floor's normal, a scene file's attitude (angles in rad; the sequence is static)
unit_vector = jax.jit(_quaternion.unit_vector)
axis_angle_to_quat = jax.jit(_quaternion.axis_angle_to_quat)
euler_to_quat = jax.jit(_euler.euler_to_quat, static_argnums=1)


@eqx.filter_jit
def shape_inertia(shape, mass):
    """`shape`'s uniform-solid inertia (kg m^2) about its centre, for a body of `mass` (kg)."""
    return shape.inertia(mass)


@eqx.filter_jit
def energy(scene, state):
    """`jaxrb.energy(scene, state)` (J), one program per state shape."""
    return _energy(scene, state)


@eqx.filter_jit
def floor_gap(scene, state):
    """Signed distance (m) of the body's lowest point above the scene's floor at `state`
    (its quaternion normalised first)."""
    return scene.floor.body_distance(scene.body.shape, state.pos, quat_normalize(state.quat))


@eqx.filter_jit
def omega_world(state):
    """The angular velocity in world axes (rad/s): R(quat) omega."""
    return quat_rotate(state.quat, state.omega)


@eqx.filter_jit
def lowest_z(shape, state):
    """World z (m) of the shape's lowest point: its distance above the plane z = 0."""
    return shape.floor_distance(state.pos, state.quat)
