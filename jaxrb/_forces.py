"""Force models. Each adds only its own terms to the right-hand side.

A force returns its wrench on the body: the force in the world frame (N) acting at the mass
centre and the moment about the mass centre in the body frame (N m). A force applied away
from the mass centre contributes the moment of that offset.
"""

import abc
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp

from ._body import RigidBody
from ._checks import (
    Requirement,
    as_float_array,
    finite,
    finite_nonnegative,
    raise_unmet,
)
from ._quaternion import _safe_norm, quat_conjugate, quat_rotate
from ._state import State
from ._typing import Vec3


class AbstractForce(eqx.Module):
    """A force model: `wrench(t, state, body) -> (force_world, moment_body)`.

    Parameters are checked where the force is made (a ValueError naming the field for
    concrete values) and by `simulate` (`RESULTS.invalid_force` for traced ones).
    """

    def requirements(self) -> tuple[Requirement, ...]:
        """The conditions on the force's parameters; none by default."""
        return ()

    def __check_init__(self):
        raise_unmet(type(self).__name__, self.requirements())

    @abc.abstractmethod
    def wrench(self, t, state: State, body: RigidBody) -> tuple[Vec3, Vec3]:
        """Force (world frame, N) at the mass centre and moment about it (body frame, N m)."""

    def potential_energy(self, state: State, body: RigidBody):
        """Potential energy (J) if the force is conservative, else 0."""
        return jnp.zeros_like(state.pos[..., 0])


def _zero3(state):
    return jnp.zeros_like(state.pos)


class Gravity(AbstractForce):
    """Uniform gravity, force m g at the mass centre; `g` in m/s^2, world frame (z up)."""

    g: jnp.ndarray

    def __init__(self, g=(0.0, 0.0, -9.81)):
        self.g = as_float_array(g, "g", (3,))

    def requirements(self):
        return (Requirement("g", self.g, "finite", finite(self.g)),)

    def wrench(self, t, state, body):
        force = body.mass[..., None] * self.g.astype(state.pos.dtype)
        return jnp.broadcast_to(force, state.pos.shape), _zero3(state)

    def potential_energy(self, state, body):
        return -body.mass * jnp.sum(self.g.astype(state.pos.dtype) * state.pos, axis=-1)


class LinearDrag(AbstractForce):
    """Linear air resistance F = -c v on the mass centre; `coefficient` c in N s/m."""

    coefficient: jnp.ndarray

    def __init__(self, coefficient):
        self.coefficient = jnp.asarray(coefficient, dtype=float)

    def requirements(self):
        c = self.coefficient
        return (Requirement("coefficient", c, "finite and >= 0", finite_nonnegative(c)),)

    def wrench(self, t, state, body):
        return -self.coefficient[..., None] * state.vel, _zero3(state)


class QuadraticDrag(AbstractForce):
    """Quadratic air resistance F = -k |v| v on the mass centre; k = rho C_D A / 2 in kg/m.

    Build from physical quantities with `QuadraticDrag.from_air(rho, drag_coefficient, area)`.
    """

    coefficient: jnp.ndarray

    def __init__(self, coefficient):
        self.coefficient = jnp.asarray(coefficient, dtype=float)

    def requirements(self):
        c = self.coefficient
        return (Requirement("coefficient", c, "finite and >= 0", finite_nonnegative(c)),)

    @classmethod
    def from_air(cls, rho=1.225, drag_coefficient=1.0, area=1.0):
        """k = rho C_D A / 2 with air density rho (kg/m^3), C_D and frontal area A (m^2)."""
        return cls(0.5 * jnp.asarray(rho) * drag_coefficient * area)

    def wrench(self, t, state, body):
        speed = _safe_norm(state.vel, keepdims=True)
        return -self.coefficient[..., None] * speed * state.vel, _zero3(state)


class DampingMoment(AbstractForce):
    """Aerodynamic damping moment M = -(c_w + c_w2 |w|) w, body frame (N m).

    `linear` c_w in N m s, `quadratic` c_w2 in N m s^2.
    """

    linear: jnp.ndarray
    quadratic: jnp.ndarray

    def __init__(self, linear=0.0, quadratic=0.0):
        self.linear = jnp.asarray(linear, dtype=float)
        self.quadratic = jnp.asarray(quadratic, dtype=float)

    def requirements(self):
        lin, quad = self.linear, self.quadratic
        return (
            Requirement("linear", lin, "finite and >= 0", finite_nonnegative(lin)),
            Requirement("quadratic", quad, "finite and >= 0", finite_nonnegative(quad)),
        )

    def wrench(self, t, state, body):
        rate = _safe_norm(state.omega, keepdims=True)
        moment = -(self.linear[..., None] + self.quadratic[..., None] * rate) * state.omega
        return _zero3(state), moment


class Wrench(AbstractForce):
    """A force and torque applied at a body point, constant or a function of time.

    **Arguments:**

    - `force`: (3,) array or a callable `t -> (3,)`, N; in `frame` axes. None means zero.
    - `torque`: (3,) array or a callable `t -> (3,)`, N m; in `frame` axes. None means zero.
    - `point`: body-frame application point relative to the mass centre (m); default the
      mass centre.
    - `frame`: "world" or "body": the axes `force` and `torque` are given in.
    """

    force: jnp.ndarray | Callable | None
    torque: jnp.ndarray | Callable | None
    point: jnp.ndarray | None
    frame: str = eqx.field(static=True)

    def __init__(self, force=None, torque=None, point=None, frame="world"):
        if frame not in ("world", "body"):
            raise ValueError(f"frame must be 'world' or 'body', got {frame!r}")
        self.force = (
            force if force is None or callable(force) else as_float_array(force, "force", (3,))
        )
        self.torque = (
            torque if torque is None or callable(torque) else as_float_array(torque, "torque", (3,))
        )
        self.point = None if point is None else as_float_array(point, "point", (3,))
        self.frame = frame

    def requirements(self):
        arrays = {"force": self.force, "torque": self.torque, "point": self.point}
        return tuple(
            Requirement(name, x, "finite", finite(x))
            for name, x in arrays.items()
            if x is not None and not callable(x)
        )

    @staticmethod
    def _value(x, t, like):
        if x is None:
            return jnp.zeros_like(like)
        value = x(t) if callable(x) else x
        return jnp.broadcast_to(jnp.asarray(value, like.dtype), like.shape)

    def wrench(self, t, state, body):
        force = self._value(self.force, t, state.pos)
        torque = self._value(self.torque, t, state.pos)
        to_body = quat_conjugate(state.quat)
        if self.frame == "world":
            force_world, force_body = force, quat_rotate(to_body, force)
            torque_body = quat_rotate(to_body, torque)
        else:
            force_world, force_body = quat_rotate(state.quat, force), force
            torque_body = torque
        if self.point is not None:
            torque_body = torque_body + jnp.cross(self.point.astype(force.dtype), force_body)
        return force_world, torque_body
