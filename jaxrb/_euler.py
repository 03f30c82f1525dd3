"""Euler angles for the 12 rotation sequences, to and from rotation matrices and quaternions.

A sequence "abc" (a, b, c in {1, 2, 3} = body axes xi, eta, zeta) with angles (phi1, phi2, phi3)
in rad means successive rotations about the body-embedded (moving) axes:

    R = R_a(phi1) R_b(phi2) R_c(phi3),

with the elementary rotations R_1, R_2, R_3 of docs/theory.md, section 2.1. R maps body to world
(r_world = R r_body). This equals scipy's `Rotation.from_euler(seq, angles)` with `seq` the
uppercase (intrinsic) letters, e.g. "313" -> "ZXZ". Classical Euler angles (psi, theta, phi) are
"313".

Ranges returned by `matrix_to_euler` / `quat_to_euler`: phi1, phi3 in (-pi, pi]; phi2 in
[0, pi] for the proper sequences (a == c: 121 131 212 232 313 323) and in [-pi/2, pi/2] for the
Tait-Bryan sequences (123 132 213 231 312 321).

Singularities (gimbal lock): proper sequences at phi2 in {0, pi}, Tait-Bryan sequences at
phi2 = +-pi/2. There only phi1 + phi3 (proper at 0, Tait-Bryan at +pi/2 up to a sign given by
the sequence) or phi1 - phi3 is determined; the conversion then returns phi3 = 0 and puts the
determined combination into phi1.

Method: every sequence is reduced exactly (by a signed permutation of the quaternion's vector
part) to "121" or "123", whose angles are read off the quaternion with half-angle atan2 forms
(the approach of Bernardes & Viollet, PLoS ONE 17(11), 2022): the middle angle is
2 atan2(|u|, |v|) for two 2-vectors u, v of quaternion components, and phi1, phi3 are sums and
differences of two half-angles. Near a singularity the well-determined combination comes from
O(1) components and the ill-determined one multiplies a vanishing factor, so the angles
reproduce R to working precision arbitrarily close to gimbal lock.
"""

import math

import jax.numpy as jnp

from ._checks import as_float_array
from ._quaternion import _safe_norm, matrix_to_quat, require_nonzero, unit_vector
from ._typing import Array, Float, Mat3, Quat, Vec3

SEQUENCES = ("121", "123", "131", "132", "212", "213", "231", "232", "312", "313", "321", "323")

# Snapping tolerance for matrix_to_euler, in units of the dtype's machine epsilon: attitudes
# whose middle angle lies this close to its singular value are reported with phi3 = 0.
# Snapping an attitude at distance d from the singularity changes R by about 2 d, so this is
# kept at a few ulps (the rounding noise of an exactly singular input is ~1-4 eps).
_SNAP_EPS = 64.0


def _check_seq(seq) -> str:
    if not isinstance(seq, str) or seq not in SEQUENCES:
        raise ValueError(
            f"seq must be one of the 12 Euler sequence strings {', '.join(SEQUENCES)}; got {seq!r}"
        )
    return seq


def _parity(i: int, j: int, k: int) -> int:
    """+1 if (i, j, k) is a cyclic permutation of (0, 1, 2), -1 otherwise."""
    return 1 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1


def _seq_info(seq: str) -> tuple[int, int, int, bool, int]:
    """(i, j, k3, proper, eps): axes of the canonical frame and the parity sign.

    The signed permutation P with P e_0 = e_i, P e_1 = e_j, P e_2 = eps e_k3 is a proper
    rotation; R_i = P R_1 P^T, R_j = P R_2 P^T, and for Tait-Bryan R_k3(phi) = P R_3(eps phi) P^T.
    """
    i, j, k = (int(ch) - 1 for ch in seq)
    proper = i == k
    k3 = 3 - i - j
    return i, j, k3, proper, _parity(i, j, k3)


def _wrap(x):
    """Wrap an angle to (-pi, pi]."""
    two_pi = 2 * math.pi
    y = x - two_pi * jnp.ceil((x - math.pi) / two_pi)
    # rounding can land one ulp outside; two_pi = 2 * float(pi) exactly, so these are exact
    y = jnp.where(y <= -math.pi, y + two_pi, y)
    return jnp.where(y > math.pi, y - two_pi, y)


