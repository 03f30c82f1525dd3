"""Joints: a fixed point (`Pivot`, the heavy top) and a fixed axis (`Hinge`, the pendulum).

`point` and `axis` are body coordinates (m, relative to the mass centre); the joint's world
anchor is where that point is in the initial state. A jointed body is integrated in its own
coordinates (attitude and angular velocity for a pivot, one angle and its rate for a hinge);
`expand` turns those back into a full `State`.

Dynamics about the fixed point O (docs/theory.md, section 4.4, i.e. section 4.3 with v_O = 0):
J_O w_dot + w x J_O w = M_O, with J_O = J_C + m (|r|^2 1 - r r^T) and r = C - O (body);
the mass centre then accelerates as a_C = R (w_dot x r + w x (w x r)).
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from . import inertia as _inertia
from ._body import RigidBody
from ._checks import Requirement, as_float_array, finite, raise_unmet
from ._quaternion import (
    axis_angle_to_quat,
    quat_conjugate,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    unit_vector,
)
from ._rotational import angular_acceleration
from ._state import State
from ._typing import Vec3


class AbstractJoint(eqx.Module):
    """A joint holding one body point fixed in the world."""

    point: eqx.AbstractVar[jnp.ndarray]

    def requirements(self) -> tuple[Requirement, ...]:
        """Conditions on the joint's parameters: a ValueError naming the field for concrete
        values where the joint is made, `RESULTS.invalid_joint` in `simulate` for traced ones."""
        return (Requirement("point", self.point, "finite", finite(self.point)),)

    def __check_init__(self):
        raise_unmet(type(self).__name__, self.requirements())

    def anchor(self, state0: State) -> Vec3:
        """World position (m) of the fixed point: where `point` is in `state0`."""
        return state0.pos + quat_rotate(
            quat_normalize(state0.quat), self.point.astype(state0.pos.dtype)
        )

    def _kinematics(self, quat, omega, anchor):
        """Mass-centre position and velocity (world) of a body turning about the anchor."""
        r_body = -self.point.astype(omega.dtype)
        pos = anchor + quat_rotate(quat, r_body)
        vel = quat_rotate(quat, jnp.cross(omega, r_body))
        return pos, vel

    def mass_centre_acceleration(self, state: State, omega_dot: Vec3) -> Vec3:
        """a_C = R (w_dot x r + w x (w x r)), world frame, r = C - O in body axes."""
        r_body = -self.point.astype(state.omega.dtype)
        w = state.omega
        a_body = jnp.cross(omega_dot, r_body) + jnp.cross(w, jnp.cross(w, r_body))
        return quat_rotate(state.quat, a_body)

    def inertia_about_point(self, body: RigidBody):
        """J_O (kg m^2, body axes): the inertia tensor about the fixed point."""
        return _inertia.parallel_axis(
            body.inertia_matrix, body.mass, self.point.astype(body.inertia.dtype)
        )

    def moment_about_point(self, force_world, moment_body, state: State) -> Vec3:
        """M_O = M_C + r x F (body frame), r = C - O."""
        force_body = quat_rotate(quat_conjugate(state.quat), force_world)
        return moment_body + jnp.cross(-self.point.astype(force_body.dtype), force_body)

    def raw_quat_norm(self, y):
        """|q| of the integrated quaternion before normalisation (1 if none is integrated)."""
        return jnp.ones(())

    @abc.abstractmethod
    def angular_acceleration(self, state: State, body: RigidBody, moment_about_point: Vec3) -> Vec3:
        """Body-frame angular acceleration allowed by the joint (rad/s^2)."""

    @abc.abstractmethod
    def reduce(self, state0: State):
        """The joint's integration coordinates at the initial state."""

    @abc.abstractmethod
    def expand(self, y, state0: State) -> State:
        """The full `State` from the joint's coordinates."""

    @abc.abstractmethod
    def coordinate_rates(self, y, rates: State):
        """d(coordinates)/dt from the full state's rates."""


class Pivot(AbstractJoint):
    """A fixed point (ball joint) at body coordinates `point` (m, from the mass centre).

    Integrated in (quat, omega): 7 coordinates.
    """

    point: jnp.ndarray

    def __init__(self, point=(0.0, 0.0, 0.0)):
        self.point = as_float_array(point, "point", (3,))

    def angular_acceleration(self, state, body, moment_about_point):
        J_O = self.inertia_about_point(body)
        return angular_acceleration(J_O, False, state.omega, moment_about_point)

    def reduce(self, state0):
        return (quat_normalize(state0.quat), state0.omega)

    def expand(self, y, state0):
        quat, omega = y
        quat = quat_normalize(quat)
        pos, vel = self._kinematics(quat, omega, self.anchor(state0))
        return State(pos=pos, quat=quat, vel=vel, omega=omega)

    def coordinate_rates(self, y, rates):
        return (rates.quat, rates.omega)

    def raw_quat_norm(self, y):
        return jnp.linalg.norm(y[0], axis=-1)


class Hinge(AbstractJoint):
    """A fixed axis through body point `point` along body direction `axis` (any length > 0).

    Integrated in one angle theta (rad, right-handed about `axis`, zero at the initial
    attitude) and its rate. The initial angular velocity must be along the axis; only its
    component along the axis is used.
    """

    point: jnp.ndarray
    axis: jnp.ndarray

    def __init__(self, point=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0)):
        self.point = as_float_array(point, "point", (3,))
        axis = as_float_array(axis, "axis", (3,))
        unit = unit_vector(axis)  # NaN for a zero axis: flagged by `requirements`
        raise_unmet(
            "Hinge", (Requirement("axis", axis, "a finite non-zero direction", finite(unit)),)
        )
        self.axis = unit

    def requirements(self):
        rule = "a finite non-zero direction"
        return (*super().requirements(), Requirement("axis", self.axis, rule, finite(self.axis)))

    def angular_acceleration(self, state, body, moment_about_point):
        a = self.axis.astype(state.omega.dtype)
        J_O = self.inertia_about_point(body)
        J_a = jnp.einsum("...i,...ij,...j->...", a, J_O, a)
        gyro = jnp.cross(state.omega, jnp.einsum("...ij,...j->...i", J_O, state.omega))
        theta_ddot = jnp.sum(a * (moment_about_point - gyro), axis=-1) / J_a
        return theta_ddot[..., None] * a

    def reduce(self, state0):
        a = self.axis.astype(state0.omega.dtype)
        theta_dot = jnp.sum(state0.omega * a, axis=-1)
        return (jnp.zeros_like(theta_dot), theta_dot)

    def expand(self, y, state0):
        theta, theta_dot = y
        a = self.axis.astype(theta.dtype)
        quat = quat_multiply(quat_normalize(state0.quat), axis_angle_to_quat(a, theta))
        omega = theta_dot[..., None] * a
        pos, vel = self._kinematics(quat, omega, self.anchor(state0))
        return State(pos=pos, quat=quat, vel=vel, omega=omega)

    def coordinate_rates(self, y, rates):
        theta, theta_dot = y
        return (theta_dot, jnp.sum(rates.omega * self.axis.astype(theta.dtype), axis=-1))
