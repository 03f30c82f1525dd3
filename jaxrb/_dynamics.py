"""The right-hand side: Newton-Euler equations with quaternion kinematics.

Translation of the mass centre in the world frame (m a_C = F), rotation in the body frame
(J w_dot + w x J w = M_C), and q_dot = 1/2 q (x) (0, w). A jointed body uses the equations
about its fixed point instead (see `_joints.py`).
"""

import jax.numpy as jnp

from ._quaternion import quat_normalize
from ._rates import quat_rate
from ._rotational import angular_acceleration
from ._state import State


def total_wrench(t, state: State, scene):
    """Sum of the scene's forces: (force, world frame, N; moment about C, body frame, N m)."""
    force = jnp.zeros_like(state.pos)
    moment = jnp.zeros_like(state.omega)
    for model in scene.forces:
        f, m = model.wrench(t, state, scene.body)
        force, moment = force + f, moment + m
    return force, moment


def accelerations(t, state: State, scene):
    """(a_C world frame m/s^2, w_dot body frame rad/s^2) of the scene's body at `state`.

    `state.quat` must be unit norm (`vector_field` normalises it).
    """
    body = scene.body
    force, moment = total_wrench(t, state, scene)
    if scene.joint is None:
        omega_dot = angular_acceleration(
            body.inertia, body.principal, state.omega, moment, body.inertia_inverse
        )
        return force / body.mass[..., None], omega_dot
    joint = scene.joint
    omega_dot = joint.angular_acceleration(
        state, body, joint.moment_about_point(force, moment, state)
    )
    return joint.mass_centre_acceleration(state, omega_dot), omega_dot


def vector_field(t, state: State, scene) -> State:
    """d(state)/dt as a `State` of rates: (vel, q_dot, a_C, w_dot).

    The quaternion is normalised before it is used to rotate vectors; the kinematics
    q_dot = 1/2 q (x) (0, w) preserves |q| exactly along the true flow.
    """
    unit = State(state.pos, quat_normalize(state.quat), state.vel, state.omega)
    acc, omega_dot = accelerations(t, unit, scene)
    return State(pos=state.vel, quat=quat_rate(state.quat, state.omega), vel=acc, omega=omega_dot)


def joint_reaction(scene, t, state: State):
    """Force (world frame, N) the joint exerts on the body: m a_C - F_external."""
    if scene.joint is None:
        raise ValueError("joint_reaction needs a scene with a joint (Pivot or Hinge)")
    unit = State(state.pos, quat_normalize(state.quat), state.vel, state.omega)
    force, _ = total_wrench(t, unit, scene)
    acc, _ = accelerations(t, unit, scene)
    return scene.body.mass[..., None] * acc - force