def _safe_atan2(y, x, ok):
    """atan2(y, x) where `ok`, else 0; the double-where trick keeps gradients finite."""
    y_safe = jnp.where(ok, y, 0.0)
    x_safe = jnp.where(ok, x, 1.0)
    return jnp.where(ok, jnp.arctan2(y_safe, x_safe), 0.0)


def _hypot(x, y):
    """sqrt(x^2 + y^2) with a zero (not NaN) gradient at the origin."""
    return _safe_norm(jnp.stack([x, y], axis=-1))


def _canonical(q: Array, seq: str):
    """Half-angle decomposition of q for `seq`.

    Returns (s0, s1, d0, d1, hs, hd, proper, eps) such that, with sigma = atan2(s1, s0) and
    delta = atan2(d1, d0), the canonical angles are phi1 = sigma + delta, phi3' = sigma - delta;
    hs = |(s0, s1)|, hd = |(d0, d1)|; the middle angle is 2 atan2(hd, hs) for proper sequences
    and 2 atan2(hs, hd) - pi/2 for Tait-Bryan ones.
    """
    i, j, k3, proper, eps = _seq_info(seq)
    w = q[..., 0]
    x = q[..., 1 + i]
    y = q[..., 1 + j]
    z = eps * q[..., 1 + k3]
    if proper:
        # q = (cos(b/2) cos(sig), cos(b/2) sin(sig), sin(b/2) cos(del), sin(b/2) sin(del))
        s0, s1, d0, d1 = w, x, y, z
    else:
        # q0 +- q2 = (cos(b/2) +- sin(b/2)) cos((a +- c)/2), q1 +- q3 likewise with sin
        s0, s1, d0, d1 = w + y, x + z, w - y, x - z
    return s0, s1, d0, d1, _hypot(s0, s1), _hypot(d0, d1), proper, eps


def _middle_and_distance(hs, hd, proper):
    if proper:
        phi2 = 2 * jnp.arctan2(hd, hs)
    else:
        phi2 = 2 * jnp.arctan2(hs, hd) - math.pi / 2
    # distance to the nearest singular value of phi2, accurate for tiny distances
    dist = 2 * jnp.arctan2(jnp.minimum(hs, hd), jnp.maximum(hs, hd))
    return phi2, dist


def _check_seq_and_quat(q, seq, name):
    seq = _check_seq(seq)
    return as_float_array(q, name, (4,)), seq


def quat_to_euler(q: Quat, seq: str) -> Vec3:
    """Euler angles (phi1, phi2, phi3) in rad of the attitude q for the sequence `seq`.

    **Arguments:**

    - `q`: quaternion(s) (e0, e1, e2, e3), scalar first, mapping body to world, shape
      (..., 4), of any finite non-zero norm (it is rescaled first). A zero quaternion is no
      attitude: a ValueError when concrete, NaN angles under jit. (XLA on a CPU flushes
      subnormal numbers, below 2.2e-308 in float64, to zero: a component that small is
      read as 0 before the rescaling.)
    - `seq`: one of `jaxrb.EULER_SEQUENCES` ("121", ..., "323").

    **Returns:**

    Angles of shape (..., 3) with R(q) = R_a(phi1) R_b(phi2) R_c(phi3); ranges and the
    convention at singular attitudes (phi3 = 0) as in `matrix_to_euler`.
    """
    q, seq = _check_seq_and_quat(q, seq, "q")
    require_nonzero(q, "q")
    q = unit_vector(q)
    s0, s1, d0, d1, hs, hd, proper, eps = _canonical(q, seq)
    phi2, dist = _middle_and_distance(hs, hd, proper)
    tol = _SNAP_EPS * jnp.finfo(q.dtype).eps
    singular = dist <= tol
    # Which half-angle is determined at the singularity: sigma where hd -> 0, delta where hs -> 0.
    sigma_lost = hs < hd
    delta_lost = ~sigma_lost
    sigma = _safe_atan2(s1, s0, ~(singular & sigma_lost))
    delta = _safe_atan2(d1, d0, ~(singular & delta_lost))
    phi1_reg = sigma + delta
    phi3_reg = sigma - delta
    phi1_sing = 2 * jnp.where(sigma_lost, delta, sigma)
    phi1 = jnp.where(singular, phi1_sing, phi1_reg)
    phi3 = jnp.where(singular, 0.0, phi3_reg)
    if not proper:
        phi3 = eps * phi3
    angles = jnp.stack([_wrap(phi1), phi2, _wrap(phi3)], axis=-1)
    return jnp.where(jnp.isnan(q[..., :1]), jnp.nan, angles)


