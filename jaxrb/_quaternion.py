"""Unit quaternions (Euler parameters) and rotation matrices.

Convention: q = (e0, e1, e2, e3), scalar first, e0 = cos(phi/2), (e1, e2, e3) = v sin(phi/2)
for a rotation by phi about the unit axis v. q maps body to world: r_world = R(q) r_body.
All functions accept leading batch axes and are jit/vmap/grad safe.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import as_computed, as_float_array, is_concrete
from ._typing import Float, Mat3, Quat, Vec3


def quat_identity(dtype=None) -> Quat:
    """The identity rotation (1, 0, 0, 0)."""
    return jnp.array([1.0, 0.0, 0.0, 0.0], dtype=dtype)


def quat_multiply(p: Quat, q: Quat) -> Quat:
    """Hamilton product p (x) q (scalar first): rotate by q, then by p."""
    p = as_float_array(p, "p", (4,))
    q = as_float_array(q, "q", (4,))
    p0, p1, p2, p3 = jnp.moveaxis(p, -1, 0)
    q0, q1, q2, q3 = jnp.moveaxis(q, -1, 0)
    return jnp.stack(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ],
        axis=-1,
    )


def quat_conjugate(q: Quat) -> Quat:
    """Conjugate (e0, -e1, -e2, -e3); the inverse rotation for a unit quaternion."""
    q = as_float_array(q, "q", (4,))
    return q * jnp.array([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)


def unit_vector(x):
    """x / |x| along the last axis, exact for any finite non-zero length (no overflow of
    |x|^2 above ~1e154 or underflow below ~1e-154): x is first divided by its largest
    entry, in two halves (XLA may divide by multiplying with the reciprocal, and 1/1e308 is
    subnormal, which the CPU flushes to zero). NaN for a zero vector."""
    scale = jax.lax.stop_gradient(jnp.max(jnp.abs(x), axis=-1, keepdims=True))
    half = jnp.sqrt(jnp.where(scale > 0, scale, 1.0))
    scaled = x / half / half
    return scaled / jnp.linalg.norm(scaled, axis=-1, keepdims=True)


def require_nonzero(q, name: str) -> None:
    """Raise a ValueError naming `name` if a concrete quaternion has zero norm."""
    if is_concrete(q) and np.any(np.all(as_computed(q) == 0, axis=-1)):
        raise ValueError(f"{name} has zero norm: it is no attitude")


def quat_normalize(q: Quat) -> Quat:
    """q / |q|, for any finite non-zero norm (1e-300 to 1e300 in float64).

    A zero quaternion raises a ValueError when concrete and gives NaN under jit.
    """
    q = as_float_array(q, "q", (4,))
    require_nonzero(q, "q")
    return unit_vector(q)


def quat_to_matrix(q: Quat) -> Mat3:
    """Rotation matrix R(q) = (2 e0^2 - 1) I + 2 e e^T + 2 e0 skew(e) (body -> world).

    `q` is assumed unit norm (the classical expanded form); normalise first if unsure.
    """
    q = as_float_array(q, "q", (4,))
    e0, e1, e2, e3 = jnp.moveaxis(q, -1, 0)
    r00 = 2 * (e0 * e0 + e1 * e1) - 1
    r11 = 2 * (e0 * e0 + e2 * e2) - 1
    r22 = 2 * (e0 * e0 + e3 * e3) - 1
    r01 = 2 * (e1 * e2 - e0 * e3)
    r10 = 2 * (e1 * e2 + e0 * e3)
    r02 = 2 * (e1 * e3 + e0 * e2)
    r20 = 2 * (e1 * e3 - e0 * e2)
    r12 = 2 * (e2 * e3 - e0 * e1)
    r21 = 2 * (e2 * e3 + e0 * e1)
    return jnp.stack(
        [
            jnp.stack([r00, r01, r02], axis=-1),
            jnp.stack([r10, r11, r12], axis=-1),
            jnp.stack([r20, r21, r22], axis=-1),
        ],
        axis=-2,
    )


def matrix_to_quat(R: Mat3) -> Quat:
    """Unit quaternion of a rotation matrix, with e0 >= 0.

    Shepperd's method: of the four algebraically equivalent formulas the one with the largest
    pivot (e0^2, e1^2, e2^2 or e3^2) is used, so every branch is well conditioned. Gradient
    safe: the square roots of the unused branches are guarded.
    """
    R = as_float_array(R, "R", (3, 3))
    r00, r11, r22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    trace = r00 + r11 + r22
    # 4 e_k^2 for k = 0..3
    pivots = jnp.stack(
        [1 + trace, 1 + 2 * r00 - trace, 1 + 2 * r11 - trace, 1 + 2 * r22 - trace], axis=-1
    )
    k = jnp.argmax(pivots, axis=-1)
    # The selected pivot is >= 1 for a rotation matrix, so sqrt is safe there; guard the rest.
    s = 2 * jnp.sqrt(jnp.maximum(jnp.max(pivots, axis=-1), 0.25))  # = 4 |e_k|
    d21, d02, d10 = (
        R[..., 2, 1] - R[..., 1, 2],
        R[..., 0, 2] - R[..., 2, 0],
        R[..., 1, 0] - R[..., 0, 1],
    )
    a21, a02, a10 = (
        R[..., 2, 1] + R[..., 1, 2],
        R[..., 0, 2] + R[..., 2, 0],
        R[..., 1, 0] + R[..., 0, 1],
    )
    candidates = jnp.stack(
        [
            jnp.stack([s / 4, d21 / s, d02 / s, d10 / s], axis=-1),
            jnp.stack([d21 / s, s / 4, a10 / s, a02 / s], axis=-1),
            jnp.stack([d02 / s, a10 / s, s / 4, a21 / s], axis=-1),
            jnp.stack([d10 / s, a02 / s, a21 / s, s / 4], axis=-1),
        ],
        axis=-2,
    )
    q = jnp.take_along_axis(candidates, k[..., None, None], axis=-2)[..., 0, :]
    q = jnp.where(q[..., :1] < 0, -q, q)
    return q / jnp.linalg.norm(q, axis=-1, keepdims=True)


def quat_rotate(q: Quat, v: Vec3) -> Vec3:
    """R(q) v: a body-frame vector expressed in the world frame."""
    q = as_float_array(q, "q", (4,))
    v = as_float_array(v, "v", (3,))
    e0 = q[..., :1]
    e = q[..., 1:]
    t = 2 * jnp.cross(e, v)
    return v + e0 * t + jnp.cross(e, t)


def _safe_norm(x, axis=-1, keepdims=False):
    """|x| with a zero (not NaN) gradient at x = 0 (the double-where trick). Over a last axis
    of a few components the squares are added one by one: elementwise work, which XLA fuses
    with what comes before and after, where a sum is a reduction kernel of its own."""
    if axis in (-1, x.ndim - 1) and 1 <= x.shape[-1] <= 4:
        sq = x[..., 0] * x[..., 0]
        for i in range(1, x.shape[-1]):
            sq = sq + x[..., i] * x[..., i]
        sq = sq[..., None] if keepdims else sq
    else:
        sq = jnp.sum(x * x, axis=axis, keepdims=keepdims)
    nonzero = sq > 0
    return jnp.where(nonzero, jnp.sqrt(jnp.where(nonzero, sq, 1.0)), 0.0)


def axis_angle_to_quat(axis: Vec3, angle) -> Quat:
    """Quaternion of a rotation by `angle` (rad) about `axis` (normalised here; any length > 0)."""
    axis = as_float_array(axis, "axis", (3,))
    angle = jnp.asarray(angle, dtype=axis.dtype)
    n = _safe_norm(axis, keepdims=True)
    unit = axis / jnp.where(n > 0, n, 1.0)
    half = 0.5 * angle[..., None]
    return jnp.concatenate([jnp.cos(half), jnp.sin(half) * unit], axis=-1)


def quat_to_axis_angle(q: Quat) -> tuple[Vec3, Float]:
    """(unit axis, angle in [0, pi]) of a unit quaternion; axis (1, 0, 0) at zero rotation.

    Gradient safe at zero rotation (the angle's gradient there is zero, not NaN).
    """
    q = as_float_array(q, "q", (4,))
    q = jnp.where(q[..., :1] < 0, -q, q)
    s = _safe_norm(q[..., 1:])
    angle = 2 * jnp.arctan2(s, q[..., 0])
    small = s < 1e-30
    default = jnp.zeros_like(q[..., 1:]).at[..., 0].set(1.0)
    axis = jnp.where(small[..., None], default, q[..., 1:] / jnp.where(small, 1.0, s)[..., None])
    return axis, angle


def quat_to_rotvec(q: Quat) -> Vec3:
    """Rotation vector angle * axis (rad), angle in [0, pi]."""
    axis, angle = quat_to_axis_angle(q)
    return axis * angle[..., None]


def quat_geodesic_angle(p: Quat, q: Quat):
    """Angle (rad, in [0, pi]) of the rotation taking attitude p to attitude q."""
    p = as_float_array(p, "p", (4,))
    q = as_float_array(q, "q", (4,))
    dot = jnp.abs(jnp.sum(p * q, axis=-1))
    s = _safe_norm(quat_multiply(quat_conjugate(p), q)[..., 1:])
    return 2 * jnp.arctan2(s, dot)


def skew(v: Vec3) -> Mat3:
    """skew(v) w = v x w."""
    v = as_float_array(v, "v", (3,))
    x, y, z = jnp.moveaxis(v, -1, 0)
    zero = jnp.zeros_like(x)
    return jnp.stack(
        [
            jnp.stack([zero, -z, y], axis=-1),
            jnp.stack([z, zero, -x], axis=-1),
            jnp.stack([-y, x, zero], axis=-1),
        ],
        axis=-2,
    )
