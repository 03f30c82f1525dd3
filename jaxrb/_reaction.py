"""The joint reaction along a trajectory, in the components `jaxrb run` writes and plots.

The reaction O (N, world frame) is the force the joint exerts on the body, O = m a_C - F
(`jaxrb.joint_reaction`). For a `Hinge` it is also split in the plane of motion
(docs/theory.md, section 6), with `a` the world direction of the axis and d the
perpendicular from the axis to the mass centre C (rbar = |d|):

- theta (rad): the hinge angle, right-handed about `axis`, 0 at the first save (the initial
  attitude), continuous over full turns;
- e_n = -d / rbar: along the line from C towards the axis;
- e_t = a x d / rbar: the direction C moves in when theta increases;
- O_n = O . e_n (positive towards the axis), O_t = -O . e_t (positive against increasing
  theta), O_a = O . a (along the axis): O = O_n e_n - O_t e_t + O_a a.

O_n and O_t are NaN when C lies on the axis (there is no line from the axis to C).
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["PendulumRelease", "hinge_angle", "reaction_arrays", "released_pendulum"]

_REL = 1e-9  # relative tolerance of the checks that the closed form applies


def _np(x):
    return np.asarray(x, dtype=float)


def _rotate(quat, v):
    """Rotate body vectors v (..., 3) by unit quaternions (..., 4), scalar first (numpy)."""
    e0, e = quat[..., :1], quat[..., 1:]
    t = 2.0 * np.cross(e, v)
    return v + e0 * t + np.cross(e, t)


def hinge_angle(joint, quat) -> np.ndarray:
    """Hinge angle theta (rad, right-handed about the joint's axis) at each save.

    `quat`: (T, 4) unit quaternions (scalar first, body -> world); theta = 0 at quat[0] and
    is unwrapped, so it keeps counting over full turns.
    """
    q = _np(quat)
    q0 = q[0] * np.array([1.0, -1.0, -1.0, -1.0])  # conjugate of the first attitude
    # the relative rotation q0* (x) q(t) = (cos(theta/2), axis sin(theta/2)), body axes
    dq0 = q0[0] * q[:, 0] - q[:, 1:] @ q0[1:]
    dqv = q0[0] * q[:, 1:] + q[:, :1] * q0[1:] + np.cross(q0[1:], q[:, 1:])
    return np.unwrap(2.0 * np.arctan2(dqv @ _np(joint.axis), dq0))


def _hinge_frame(joint, quat):
    """World axis a, unit vectors e_n, e_t (T, 3) and rbar (T,; m) of a hinge at attitudes
    `quat` (T, 4; unit, scalar first, body -> world)."""
    quat = _np(quat)
    a = _rotate(quat, np.broadcast_to(_np(joint.axis), quat[:, 1:].shape))
    r = _rotate(quat, np.broadcast_to(-_np(joint.point), quat[:, 1:].shape))  # C - O
    d = r - np.sum(r * a, axis=-1, keepdims=True) * a
    rbar = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(rbar[:, None] > 0, d / rbar[:, None], np.nan)
    return a, -unit, np.cross(a, unit), rbar


def reaction_arrays(traj, scene) -> dict:
    """The joint reaction at each save time of an unbatched trajectory of a jointed scene.

    **Returns:** a dict of numpy arrays: `reaction` (T, 3; N, world frame) and
    `reaction_magnitude` (T,; N); for a `Hinge` also `joint_angle` (T,; rad) and
    `reaction_normal`, `reaction_tangential`, `reaction_axial` (T,; N), the O_n, O_t, O_a of
    the module docstring.
    """
    import jax

    import jaxrb

    force = _np(jax.vmap(lambda t, s: jaxrb.joint_reaction(scene, t, s))(traj.ts, traj.states))
    out = {"reaction": force, "reaction_magnitude": np.linalg.norm(force, axis=-1)}
    if isinstance(scene.joint, jaxrb.Hinge):
        a, e_n, e_t, _ = _hinge_frame(scene.joint, traj.states.quat)
        out["joint_angle"] = hinge_angle(scene.joint, traj.states.quat)
        out["reaction_normal"] = np.sum(force * e_n, axis=-1)
        out["reaction_tangential"] = -np.sum(force * e_t, axis=-1)
        out["reaction_axial"] = np.sum(force * a, axis=-1)
    return out


@dataclasses.dataclass(frozen=True)
class PendulumRelease:
    """A hinged body released from rest with its mass centre level with the axis.

    `mass` (kg), `rbar` (m, axis to mass centre), `k_O` (m, radius of gyration about the
    axis), `g` (m/s^2, |gravity|), `sign`: +1 if it falls towards increasing hinge angle,
    -1 if towards decreasing.
    """

    mass: float
    rbar: float
    k_O: float
    g: float
    sign: float

    def reaction(self, theta):
        """Closed-form (O_n, O_t) in N at hinge angles theta (rad), signs of the module docstring.

        Let phi = sign * theta, the angle of the line from the axis to C below the horizontal,
        growing as the body falls, and e_n (from C to the axis), e_t (towards increasing phi)
        the unit vectors of docs/theory.md, section 6. The moment of gravity about the axis
        gives m k_O^2 phi_ddot = m g rbar cos(phi); energy from rest at phi = 0 gives
        phi_dot^2 = 2 g rbar sin(phi) / k_O^2. Gravity's components are -m g sin(phi) on e_n
        and m g cos(phi) on e_t, and a_C = rbar phi_dot^2 e_n + rbar phi_ddot e_t, so
        m a_C = m g + O reads

            on e_n: m rbar phi_dot^2 = O_n - m g sin(phi),
                    O_n = m g (1 + 2 rbar^2 / k_O^2) sin(phi)   (along the line, towards O);
            on e_t: m rbar phi_ddot = m g cos(phi) - O_t,
                    O_t = m g (1 - rbar^2 / k_O^2) cos(phi)     (across it, against the fall).

        For sign = -1 the hinge's e_t is minus the direction of the fall, and sin(phi) =
        -sin(theta): both components come back multiplied by `sign`.
        """
        ratio = (self.rbar / self.k_O) ** 2
        mg = self.mass * self.g
        theta = _np(theta)
        return (
            self.sign * mg * (1.0 + 2.0 * ratio) * np.sin(theta),
            self.sign * mg * (1.0 - ratio) * np.cos(theta),
        )


def released_pendulum(scene, state0) -> PendulumRelease | None:
    """The closed form's parameters, or None when the scene is not such a pendulum.

    It applies to a `Hinge` under uniform gravity only (no other force), with the axis
    horizontal, the mass centre off the axis and level with it, at rest (checked to a
    relative 1e-9) in `state0`.
    """
    import jaxrb

    joint = scene.joint
    if not isinstance(joint, jaxrb.Hinge) or not scene.forces:
        return None
    if not all(isinstance(f, jaxrb.Gravity) for f in scene.forces):
        return None
    g = sum(_np(f.g) for f in scene.forces)
    quat = _np(state0.quat) / np.linalg.norm(_np(state0.quat))
    a, e_n, _, rbar = (x[0] for x in _hinge_frame(joint, quat[None]))
    g_norm = float(np.linalg.norm(g))
    if g_norm == 0 or rbar == 0:
        return None
    if abs(a @ g) > _REL * g_norm or abs(e_n @ g) > _REL * g_norm:
        return None
    axis = _np(joint.axis)
    if abs(_np(state0.omega) @ axis) > _REL * np.sqrt(g_norm / rbar):  # a hinge uses omega . axis
        return None
    body = scene.body
    J_O = _np(joint.inertia_about_point(body))
    mass = float(body.mass)
    # the moment of gravity about the axis, a . (d x m g) with d = -rbar e_n, sets the sign
    sign = 1.0 if a @ np.cross(-e_n, g) > 0 else -1.0
    return PendulumRelease(
        mass, float(rbar), float(np.sqrt(axis @ J_O @ axis / mass)), g_norm, sign
    )