def matrix_to_euler(R: Mat3, seq: str) -> Vec3:
    """Euler angles (phi1, phi2, phi3) in rad of a rotation matrix for the sequence `seq`.

    R = R_a(phi1) R_b(phi2) R_c(phi3), rotations about the body-embedded (moving) axes; R maps
    body to world. Computed through the quaternion of R (Shepperd's method) and half-angle
    atan2 forms, so it is accurate in every branch, including within 1e-10 rad of gimbal lock.

    **Arguments:**

    - `R`: rotation matrix (matrices), shape (..., 3, 3).
    - `seq`: one of `jaxrb.EULER_SEQUENCES` ("121", ..., "323").

    **Returns:**

    Angles of shape (..., 3): phi1, phi3 in (-pi, pi]; phi2 in [0, pi] for proper sequences
    (a == c), in [-pi/2, pi/2] for Tait-Bryan sequences. At a singular attitude (phi2 within a
    few ulps of 0 or pi, resp. +-pi/2) phi3 = 0 and phi1 carries the determined combination
    phi1 +- phi3, so the angles still reproduce R. Use `is_euler_singular` /
    `euler_singularity_distance` to ask how close an attitude is to gimbal lock.

    Gradients are finite everywhere (also at the identity and exactly at gimbal lock) and
    correct at regular attitudes.
    """
    seq = _check_seq(seq)
    R = as_float_array(R, "R", (3, 3))
    return quat_to_euler(matrix_to_quat(R), seq)


def _elementary_matrix(axis: int, angle):
    """R_axis(angle) as nested lists; None marks a structural 0 and the int 1 a structural 1."""
    c = jnp.cos(angle)
    s = jnp.sin(angle)
    if axis == 0:
        return [[1, None, None], [None, c, -s], [None, s, c]]
    if axis == 1:
        return [[c, None, s], [None, 1, None], [-s, None, c]]
    return [[c, -s, None], [s, c, None], [None, None, 1]]


def _times(x, y):
    if x is None or y is None:
        return None
    if isinstance(x, int):
        return y
    if isinstance(y, int):
        return x
    return x * y


def _plus(x, y):
    if x is None:
        return y
    if y is None:
        return x
    return x + y


def _sparse_matmul(A, B):
    """Product of 3x3 nested lists, skipping structural zeros and ones at trace time."""
    out = []
    for i in range(3):
        row = []
        for j in range(3):
            acc = None
            for k in range(3):
                acc = _plus(acc, _times(A[i][k], B[k][j]))
            row.append(acc)
        out.append(row)
    return out


def _elementary_quat(axis: int, angle):
    """q_axis(angle) as a list of 4 components; absent (structurally zero) ones are None."""
    half = 0.5 * angle
    parts = [jnp.cos(half), None, None, None]
    parts[1 + axis] = jnp.sin(half)
    return parts


def _sparse_product(p, q):
    """Hamilton product of component lists with structural zeros (None) skipped at trace time.

    Keeps the traced program (and its derivatives) small: the product of three elementary
    quaternions needs a fraction of the multiplications of the dense product.
    """
    # (sign, i, j) triples of p_i q_j contributing to each component of p (x) q
    table = (
        ((1, 0, 0), (-1, 1, 1), (-1, 2, 2), (-1, 3, 3)),
        ((1, 0, 1), (1, 1, 0), (1, 2, 3), (-1, 3, 2)),
        ((1, 0, 2), (-1, 1, 3), (1, 2, 0), (1, 3, 1)),
        ((1, 0, 3), (1, 1, 2), (-1, 2, 1), (1, 3, 0)),
    )
    out = []
    for terms in table:
        acc = None
        for sign, i, j in terms:
            if p[i] is None or q[j] is None:
                continue
            t = p[i] * q[j]
            acc = (t if sign > 0 else -t) if acc is None else (acc + t if sign > 0 else acc - t)
        out.append(acc)
    return out


