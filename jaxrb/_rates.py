"""Quaternion-rate relations (docs/theory.md, section 2.5).

Convention: q = (e0, e1, e2, e3), scalar first, a unit quaternion mapping body to world
(r_world = R(q) r_body). `omega_body` has components on the body-embedded axes, `omega_world`
on the world axes (omega_world = R(q) omega_body); rad/s. q_dot, q_ddot are the first and
second time derivatives of q (1/s, 1/s^2). All functions take leading batch axes.
"""

import jax.numpy as jnp

from ._checks import as_float_array
from ._quaternion import quat_multiply
from ._typing import Array, Float, Mat3, Quat, Vec3

Mat34 = Float[Array, "*batch 3 4"]


def _rows(rows):
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def quat_G(q: Quat) -> Mat34:
    """The 3x4 matrix G(q) = [[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]].

    G(q) p is the vector part of conj(q) (x) p; omega_body = 2 G(q) q_dot and
    q_dot = 1/2 G(q)^T omega_body for a unit q. G(p) p = 0 for every p.

    **Arguments:**

    - `q`: quaternion(s), shape (..., 4).

    **Returns:**

    G of shape (..., 3, 4).
    """
    q = as_float_array(q, "q", (4,))
    e0, e1, e2, e3 = jnp.moveaxis(q, -1, 0)
    return _rows([[-e1, e0, e3, -e2], [-e2, -e3, e0, e1], [-e3, e2, -e1, e0]])


def quat_E(q: Quat) -> Mat34:
    """The 3x4 matrix E(q) = [[-e1, e0, -e3, e2], [-e2, e3, e0, -e1], [-e3, -e2, e1, e0]].

    E(q) p is the vector part of p (x) conj(q); omega_world = 2 E(q) q_dot, and
    R(q) = E(q) G(q)^T for a unit q.

    **Arguments:**

    - `q`: quaternion(s), shape (..., 4).

    **Returns:**

    E of shape (..., 3, 4).
    """
    q = as_float_array(q, "q", (4,))
    e0, e1, e2, e3 = jnp.moveaxis(q, -1, 0)
    return _rows([[-e1, e0, -e3, e2], [-e2, e3, e0, -e1], [-e3, -e2, e1, e0]])


def _matvec(M, v):
    return jnp.einsum("...ij,...j->...i", M, v)


def _q_and(q, other, name):
    q = as_float_array(q, "q", (4,))
    other = as_float_array(other, name, (4,))
    return q, other


def omega_body_from_quat_rate(q: Quat, q_dot: Quat) -> Vec3:
    """Body-frame angular velocity omega_body = 2 G(q) q_dot (rad/s).

    **Arguments:**

    - `q`: unit quaternion(s), body -> world, shape (..., 4).
    - `q_dot`: dq/dt, shape (..., 4).

    **Returns:**

    omega_body of shape (..., 3), components on the body axes.
    """
    q, q_dot = _q_and(q, q_dot, "q_dot")
    return 2 * _matvec(quat_G(q), q_dot)


def omega_world_from_quat_rate(q: Quat, q_dot: Quat) -> Vec3:
    """World-frame angular velocity omega_world = 2 E(q) q_dot = R(q) omega_body (rad/s).

    **Arguments:**

    - `q`: unit quaternion(s), body -> world, shape (..., 4).
    - `q_dot`: dq/dt, shape (..., 4).

    **Returns:**

    omega_world of shape (..., 3), components on the world axes.
    """
    q, q_dot = _q_and(q, q_dot, "q_dot")
    return 2 * _matvec(quat_E(q), q_dot)


def angular_acceleration_from_quat(q: Quat, q_ddot: Quat) -> Vec3:
    """Body-frame angular acceleration d(omega_body)/dt = 2 G(q) q_ddot (rad/s^2).

    Differentiating omega_body = 2 G(q) q_dot gives 2 G(q_dot) q_dot + 2 G(q) q_ddot, and
    G(p) p = 0 for every p (G is linear in its argument and its rows are orthogonal to it), so
    the first term vanishes. The starting identity omega_body = 2 G(q) q_dot holds for a unit
    quaternion (|q| = 1 along the motion, i.e. q . q_dot = 0), so q, q_ddot must come from a
    unit-norm trajectory q(t). Note this is the derivative of the body-frame components, which
    equals R^T d(omega_world)/dt.

    **Arguments:**

    - `q`: unit quaternion(s), body -> world, shape (..., 4).
    - `q_ddot`: d^2 q / dt^2, shape (..., 4).

    **Returns:**

    d(omega_body)/dt of shape (..., 3).
    """
    q, q_ddot = _q_and(q, q_ddot, "q_ddot")
    return 2 * _matvec(quat_G(q), q_ddot)


def _pure(v):
    return jnp.concatenate([jnp.zeros_like(v[..., :1]), v], axis=-1)


def quat_rate(q: Quat, omega_body: Vec3) -> Quat:
    """q_dot = 1/2 q (x) (0, omega_body): kinematics of a body-frame angular velocity.

    **Arguments:**

    - `q`: quaternion(s), body -> world, shape (..., 4).
    - `omega_body`: angular velocity on the body axes (rad/s), shape (..., 3).

    **Returns:**

    q_dot of shape (..., 4) (= 1/2 G(q)^T omega_body for a unit q).
    """
    q = as_float_array(q, "q", (4,))
    omega_body = as_float_array(omega_body, "omega_body", (3,))
    return 0.5 * quat_multiply(q, _pure(omega_body))


def quat_rate_world(q: Quat, omega_world: Vec3) -> Quat:
    """q_dot = 1/2 (0, omega_world) (x) q: kinematics of a world-frame angular velocity.

    **Arguments:**

    - `q`: quaternion(s), body -> world, shape (..., 4).
    - `omega_world`: angular velocity on the world axes (rad/s), shape (..., 3).

    **Returns:**

    q_dot of shape (..., 4) (= 1/2 E(q)^T omega_world for a unit q).
    """
    q = as_float_array(q, "q", (4,))
    omega_world = as_float_array(omega_world, "omega_world", (3,))
    return 0.5 * quat_multiply(_pure(omega_world), q)


def angular_velocity_matrix(R: Mat3, R_dot: Mat3) -> Mat3:
    """Body-frame angular velocity matrix Omega = R^T R_dot = skew(omega_body).

    **Arguments:**

    - `R`: rotation matrix (matrices), body -> world, shape (..., 3, 3).
    - `R_dot`: dR/dt, shape (..., 3, 3).

    **Returns:**

    Omega of shape (..., 3, 3); skew-symmetric when R is a rotation and R_dot its derivative.
    """
    R = as_float_array(R, "R", (3, 3))
    R_dot = as_float_array(R_dot, "R_dot", (3, 3))
    return jnp.swapaxes(R, -1, -2) @ R_dot


def omega_from_angular_velocity_matrix(Omega: Mat3) -> Vec3:
    """The vee map: omega with skew(omega) = Omega.

    Uses the skew-symmetric part, omega = 1/2 (O21 - O12, O02 - O20, O10 - O01), which is
    exact for a skew-symmetric Omega and the least-squares answer otherwise (e.g. for an
    Omega built from finite differences).

    **Arguments:**

    - `Omega`: shape (..., 3, 3).

    **Returns:**

    omega of shape (..., 3).
    """
    W = as_float_array(Omega, "Omega", (3, 3))
    return 0.5 * jnp.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )
