"""Inertia tensors (kg m^2), about the mass centre in body axes unless stated.

Convention (docs/theory.md, section 3.1): J = integral of (r.r 1 - r r^T) dm, so the
products of inertia J_ij = integral of x_i x_j dm (i != j) enter with a minus sign off the
diagonal: J = [[Jxx, -Jxy, -Jxz], [-Jxy, Jyy, -Jyz], [-Jxz, -Jyz, Jzz]].

Every function broadcasts over leading batch axes (a mass of shape (...) with a tensor of shape
(..., 3, 3)) and is jit/vmap/grad safe. Validity checks: `inertia_violations` (traceable flags),
`is_valid_inertia` (traceable bool) and `check_inertia` (raises on concrete input).
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ._checks import as_computed, as_float_array, is_concrete
from ._linalg import symmetric_eigenvalues3
from ._typing import Array, ArrayLike, Float, Mat3

__all__ = [
    "InertiaViolations",
    "check_inertia",
    "cube",
    "cuboid",
    "cylinder",
    "from_products",
    "inertia_violations",
    "is_valid_inertia",
    "parallel_axis",
    "principal",
    "rod",
    "rotate",
    "sphere",
]


def _floats(*xs) -> list[Array]:
    """Float arrays of one common dtype (Python scalars do not upcast float32 arrays)."""
    arrs = [jnp.asarray(x) for x in xs]
    strong = [a.dtype for a, x in zip(arrs, xs, strict=True) if not isinstance(x, int | float)]
    dtypes = strong or [a.dtype for a in arrs]
    dtype = dtypes[0]
    for d in dtypes[1:]:
        dtype = np.promote_types(dtype, d)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return [a.astype(dtype) for a in arrs]


def _diag(d0: Array, d1: Array, d2: Array) -> Mat3:
    d = jnp.stack(jnp.broadcast_arrays(d0, d1, d2), axis=-1)
    return d[..., :, None] * jnp.eye(3, dtype=d.dtype)


def _check_axis(axis, name: str = "axis") -> int:
    ok = isinstance(axis, int | np.integer) and not isinstance(axis, bool)
    if not ok or int(axis) not in (0, 1, 2):
        raise ValueError(f"{name} must be 0, 1 or 2 (body x, y, z), got {axis!r}")
    return int(axis)


# ----------------------------------------------------------------------------- primitives


def cuboid(mass: ArrayLike, width: ArrayLike, height: ArrayLike, depth: ArrayLike) -> Mat3:
    """Solid homogeneous cuboid about its mass centre, edges along the body axes.

    J = m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) with a = width along body x, b = height
    along body y, c = depth along body z (docs/theory.md, section 3.2).

    **Arguments:**

    - `mass`: kg, shape (...).
    - `width`, `height`, `depth`: full edge lengths (m) along body x, y, z, shape (...).

    **Returns:** the diagonal tensor (kg m^2), shape (..., 3, 3).
    """
    m, a, b, c = _floats(mass, width, height, depth)
    k = m / 12.0
    return _diag(k * (b * b + c * c), k * (a * a + c * c), k * (a * a + b * b))


def cube(mass: ArrayLike, side: ArrayLike) -> Mat3:
    """Solid homogeneous cube (a die) of edge `side` (m): m side^2 / 6 times the identity."""
    return cuboid(mass, side, side, side)


def cylinder(mass: ArrayLike, radius: ArrayLike, height: ArrayLike, axis: int = 2) -> Mat3:
    """Solid homogeneous circular cylinder (a coin is a short one) about its mass centre.

    Axial moment m R^2 / 2 about the symmetry axis, transverse moments m (3 R^2 + h^2) / 12.

    **Arguments:**

    - `mass`: kg, shape (...).
    - `radius`: R (m), shape (...).
    - `height`: full length h (m) along the symmetry axis, shape (...).
    - `axis`: which body axis (0 = x, 1 = y, 2 = z) is the symmetry axis (static int).

    **Returns:** the diagonal tensor (kg m^2), shape (..., 3, 3).
    """
    axis = _check_axis(axis)
    m, r, h = _floats(mass, radius, height)
    axial = 0.5 * m * r * r
    transverse = m * (3.0 * r * r + h * h) / 12.0
    d = [transverse, transverse, transverse]
    d[axis] = axial
    return _diag(*d)


def sphere(mass: ArrayLike, radius: ArrayLike, hollow: bool = False) -> Mat3:
    """Homogeneous ball about its centre: 2/5 m R^2 (solid) or 2/3 m R^2 (thin shell, `hollow`).

    **Arguments:**

    - `mass`: kg, shape (...).
    - `radius`: R (m), shape (...).
    - `hollow`: static bool; True for a thin spherical shell.

    **Returns:** the isotropic tensor (kg m^2), shape (..., 3, 3).
    """
    m, r = _floats(mass, radius)
    i = (2.0 / 3.0 if hollow else 0.4) * m * r * r
    return _diag(i, i, i)


def rod(mass: ArrayLike, length: ArrayLike, axis: int = 0) -> Mat3:
    """Thin homogeneous rod about its centre, lying along body axis `axis` (0, 1 or 2).

    m L^2 / 12 about the two transverse axes and 0 about the rod's own axis. The zero moment
    makes this an idealisation: the tensor is singular (`is_valid_inertia` is False), so use it
    as a part (summed, shifted with `parallel_axis`), not as a whole body's inertia.

    **Arguments:**

    - `mass`: kg, shape (...).
    - `length`: L (m), shape (...).
    - `axis`: the body axis along the rod (static int).

    **Returns:** the diagonal tensor (kg m^2), shape (..., 3, 3).
    """
    axis = _check_axis(axis)
    m, L = _floats(mass, length)
    t = m * L * L / 12.0
    d = [t, t, t]
    d[axis] = jnp.zeros_like(t)
    return _diag(*d)


def from_products(
    Jxx: ArrayLike,
    Jyy: ArrayLike,
    Jzz: ArrayLike,
    Jxy: ArrayLike = 0.0,
    Jxz: ArrayLike = 0.0,
    Jyz: ArrayLike = 0.0,
) -> Mat3:
    """Tensor from moments and products of inertia (J_ij = integral of x_i x_j dm, i != j).

    Returns [[Jxx, -Jxy, -Jxz], [-Jxy, Jyy, -Jyz], [-Jxz, -Jyz, Jzz]] (kg m^2), shape (..., 3, 3).
    """
    xx, yy, zz, xy, xz, yz = jnp.broadcast_arrays(*_floats(Jxx, Jyy, Jzz, Jxy, Jxz, Jyz))
    rows = [
        jnp.stack([xx, -xy, -xz], axis=-1),
        jnp.stack([-xy, yy, -yz], axis=-1),
        jnp.stack([-xz, -yz, zz], axis=-1),
    ]
    return jnp.stack(rows, axis=-2)


# ----------------------------------------------------------------------------- transforms


def parallel_axis(J_C: ArrayLike, mass: ArrayLike, offset: ArrayLike) -> Mat3:
    """Inertia tensor about a point O, from the tensor about the mass centre C (parallel axes).

    J_O = J_C + m (|d|^2 1 - d d^T), with d the position of C relative to O in body axes (m).
    The shift is even in d, so d = O - C (O's position relative to C) gives the same result.

    **Arguments:**

    - `J_C`: tensor about the mass centre (kg m^2), shape (..., 3, 3).
    - `mass`: kg, shape (...).
    - `offset`: d (m, body axes), shape (..., 3).

    **Returns:** J_O (kg m^2, body axes), shape (..., 3, 3).
    """
    J_C = as_float_array(J_C, "J_C", (3, 3))
    offset = as_float_array(offset, "offset", (3,))
    J_C, m, d = _floats(J_C, mass, offset)
    dd = jnp.sum(d * d, axis=-1)[..., None, None]
    shift = dd * jnp.eye(3, dtype=d.dtype) - d[..., :, None] * d[..., None, :]
    return J_C + m[..., None, None] * shift


def rotate(J: ArrayLike, R: ArrayLike) -> Mat3:
    """Express a tensor in other axes: R J R^T.

    If R maps components in J's axes to components in the new axes (e.g. R = R(q), body ->
    world, r_world = R r_body), the result is the same tensor in the new axes (for R = R(q),
    the world-frame tensor I_w = R J R^T of docs/theory.md, section 3.3). Use R^T for the
    opposite direction.

    **Arguments:**

    - `J`: kg m^2, shape (..., 3, 3).
    - `R`: rotation matrix, shape (..., 3, 3).

    **Returns:** R J R^T, shape (..., 3, 3).
    """
    J = as_float_array(J, "J", (3, 3))
    R = as_float_array(R, "R", (3, 3))
    J, R = _floats(J, R)
    return R @ J @ jnp.swapaxes(R, -1, -2)


def principal(J: ArrayLike) -> tuple[Float[Array, "*batch 3"], Mat3]:
    """Principal moments and axes: J = axes @ diag(moments) @ axes.T.

    Uses the symmetric part of J (jnp.linalg.eigh). Gradients are well defined for distinct
    moments; for repeated moments (symmetric or spherical bodies) the axes in the degenerate
    subspace are not unique and their gradients are not meaningful.

    **Arguments:**

    - `J`: kg m^2, shape (..., 3, 3).

    **Returns:** `(moments, axes)`: moments ascending I1 <= I2 <= I3, shape (..., 3); axes
    with the principal directions as COLUMNS (components in J's axes), a right-handed rotation
    (det = +1), shape (..., 3, 3).
    """
    J = as_float_array(J, "J", (3, 3))
    Js = 0.5 * (J + jnp.swapaxes(J, -1, -2))
    moments, axes = jnp.linalg.eigh(Js)
    sign = jnp.where(jnp.linalg.det(axes) < 0, -1.0, 1.0).astype(axes.dtype)
    axes = axes.at[..., :, 2].multiply(sign[..., None])
    return moments, axes


# ----------------------------------------------------------------------------- validity


class InertiaViolations(NamedTuple):
    """Per-tensor boolean flags (shape (...)); all False means a physically valid tensor."""

    not_symmetric: Array
    not_positive_definite: Array
    triangle_inequality_violated: Array
    non_finite: Array


def _analyse(J: Array, rtol: float, eigenvalues=symmetric_eigenvalues3, xp=jnp):
    """Flags plus the numbers the error messages quote; `xp` is `jax.numpy` (traceable) or
    `numpy` (a concrete tensor's check: no compiled programs)."""
    non_finite = ~xp.all(xp.isfinite(J), axis=(-2, -1))
    eye = xp.eye(3, dtype=J.dtype)
    Jf = xp.where(non_finite[..., None, None], eye, J)
    JT = xp.swapaxes(Jf, -1, -2)
    scale = xp.max(xp.abs(Jf), axis=(-2, -1))
    asym = xp.max(xp.abs(Jf - JT), axis=(-2, -1))
    not_symmetric = asym > rtol * scale
    # the conditions are scale invariant: analyse J / max |J| (divided in two halves, whose
    # reciprocals stay normal numbers), so that no product overflows for huge or tiny tensors
    half = xp.sqrt(xp.where(scale > 0, scale, 1.0))[..., None, None]
    unit = eigenvalues(0.5 * (Jf / half / half + JT / half / half))
    trace = xp.sum(unit, axis=-1)
    i1, i2, i3 = unit[..., 0], unit[..., 1], unit[..., 2]
    not_pd = i1 <= rtol * xp.abs(trace)
    triangle = i1 + i2 < i3 - rtol * xp.abs(trace)
    moments = unit * half[..., 0] * half[..., 0]
    flags = InertiaViolations(
        not_symmetric=not_symmetric & ~non_finite,
        not_positive_definite=not_pd & ~non_finite,
        triangle_inequality_violated=triangle & ~non_finite,
        non_finite=non_finite,
    )
    return flags, asym, scale, moments


def inertia_violations(J: ArrayLike, rtol: float = 1e-9) -> InertiaViolations:
    """Which physical conditions an inertia tensor violates (traceable; jit/vmap safe).

    - `not_symmetric`: max |J - J^T| > rtol * max |J|.
    - `not_positive_definite`: smallest principal moment I1 <= rtol * trace (a singular
      tensor such as `rod`'s counts as not positive definite).
    - `triangle_inequality_violated`: I1 + I2 < I3 - rtol * trace for the ascending principal
      moments of the symmetric part (the other two inequalities then hold automatically).
    - `non_finite`: any entry NaN or inf (the other flags are then False).

    **Arguments:**

    - `J`: kg m^2, shape (..., 3, 3).
    - `rtol`: relative tolerance (static float).

    **Returns:** an `InertiaViolations` of boolean arrays, each of shape (...).
    """
    J = as_float_array(J, "inertia", (3, 3))
    return _analyse(J, rtol)[0]


def is_valid_inertia(J: ArrayLike, rtol: float = 1e-9) -> Array:
    """True where the tensor is finite, symmetric, positive definite and obeys the triangle
    inequality (traceable). Shape (...)."""
    v = inertia_violations(J, rtol)
    bad = v.not_symmetric | v.not_positive_definite | v.triangle_inequality_violated
    return ~(bad | v.non_finite)


def check_inertia(J: ArrayLike, name: str = "inertia", rtol: float = 1e-9) -> Mat3:
    """Validate an inertia tensor, raising a ValueError that names `name` and the problem.

    The shape (must be (..., 3, 3)) is always checked; the values only when `J` is concrete
    (not traced; under jit use `inertia_violations` / `is_valid_inertia`).

    **Arguments:**

    - `J`: kg m^2, shape (..., 3, 3).
    - `name`: the argument name used in error messages.
    - `rtol`: relative tolerance, as in `inertia_violations`.

    **Returns:** `J` as a float array, unchanged.

    **Raises:** ValueError for a wrong shape, non-finite entries, asymmetry, a non positive
    definite tensor or a violated triangle inequality (the first failing batch index is named).
    """
    J = as_float_array(J, name, (3, 3))
    if not is_concrete(J):
        return J
    # in float64 whatever J's precision: a tensor on the triangle inequality's boundary (a flat
    # plate, I1 + I2 = I3 in its float32 numbers) is not refused for float32 roundoff
    J64 = as_computed(J).astype(np.float64)  # subnormal entries 0, as in the simulation
    flags, asym, scale, moments = _analyse(J64, rtol, np.linalg.eigvalsh, xp=np)

    def where(flag) -> tuple[tuple[int, ...], str]:
        idx = tuple(int(i) for i in np.argwhere(flag)[0]) if flag.ndim else ()
        return idx, (f" at batch index {idx}" if idx else "")

    if flags.non_finite.any():
        _, at = where(flags.non_finite)
        raise ValueError(f"{name} contains non-finite values (NaN or inf){at}")
    if flags.not_symmetric.any():
        i, at = where(flags.not_symmetric)
        raise ValueError(
            f"{name} is not symmetric{at}: max |J - J^T| = {asym[i]:.6g} > "
            f"{rtol:g} * max |J| = {rtol * scale[i]:.6g}"
        )
    if flags.not_positive_definite.any():
        i, at = where(flags.not_positive_definite)
        raise ValueError(
            f"{name} is not positive definite{at}: smallest principal moment "
            f"I1 = {moments[i][0]:.6g} (principal moments {moments[i].tolist()})"
        )
    if flags.triangle_inequality_violated.any():
        i, at = where(flags.triangle_inequality_violated)
        i1, i2, i3 = moments[i]
        raise ValueError(
            f"{name} violates the triangle inequality{at}: I1 + I2 = {i1 + i2:.6g} < I3 = {i3:.6g}"
        )
    return J