def euler_to_matrix(angles: Vec3, seq: str) -> Mat3:
    """Rotation matrix R = R_a(phi1) R_b(phi2) R_c(phi3) of Euler angles (body -> world).

    **Arguments:**

    - `angles`: (phi1, phi2, phi3) in rad, shape (..., 3). Any values (no range restriction).
    - `seq`: one of `jaxrb.EULER_SEQUENCES`; "abc" means rotations about the body-embedded
      (moving) axes a, then b, then c (1, 2, 3 = xi, eta, zeta).

    **Returns:**

    R of shape (..., 3, 3), r_world = R r_body.
    """
    seq = _check_seq(seq)
    angles = as_float_array(angles, "angles", (3,))
    a, b, c = (int(ch) - 1 for ch in seq)
    Ra = _elementary_matrix(a, angles[..., 0])
    Rb = _elementary_matrix(b, angles[..., 1])
    Rc = _elementary_matrix(c, angles[..., 2])
    R = _sparse_matmul(_sparse_matmul(Ra, Rb), Rc)
    # every entry of a product of three elementary rotations about axes a != b != c depends on
    # an angle, so no structural constant survives; guard anyway for clarity
    zero = jnp.zeros_like(angles[..., 0])
    R = [[zero if x is None else (zero + 1 if isinstance(x, int) else x) for x in r] for r in R]
    return jnp.stack([jnp.stack(r, axis=-1) for r in R], axis=-2)


def euler_to_quat(angles: Vec3, seq: str) -> Quat:
    """Unit quaternion q = q_a(phi1) (x) q_b(phi2) (x) q_c(phi3) of Euler angles.

    **Arguments:**

    - `angles`: (phi1, phi2, phi3) in rad, shape (..., 3).
    - `seq`: one of `jaxrb.EULER_SEQUENCES`.

    **Returns:**

    q = (e0, e1, e2, e3), scalar first, body -> world, shape (..., 4), with
    quat_to_matrix(q) == euler_to_matrix(angles, seq). The sign is not normalised (e0 may be
    negative), so the map is smooth in the angles.
    """
    seq = _check_seq(seq)
    angles = as_float_array(angles, "angles", (3,))
    a, b, c = (int(ch) - 1 for ch in seq)
    qa = _elementary_quat(a, angles[..., 0])
    qb = _elementary_quat(b, angles[..., 1])
    qc = _elementary_quat(c, angles[..., 2])
    parts = _sparse_product(_sparse_product(qa, qb), qc)
    zero = jnp.zeros_like(angles[..., 0])
    return jnp.stack([zero if x is None else x for x in parts], axis=-1)


def euler_singularity_distance(R: Mat3, seq: str) -> Float[Array, "*batch"]:
    """Distance (rad) of the middle Euler angle phi2 of R from its nearest singular value.

    Singular values: phi2 in {0, pi} for the proper sequences (121 131 212 232 313 323),
    phi2 = +-pi/2 for the Tait-Bryan sequences (123 132 213 231 312 321). The result is in
    [0, pi/2] and has full relative accuracy for tiny distances (it is computed as
    2 atan2(small, large) of quaternion components, not as a difference of angles).

    **Arguments:**

    - `R`: rotation matrix (matrices), shape (..., 3, 3), body -> world.
    - `seq`: one of `jaxrb.EULER_SEQUENCES`.

    **Returns:**

    Distance of shape (...,).
    """
    seq = _check_seq(seq)
    R = as_float_array(R, "R", (3, 3))
    *_, hs, hd, proper, _ = _canonical(matrix_to_quat(R), seq)
    return _middle_and_distance(hs, hd, proper)[1]


def is_euler_singular(R: Mat3, seq: str, tol: float = 1e-9) -> Array:
    """Whether R is within `tol` rad of gimbal lock for the sequence `seq`.

    True where phi2 is within `tol` of 0 or pi (proper sequences, a == c) or of +-pi/2
    (Tait-Bryan sequences). There only phi1 + phi3 or phi1 - phi3 is determined by R, and
    Euler-angle rates diverge; `matrix_to_euler` itself stays exact (it sets phi3 = 0 only
    within a few ulps of the singularity).

    **Arguments:**

    - `R`: rotation matrix (matrices), shape (..., 3, 3), body -> world.
    - `seq`: one of `jaxrb.EULER_SEQUENCES`.
    - `tol`: distance threshold in rad (default 1e-9).

    **Returns:**

    Boolean array of shape (...,).
    """
    return euler_singularity_distance(R, seq) <= tol
