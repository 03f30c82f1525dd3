"""Exact torque-free motion of spherical, symmetric and asymmetric tops (docs/theory.md, section 5).

Body-frame angular velocity omega; quaternions scalar first (e0, e1, e2, e3) mapping body to
world. Euler's equations J omega_dot = -omega x J omega, q_dot = 1/2 q (x) (0, omega).
All functions take times `t` of any shape and return arrays with t's shape in front of the
trailing component axis. jittable, vmappable, differentiable (in t, omega0 and the inertia).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array, is_concrete
from .._quaternion import _safe_norm, quat_multiply, quat_rotate
from .._typing import Array, ArrayLike
from ._elliptic import _f_from_sncndn, ellipj_m1, ellipk_m1


def _rotvec_to_quat(theta: Array) -> Array:
    """exp(theta / 2) as a unit quaternion, AD-safe at theta = 0."""
    n = _safe_norm(theta, keepdims=True)
    half = 0.5 * n
    # sin(n/2) / n = 1/2 sinc(n / (2 pi)) (jnp.sinc is smooth at 0)
    return jnp.concatenate([jnp.cos(half), 0.5 * jnp.sinc(half / jnp.pi) * theta], axis=-1)


def _prep_t(t: ArrayLike, dtype) -> Array:
    t = jnp.asarray(t)
    if not jnp.issubdtype(t.dtype, jnp.floating):
        t = t.astype(dtype)
    return t


def _default_q0(q0, dtype):
    if q0 is None:
        return jnp.array([1.0, 0.0, 0.0, 0.0], dtype=dtype)
    return as_float_array(q0, "q0", (4,))


def spherical_top(t: ArrayLike, omega0: ArrayLike, q0: ArrayLike | None = None):
    """Torque-free spherical top (J = J1 * identity): omega is constant in body and world.

    **Arguments:**

    - `t`: times (s), any shape `T`.
    - `omega0`: body angular velocity (rad/s), shape (3,).
    - `q0`: initial attitude quaternion (body -> world), shape (4,); identity by default.

    **Returns:**

    `(omega, q)` with shapes `T + (3,)` and `T + (4,)`: omega(t) = omega0 and
    q(t) = q0 (x) exp(omega0 t / 2).
    """
    omega0 = as_float_array(omega0, "omega0", (3,))
    if omega0.ndim != 1:
        raise ValueError(f"omega0 must have shape (3,), got {omega0.shape}; vmap for batches")
    q0 = _default_q0(q0, omega0.dtype)
    t = _prep_t(t, omega0.dtype)
    omega = jnp.broadcast_to(omega0, t.shape + (3,))
    q = quat_multiply(q0, _rotvec_to_quat(t[..., None] * omega0))
    return omega, q


class SymmetricTopSolution(NamedTuple):
    """Exact torque-free symmetric top (J1 = J2, J3); every field has t's shape in front.

    - `omega`: body angular velocity (rad/s), `T + (3,)`.
    - `quat`: attitude q(t) (body -> world, scalar first), `T + (4,)`.
    - `angular_momentum`: K in body axes (J1 w1, J1 w2, J3 w3_0), `T + (3,)`.
    - `angular_momentum_norm`: |K| (constant), `T`.
    - `omega_norm`: |omega| (constant), `T`.
    - `gamma`: angle symmetry axis to K (rad), `T`.
    - `alpha`: angle symmetry axis to omega (rad), `T`.
    - `beta`: alpha - gamma, angle K to omega (signed, rad), `T`.
    - `body_rate`: lambda = (J1 - J3) w3_0 / J1 (rad/s): omega turns about e3 at -lambda in body.
    - `precession_rate`: |K| / J1 (rad/s): the body turns about the fixed world K at this rate.
    """

    omega: Array
    quat: Array
    angular_momentum: Array
    angular_momentum_norm: Array
    omega_norm: Array
    gamma: Array
    alpha: Array
    beta: Array
    body_rate: Array
    precession_rate: Array


def symmetric_top(
    t: ArrayLike, J1: ArrayLike, J3: ArrayLike, omega0: ArrayLike, q0: ArrayLike | None = None
) -> SymmetricTopSolution:
    """Torque-free symmetric top with principal moments (J1, J1, J3) about body axes (1, 2, 3).

    With lambda = (J1 - J3) w3_0 / J1 (docs/theory.md, section 5.2):
    w1 = w1_0 cos(lambda t) + w2_0 sin(lambda t), w2 = w2_0 cos(lambda t) - w1_0 sin(lambda t),
    w3 = w3_0, i.e. omega(t) = R_3(-lambda t) omega0 in body axes. The attitude is

        q(t) = exp(L t / (2 J1)) (x) q0 (x) exp(e3 lambda t / 2),

    with L = R(q0) J omega0 the (fixed) world angular momentum: a rotation about L at rate
    |L| / J1 composed with a body spin about the symmetry axis at rate lambda (derived from
    R^T R_dot = skew(omega); checked against numerical integration in the tests).

    **Arguments:**

    - `t`: times (s), any shape `T`.
    - `J1`, `J3`: transverse and axial principal moments (kg m^2), scalars.
    - `omega0`: initial body angular velocity (rad/s), shape (3,).
    - `q0`: initial attitude (body -> world), shape (4,); identity by default.

    **Returns:**

    A `SymmetricTopSolution`.
    """
    omega0 = as_float_array(omega0, "omega0", (3,))
    if omega0.ndim != 1:
        raise ValueError(f"omega0 must have shape (3,), got {omega0.shape}; vmap for batches")
    dtype = omega0.dtype
    J1 = jnp.asarray(J1, dtype=dtype)
    J3 = jnp.asarray(J3, dtype=dtype)
    if J1.ndim != 0 or J3.ndim != 0:
        raise ValueError("J1 and J3 must be scalars; vmap for batches")
    q0 = _default_q0(q0, dtype)
    t = _prep_t(t, dtype)
    w1, w2, w3 = omega0[0], omega0[1], omega0[2]
    lam = (J1 - J3) * w3 / J1
    c, s = jnp.cos(lam * t), jnp.sin(lam * t)
    o1 = w1 * c + w2 * s
    o2 = w2 * c - w1 * s
    o3 = jnp.broadcast_to(w3, t.shape)
    omega = jnp.stack([o1, o2, o3], axis=-1)
    K = jnp.stack([J1 * o1, J1 * o2, J3 * o3], axis=-1)
    w_tau = _safe_norm(omega0[:2])
    K_body0 = jnp.stack([J1 * w1, J1 * w2, J3 * w3])
    K_norm = _safe_norm(K_body0)
    w_norm = _safe_norm(omega0)
    gamma = jnp.arctan2(J1 * w_tau, J3 * w3)
    alpha = jnp.arctan2(w_tau, w3)
    L_world = quat_rotate(q0, K_body0)
    q_world = _rotvec_to_quat(t[..., None] * (L_world / J1))
    q_body = _rotvec_to_quat(t[..., None] * jnp.stack([0.0 * lam, 0.0 * lam, lam]))
    quat = quat_multiply(quat_multiply(q_world, q0), q_body)
    full = lambda x: jnp.broadcast_to(x, t.shape)  # noqa: E731
    return SymmetricTopSolution(
        omega=omega,
        quat=quat,
        angular_momentum=K,
        angular_momentum_norm=full(K_norm),
        omega_norm=full(w_norm),
        gamma=full(gamma),
        alpha=full(alpha),
        beta=full(alpha - gamma),
        body_rate=lam,
        precession_rate=K_norm / J1,
    )


class AsymmetricTopParams(NamedTuple):
    """Elliptic-function form of the torque-free asymmetric top, in SORTED principal axes.

    In the sorted, right-handed frame (I1 < I2 < I3; omega_s = S omega with a signed permutation
    S of determinant +1), with u = frequency * t + u0:
    regime "about axis 3" (L^2 >= 2 E I2): omega_s = (a1 cn u, a2 sn u, a3 dn u);
    regime "about axis 1" (L^2 < 2 E I2): omega_s = (a1 dn u, a2 sn u, a3 cn u).

    - `m`, `m1`: elliptic parameter and 1 - m (m1 computed from the invariants, no cancellation).
    - `frequency`: omega_p (rad/s, signed); `u0`: initial phase.
    - `amplitudes`: (a1, a2, a3) (signed); `about_axis3`: bool regime flag.
    - `perm`: S (3x3), omega_sorted = S omega.
    """

    m: Array
    m1: Array
    frequency: Array
    u0: Array
    amplitudes: Array
    about_axis3: Array
    perm: Array


def _check_inertia(inertia):
    inertia = as_float_array(inertia, "inertia", (3,))
    if is_concrete(inertia):
        v = np.asarray(inertia)
        if np.any(~np.isfinite(v)) or np.any(v <= 0):
            raise ValueError(f"inertia must hold three positive principal moments, got {v}")
        vs = np.sort(v, axis=-1)
        if np.any(np.diff(vs, axis=-1) <= 0):
            raise ValueError(
                "inertia: the asymmetric-top formulas need three distinct principal moments, "
                f"got {v}; use symmetric_top or spherical_top for equal moments"
            )
    return inertia


def _sorting_rotation(inertia: Array) -> Array:
    """Signed permutation S (det +1) with S diag(inertia) S^T = diag(sorted inertia)."""
    idx = jnp.argsort(inertia)
    P = jax.nn.one_hot(idx, 3, dtype=inertia.dtype)  # rows: P[i, idx[i]] = 1
    det = jnp.linalg.det(P)
    return P.at[2].multiply(det)


def asymmetric_top_params(inertia: ArrayLike, omega0: ArrayLike) -> AsymmetricTopParams:
    """The elliptic parameters of the torque-free asymmetric top (see `AsymmetricTopParams`).

    `inertia`: principal moments (3,) in any order (distinct); `omega0`: body omega at t = 0.
    """
    inertia = _check_inertia(inertia)
    omega0 = as_float_array(omega0, "omega0", (3,))
    if inertia.ndim != 1 or omega0.ndim != 1:
        raise ValueError("inertia and omega0 must have shape (3,); vmap for batches")
    S = _sorting_rotation(inertia)
    I1, I2, I3 = jnp.abs(S) @ inertia
    w1, w2, w3 = S @ omega0
    d21, d31, d32 = I2 - I1, I3 - I1, I3 - I2
    # Invariant combinations as sums of non-negative terms (no cancellation):
    P = I1 * d31 * w1**2 + I2 * d32 * w2**2  # 2 E I3 - L^2 >= 0
    Q = I2 * d21 * w2**2 + I3 * d31 * w3**2  # L^2 - 2 E I1 >= 0
    D = I3 * d32 * w3**2 - I1 * d21 * w1**2  # L^2 - 2 E I2 (sign picks the regime)
    about3 = D >= 0
    tiny = jnp.finfo(omega0.dtype).tiny
    Ps = jnp.maximum(P, tiny)
    Qs = jnp.maximum(Q, tiny)
    # regime 3: m = d21 P / (d32 Q), m1 = d31 D / (d32 Q)
    # regime 1: m = d32 Q / (d21 P), m1 = -d31 D / (d21 P)
    m_a = d21 * P / (d32 * Qs)
    m1_a = d31 * D / (d32 * Qs)
    m_b = d32 * Q / (d21 * Ps)
    m1_b = -d31 * D / (d21 * Ps)
    m = jnp.where(about3, m_a, m_b)
    m1 = jnp.clip(jnp.where(about3, m1_a, m1_b), 0.0, 1.0)
    # amplitudes (magnitudes)
    A1 = jnp.sqrt(P / (I1 * d31))
    A2_a = jnp.sqrt(P / (I2 * d32))
    A2_b = jnp.sqrt(Q / (I2 * d21))
    A3 = jnp.sqrt(Q / (I3 * d31))
    freq_a = jnp.sqrt(d32 * Q / (I1 * I2 * I3))
    freq_b = jnp.sqrt(d21 * P / (I1 * I2 * I3))
    # regime 3: w1 = A1 cn, w2 = A2 sn, w3 = s3 A3 dn, frequency sign = sign(w3)
    # regime 1: w1 = s1 A1 dn, w2 = A2 sn, w3 = A3 cn, frequency sign = sign(w1)
    s3 = jnp.where(w3 >= 0, 1.0, -1.0)
    s1 = jnp.where(w1 >= 0, 1.0, -1.0)
    amps = jnp.where(
        about3,
        jnp.stack([A1, A2_a, s3 * A3]),
        jnp.stack([s1 * A1, A2_b, A3]),
    )
    freq = jnp.where(about3, s3 * freq_a, s1 * freq_b)
    # initial phase: sn0 : cn0 from the (scaled) components, dn0^2 = m1 + m cn0^2
    y = w2 * jnp.sqrt(I2 * jnp.where(about3, d32, d21))
    x = jnp.where(about3, w1 * jnp.sqrt(I1 * d31), w3 * jnp.sqrt(I3 * d31))
    r2 = x * x + y * y
    ok = r2 > 0
    r = jnp.sqrt(jnp.where(ok, r2, 1.0))
    sn0 = jnp.where(ok, y / r, 0.0)
    cn0 = jnp.where(ok, x / r, 1.0)
    dn2 = m1 + m * cn0 * cn0
    K = ellipk_m1(jnp.maximum(m1, tiny))
    u0 = _f_from_sncndn(sn0, cn0, dn2, K)
    return AsymmetricTopParams(
        m=m, m1=m1, frequency=freq, u0=u0, amplitudes=amps, about_axis3=about3, perm=S
    )


def asymmetric_top(t: ArrayLike, inertia: ArrayLike, omega0: ArrayLike) -> Array:
    """Body angular velocity of the torque-free asymmetric top, exactly (Jacobi elliptic functions).

    Landau & Lifshitz, Mechanics, section 37; van Zon & Schofield, J. Comput. Phys. 225 (2007)
    145. The principal moments may come in any order (they must be distinct): they are sorted
    internally with a signed permutation of determinant +1 (a proper rotation of the body axes,
    so Euler's equations keep their form) and the result is rotated back. Both regimes
    (L^2 > 2 E I2: rotation about the largest axis; L^2 < 2 E I2: about the smallest) and
    arbitrary omega0 (signs and initial phase) are handled; near the separatrix m1 = 1 - m is
    computed from the invariants without cancellation.

    **Arguments:**

    - `t`: times (s), any shape `T`.
    - `inertia`: principal moments (I1, I2, I3) (kg m^2), shape (3,), distinct.
    - `omega0`: body angular velocity at t = 0 (rad/s), shape (3,).

    **Returns:**

    omega(t), shape `T + (3,)`, body frame.
    """
    p = asymmetric_top_params(inertia, omega0)
    t = _prep_t(t, p.m.dtype)
    u = p.frequency * t + p.u0
    sn, cn, dn = ellipj_m1(u, jnp.broadcast_to(p.m1, u.shape))
    a1, a2, a3 = p.amplitudes
    ws = jnp.where(
        p.about_axis3,
        jnp.stack([a1 * cn, a2 * sn, a3 * dn], axis=-1),
        jnp.stack([a1 * dn, a2 * sn, a3 * cn], axis=-1),
    )
    return ws @ p.perm  # omega = S^T omega_sorted


def flip_half_period(inertia: ArrayLike, omega0: ArrayLike) -> Array:
    """Time between successive sign changes of the intermediate-axis component, 2 K(m) / |omega_p|.

    (The Dzhanibekov flip half-period; infinite on the separatrix.) Arguments as
    `asymmetric_top`.
    """
    p = asymmetric_top_params(inertia, omega0)
    return 2.0 * ellipk_m1(p.m1) / jnp.abs(p.frequency)
