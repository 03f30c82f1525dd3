"""Body shapes: geometry for inertia, plots and the lowest point; their contact features
(points, edges, faces) are in `jaxrb.contact` (one table entry per shape).

Every shape is aligned with the body axes; its geometric centre sits at `offset` (body frame,
m) from the body's mass centre, (0, 0, 0) by default. A non-zero offset is a body whose mass
is not spread evenly (a loaded die, a tippe top): its inertia tensor is then the user's to
give, since `inertia(mass)` is the uniform solid's about its own centre.
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from . import inertia as _inertia
from ._checks import Requirement, as_float_array, finite, finite_positive, raise_unmet
from ._quaternion import _safe_norm, quat_conjugate, quat_rotate
from ._typing import Mat3, Quat, Vec3


def offset_requirement(offset) -> Requirement:
    return Requirement("offset", offset, "finite", finite(offset))


class AbstractShape(eqx.Module):
    """A convex solid in body axes (m), its centre at `offset` from the mass centre.

    Dimensions must be finite and > 0 and the offset finite: concrete values raise a
    ValueError naming the field where the shape is made; traced ones give
    `RESULTS.invalid_shape` in `simulate`.
    """

    offset: eqx.AbstractVar[jnp.ndarray]

    @abc.abstractmethod
    def requirements(self) -> tuple[Requirement, ...]:
        """The conditions on the shape's dimensions (see `jaxrb._checks.Requirement`)."""

    def __check_init__(self):
        raise_unmet(type(self).__name__, self.requirements())

    @abc.abstractmethod
    def inertia(self, mass) -> Mat3:
        """Inertia tensor (kg m^2) of the solid of uniform density and the given mass, about
        its geometric centre (the mass centre when `offset` is zero)."""

    @abc.abstractmethod
    def support_point(self, direction: Vec3) -> Vec3:
        """The point of the solid (body frame, from the mass centre, m) furthest along the
        body-frame `direction`."""

    def lowest_point(self, quat: Quat, normal=None) -> Vec3:
        """Body-frame point of the solid with the smallest world z (or, given a world
        `normal`, the smallest height along it) at attitude `quat`."""
        up = jnp.array([0.0, 0.0, 1.0], quat.dtype) if normal is None else normal
        down_in_body = quat_rotate(quat_conjugate(quat), -jnp.asarray(up, quat.dtype))
        return self.support_point(down_in_body)

    def floor_distance(self, pos: Vec3, quat: Quat, height=0.0, normal=None) -> jnp.ndarray:
        """Signed distance (m) of the solid's lowest point above the floor z = `height`, or
        above the plane through (0, 0, `height`) with the unit world `normal` (a tilted
        `Floor`'s `normal`).

        Negative when the solid penetrates the floor. `pos` is the mass centre (world frame),
        `quat` the unit attitude quaternion (scalar first, body to world).
        """
        lowest = pos + quat_rotate(quat, self.lowest_point(quat, normal))
        if normal is None:
            return lowest[..., 2] - height
        n = jnp.asarray(normal, pos.dtype)
        return lowest @ n - n[2] * height


class Sphere(AbstractShape):
    """A solid ball of the given radius (m)."""

    radius: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, radius, offset=(0.0, 0.0, 0.0)):
        self.radius = jnp.asarray(radius, dtype=float)
        self.offset = as_float_array(offset, "offset", (3,))

    def requirements(self):
        return (
            Requirement("radius", self.radius, "finite and > 0", finite_positive(self.radius)),
            offset_requirement(self.offset),
        )

    def inertia(self, mass) -> Mat3:
        return _inertia.sphere(mass, self.radius)

    def support_point(self, direction):
        n = _safe_norm(direction, keepdims=True)
        return self.radius * direction / jnp.where(n > 0, n, 1.0) + self.offset


class Box(AbstractShape):
    """A cuboid with the given half extents (m) along body x, y, z; a die is a cube."""

    half_extents: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, half_extents, offset=(0.0, 0.0, 0.0)):
        self.half_extents = as_float_array(half_extents, "half_extents", (3,))
        self.offset = as_float_array(offset, "offset", (3,))

    def requirements(self):
        ext = self.half_extents
        return (
            Requirement("half_extents", ext, "finite and > 0", finite_positive(ext)),
            offset_requirement(self.offset),
        )

    def inertia(self, mass) -> Mat3:
        w, h, d = (
            2 * self.half_extents[..., 0],
            2 * self.half_extents[..., 1],
            2 * self.half_extents[..., 2],
        )
        return _inertia.cuboid(mass, w, h, d)

    def support_point(self, direction):
        return jnp.where(direction >= 0, 1.0, -1.0) * self.half_extents + self.offset

    def corners(self) -> jnp.ndarray:
        """The 8 corners, body frame from the mass centre, shape (..., 8, 3)."""
        signs = jnp.array(
            [[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)],
            dtype=self.half_extents.dtype,
        )
        return signs * self.half_extents[..., None, :] + self.offset[..., None, :]


class Cylinder(AbstractShape):
    """A solid cylinder (a coin when short) with symmetry axis body z (m)."""

    radius: jnp.ndarray
    half_height: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, radius, half_height, offset=(0.0, 0.0, 0.0)):
        self.radius = jnp.asarray(radius, dtype=float)
        self.half_height = jnp.asarray(half_height, dtype=float)
        self.offset = as_float_array(offset, "offset", (3,))

    def requirements(self):
        r, h = self.radius, self.half_height
        return (
            Requirement("radius", r, "finite and > 0", finite_positive(r)),
            Requirement("half_height", h, "finite and > 0", finite_positive(h)),
            offset_requirement(self.offset),
        )

    def inertia(self, mass) -> Mat3:
        return _inertia.cylinder(mass, self.radius, 2 * self.half_height, axis=2)

    def support_point(self, direction):
        radial = direction[..., :2]
        n = _safe_norm(radial, keepdims=True)
        rim = self.radius * radial / jnp.where(n > 0, n, 1.0)
        z = jnp.where(direction[..., 2:] >= 0, 1.0, -1.0) * self.half_height
        return jnp.concatenate([rim, z], axis=-1) + self.offset
