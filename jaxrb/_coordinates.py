"""Integration coordinates: which numbers of a scene without a floor go through the solver.

- `FREE`: a free body under any forces: the full state (pos, quat, vel, omega), 13 numbers.
- `ROTATION`: a free body whose forces are all uniform `Gravity` (or none), which exert no
  moment about the mass centre: only the rotation (quat, omega: 7 numbers) is integrated,
  and the mass centre follows the exact parabola p0 + v0 t + g t^2 / 2.
- `JOINT`: a body on a `Pivot` (quat, omega) or a `Hinge` (one angle and its rate), in the
  joint's own coordinates (`jaxrb/_joints.py`).

Each kind gives, for one body: `reduce` (the coordinates at the initial state), `rates`
(their time derivative: the Newton-Euler equations with quaternion kinematics, as
`jaxrb.vector_field`), `states` (full `State`s at the save times) and `raw_quat_norm` (|q|
of the integrated quaternion before normalisation, at the save times). The scene is an
argument of each, so a batch of scenes maps over them with `jax.vmap`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._dynamics import accelerations
from ._forces import Gravity
from ._linalg import inverse3
from ._quaternion import quat_normalize
from ._rates import quat_rate
from ._rotational import angular_acceleration
from ._state import State


def _unit(q):
    """q / |q| for an integrated quaternion (|q| stays within the solver's error of 1; the
    initial one is normalised by `quat_normalize`, which accepts any finite non-zero norm)."""
    return q * jax.lax.rsqrt(jnp.sum(q * q, axis=-1, keepdims=True))


def _quat_norm(q):
    return jnp.sqrt(jnp.sum(q * q, axis=-1))


class _Free(eqx.Module):
    """The full state: pos and vel (world frame, m, m/s), quat, omega (body frame, rad/s)."""

    def reduce(self, scene, state0: State):
        return State(state0.pos, quat_normalize(state0.quat), state0.vel, state0.omega)

    def rates(self, scene, t, y: State, state0: State) -> State:
        unit = State(y.pos, _unit(y.quat), y.vel, y.omega)
        acc, omega_dot = accelerations(t, unit, scene)
        return State(y.vel, quat_rate(y.quat, y.omega), acc, omega_dot)

    def states(self, scene, ys: State, ts, state0: State) -> State:
        return State(ys.pos, _unit(ys.quat), ys.vel, ys.omega)

    def raw_quat_norm(self, scene, ys):
        return _quat_norm(ys.quat)


def rotation_rates_rows(inertia, inverse, principal: bool, rows):
    """The torque-free rotation's rates, row by row: `rows` = (q0, q1, q2, q3, w1, w2, w3),
    each an array over members (quat scalar first, body -> world; omega in body axes, rad/s).
    `inertia` and `inverse` are J and J^-1 in body axes (kg m^2 and its inverse), indexable
    as the three principal moments (`principal`) or as a 3 x 3 tensor (`[r][c]`): arrays, or
    lists of numbers (a GPU kernel's scalars). Returns the 7 rates' rows: q' = q (x) (0,
    omega) / 2 as `quat_rate`, then omega' = -J^-1 (omega x J omega)."""
    q0, q1, q2, q3, w1, w2, w3 = rows
    if principal:
        h1, h2, h3 = inertia[0] * w1, inertia[1] * w2, inertia[2] * w3
    else:
        h1, h2, h3 = (
            inertia[r][0] * w1 + inertia[r][1] * w2 + inertia[r][2] * w3 for r in range(3)
        )
    c1, c2, c3 = w2 * h3 - w3 * h2, w3 * h1 - w1 * h3, w1 * h2 - w2 * h1  # omega x J omega
    if principal:
        omega_dot = (-c1 * inverse[0], -c2 * inverse[1], -c3 * inverse[2])
    else:
        omega_dot = tuple(
            -(inverse[r][0] * c1 + inverse[r][1] * c2 + inverse[r][2] * c3) for r in range(3)
        )
    quat_dot = (
        0.5 * (-q1 * w1 - q2 * w2 - q3 * w3),
        0.5 * (q0 * w1 + q2 * w3 - q3 * w2),
        0.5 * (q0 * w2 + q3 * w1 - q1 * w3),
        0.5 * (q0 * w3 + q1 * w2 - q2 * w1),
    )
    return quat_dot + omega_dot


