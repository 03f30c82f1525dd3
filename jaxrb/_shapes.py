"""Body shapes: geometry for inertia, plots and the lowest point; their contact features
(points, edges, faces) are in `jaxrb.contact` (one table entry per shape).

Every shape is centred on the body's mass centre and aligned with the body axes.
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from . import inertia as _inertia
from ._checks import Requirement, as_float_array, finite_positive, raise_unmet
from ._quaternion import _safe_norm, quat_conjugate, quat_rotate
from ._typing import Mat3, Quat, Vec3


class AbstractShape(eqx.Module):
    """A convex solid centred on the mass centre, in body axes (m).

    Dimensions must be finite and > 0: concrete values raise a ValueError naming the field
    where the shape is made; traced ones give `RESULTS.invalid_shape` in `simulate`.
    """

    @abc.abstractmethod
    def requirements(self) -> tuple[Requirement, ...]:
        """The conditions on the shape's dimensions (see `jaxrb._checks.Requirement`)."""

    def __check_init__(self):
        raise_unmet(type(self).__name__, self.requirements())

    @abc.abstractmethod
    def inertia(self, mass) -> Mat3:
        """Inertia tensor (kg m^2) of the solid of uniform density and the given mass."""

    @abc.abstractmethod
    def support_point(self, direction: Vec3) -> Vec3:
        """The point of the solid (body frame) furthest along the body-frame `direction`."""

    def lowest_point(self, quat: Quat) -> Vec3:
        """Body-frame point of the solid with the smallest world z at attitude `quat`."""
        down_in_body = quat_rotate(quat_conjugate(quat), jnp.array([0.0, 0.0, -1.0], quat.dtype))
        return self.support_point(down_in_body)

    def floor_distance(self, pos: Vec3, quat: Quat, height=0.0) -> jnp.ndarray:
        """Signed distance (m) of the solid's lowest point above the floor z = `height`.

        Negative when the solid penetrates the floor. `pos` is the mass centre (world frame),
        `quat` the unit attitude quaternion (scalar first, body to world).
        """
        lowest = quat_rotate(quat, self.lowest_point(quat))
        return pos[..., 2] + lowest[..., 2] - height


class Sphere(AbstractShape):
    """A solid ball of the given radius (m)."""

    radius: jnp.ndarray

    def __init__(self, radius):
        self.radius = jnp.asarray(radius, dtype=float)

    def requirements(self):
        return (Requirement("radius", self.radius, "finite and > 0", finite_positive(self.radius)),)

    def inertia(self, mass) -> Mat3:
        return _inertia.sphere(mass, self.radius)

    def support_point(self, direction):
        n = _safe_norm(direction, keepdims=True)
        return self.radius * direction / jnp.where(n > 0, n, 1.0)


class Box(AbstractShape):
    """A cuboid with the given half extents (m) along body x, y, z; a die is a cube."""

    half_extents: jnp.ndarray

    def __init__(self, half_extents):
        self.half_extents = as_float_array(half_extents, "half_extents", (3,))

    def requirements(self):
        ext = self.half_extents
        return (Requirement("half_extents", ext, "finite and > 0", finite_positive(ext)),)

    def inertia(self, mass) -> Mat3:
        w, h, d = (
            2 * self.half_extents[..., 0],
            2 * self.half_extents[..., 1],
            2 * self.half_extents[..., 2],
        )
        return _inertia.cuboid(mass, w, h, d)

    def support_point(self, direction):
        return jnp.where(direction >= 0, 1.0, -1.0) * self.half_extents

    def corners(self) -> jnp.ndarray:
        """The 8 corners, body frame, shape (..., 8, 3)."""
        signs = jnp.array(
            [[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)],
            dtype=self.half_extents.dtype,
        )
        return signs * self.half_extents[..., None, :]


class Cylinder(AbstractShape):
    """A solid cylinder (a coin when short) with symmetry axis body z (m)."""

    radius: jnp.ndarray
    half_height: jnp.ndarray

    def __init__(self, radius, half_height):
        self.radius = jnp.asarray(radius, dtype=float)
        self.half_height = jnp.asarray(half_height, dtype=float)

    def requirements(self):
        r, h = self.radius, self.half_height
        return (
            Requirement("radius", r, "finite and > 0", finite_positive(r)),
            Requirement("half_height", h, "finite and > 0", finite_positive(h)),
        )

    def inertia(self, mass) -> Mat3:
        return _inertia.cylinder(mass, self.radius, 2 * self.half_height, axis=2)

    def support_point(self, direction):
        radial = direction[..., :2]
        n = _safe_norm(radial, keepdims=True)
        rim = self.radius * radial / jnp.where(n > 0, n, 1.0)
        z = jnp.where(direction[..., 2:] >= 0, 1.0, -1.0) * self.half_height
        return jnp.concatenate([rim, z], axis=-1)
