"""Body shapes: geometry for inertia and for contact with the floor.

Every shape is centred on the body's mass centre and aligned with the body axes.
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from . import inertia as _inertia
from ._checks import as_float_array
from ._quaternion import _safe_norm, quat_conjugate, quat_rotate
from ._typing import Mat3, Quat, Vec3


class AbstractShape(eqx.Module):
    """A convex solid centred on the mass centre, in body axes (m)."""

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

    def contact_candidates(self, quat: Quat) -> jnp.ndarray:
        """Body-frame points (..., K, 3) among which the lowest point at attitude `quat` lies.

        A fixed, small set (the sphere's lowest point, a box's 8 corners, the lowest rim point
        of each of a cylinder's two end caps): the floor is touched first at one of them.
        """
        return self.lowest_point(quat)[..., None, :]

    def candidate_heights(self, pos: Vec3, quat: Quat, height=0.0) -> jnp.ndarray:
        """World heights (m) above the floor z = `height` of the `contact_candidates`, (..., K)."""
        points = self.contact_candidates(quat)
        world = quat_rotate(quat[..., None, :], points)
        return pos[..., None, 2] + world[..., 2] - height

    def floor_distance(self, pos: Vec3, quat: Quat, height=0.0) -> jnp.ndarray:
        """Signed distance (m) of the solid's lowest point above the floor z = `height`.

        Negative when the solid penetrates the floor. `pos` is the mass centre (world frame),
        `quat` the unit attitude quaternion (scalar first, body to world).
        """
        return jnp.min(self.candidate_heights(pos, quat, height), axis=-1)

    def rest_faces(self):
        """Flat faces the solid can rest on: (outward unit normals (F, 3) body frame, distances
        (F,) from the mass centre to each face plane, face radii (F,) bounding each face about
        its centre), or None for a solid with no flat face (a sphere)."""
        return None


class Sphere(AbstractShape):
    """A solid ball of the given radius (m)."""

    radius: jnp.ndarray

    def __init__(self, radius):
        self.radius = jnp.asarray(radius, dtype=float)

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

    def contact_candidates(self, quat):
        return jnp.broadcast_to(self.corners(), quat.shape[:-1] + (8, 3))

    def rest_faces(self):
        a = self.half_extents
        eye = jnp.eye(3, dtype=a.dtype)
        normals = jnp.concatenate([eye, -eye], axis=0)
        offsets = jnp.concatenate([a, a], axis=-1)
        radii = jnp.sqrt(jnp.sum(a**2) - a**2)
        return normals, offsets, jnp.concatenate([radii, radii], axis=-1)


class Cylinder(AbstractShape):
    """A solid cylinder (a coin when short) with symmetry axis body z (m)."""

    radius: jnp.ndarray
    half_height: jnp.ndarray

    def __init__(self, radius, half_height):
        self.radius = jnp.asarray(radius, dtype=float)
        self.half_height = jnp.asarray(half_height, dtype=float)

    def inertia(self, mass) -> Mat3:
        return _inertia.cylinder(mass, self.radius, 2 * self.half_height, axis=2)

    def support_point(self, direction):
        radial = direction[..., :2]
        n = _safe_norm(radial, keepdims=True)
        rim = self.radius * radial / jnp.where(n > 0, n, 1.0)
        z = jnp.where(direction[..., 2:] >= 0, 1.0, -1.0) * self.half_height
        return jnp.concatenate([rim, z], axis=-1)

    def contact_candidates(self, quat):
        down = quat_rotate(quat_conjugate(quat), jnp.array([0.0, 0.0, -1.0], quat.dtype))
        radial = down[..., :2]
        n = _safe_norm(radial, keepdims=True)
        rim = self.radius * radial / jnp.where(n > 0, n, 1.0)
        top = jnp.concatenate([rim, jnp.broadcast_to(self.half_height, rim.shape[:-1] + (1,))], -1)
        bottom = jnp.concatenate(
            [rim, -jnp.broadcast_to(self.half_height, rim.shape[:-1] + (1,))], -1
        )
        return jnp.stack([top, bottom], axis=-2)

    def rest_faces(self):
        dtype = self.radius.dtype
        normals = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], dtype)
        offsets = jnp.stack([self.half_height, self.half_height])
        return normals, offsets, jnp.stack([self.radius, self.radius])