class _Rotation(eqx.Module):
    """(quat, omega) of a free body with no moment about its mass centre; the mass centre's
    motion is the exact parabola of the scene's total gravity."""

    def reduce(self, scene, state0: State):
        return (quat_normalize(state0.quat), state0.omega)

    def rates(self, scene, t, y, state0: State):
        quat, omega = y
        body = scene.body
        omega_dot = angular_acceleration(
            body.inertia.astype(omega.dtype), body.principal, omega, jnp.zeros_like(omega)
        )
        return (quat_rate(quat, omega), omega_dot)

    def member_last_rates(self, scene, y):
        """`rates` of a batch sharing `scene`, with the member axis last: quat (4, N), omega
        (3, N). Each coordinate is a row of N numbers, so every operation runs over
        contiguous memory (about 10 % of a batched solve's time against `jax.vmap`)."""
        quat, omega = y
        body = scene.body
        inertia = body.inertia.astype(omega.dtype)
        inverse = body.inertia_inverse  # cached by the caller (once, not at every stage)
        if inverse is None:
            inverse = 1.0 / inertia if body.principal else inverse3(inertia)
        rates = rotation_rates_rows(
            inertia, inverse.astype(omega.dtype), body.principal, (*quat, *omega)
        )
        return (jnp.stack(rates[:4]), jnp.stack(rates[4:]))

    def states(self, scene, ys, ts, state0: State) -> State:
        """`ys` leaves have a leading time axis (T, ...); `ts` (T,) are their times (s)."""
        quat, omega = ys
        dtype = omega.dtype
        g = sum((f.g.astype(dtype) for f in scene.forces), jnp.zeros(3, dtype))
        dt = (ts - ts[0])[:, None]
        pos = state0.pos + state0.vel * dt + 0.5 * g * dt**2
        vel = state0.vel + g * dt
        return State(pos, _unit(quat), vel, omega)

    def raw_quat_norm(self, scene, ys):
        return _quat_norm(ys[0])


class _Joint(eqx.Module):
    """The coordinates of the scene's joint (`AbstractJoint.reduce`, `expand`, ...)."""

    def reduce(self, scene, state0: State):
        return scene.joint.reduce(state0)

    def rates(self, scene, t, y, state0: State):
        state = scene.joint.expand(y, state0)  # unit quaternion
        acc, omega_dot = accelerations(t, state, scene)
        rates = State(state.vel, quat_rate(state.quat, state.omega), acc, omega_dot)
        return scene.joint.coordinate_rates(y, rates)

    def states(self, scene, ys, ts, state0: State) -> State:
        return jax.vmap(lambda y: scene.joint.expand(y, state0))(ys)

    def raw_quat_norm(self, scene, ys):
        """|q| of a pivot's integrated quaternion; 1 for a hinge (which integrates an angle)."""
        first = jax.tree.leaves(ys)[0]
        norms = jax.vmap(scene.joint.raw_quat_norm)(ys)
        return jnp.broadcast_to(norms, first.shape[:1]).astype(first.dtype)


FREE, ROTATION, JOINT = _Free(), _Rotation(), _Joint()


class FullState(eqx.Module):
    """A free body's full state in the joints' one-body interface (`AbstractJoint.reduce`,
    `expand`, `coordinate_rates`, `raw_quat_norm`), for callers that evaluate
    `jaxrb.vector_field` themselves (e.g. the scipy peers in benchmarks/)."""

    def reduce(self, state0: State) -> State:
        return State(state0.pos, quat_normalize(state0.quat), state0.vel, state0.omega)

    def expand(self, y: State, state0: State) -> State:
        return State(y.pos, quat_normalize(y.quat), y.vel, y.omega)

    def coordinate_rates(self, y: State, rates: State) -> State:
        return rates

    def raw_quat_norm(self, y: State):
        return _quat_norm(y.quat)


def coordinates_for(scene):
    """The cheapest coordinates that describe the scene's motion exactly (no floor)."""
    if scene.joint is not None:
        return JOINT
    if all(type(f) is Gravity for f in scene.forces):
        return ROTATION
    return FREE
