"""A convex polyhedron: faces from the hull of its vertices, uniform-density mass properties.

Mass properties by the divergence theorem: each face is split into triangles (v0, vk, vk+1)
and each triangle spans a tetrahedron with the origin, of signed volume
det(a, b, c) / 6, first moment det / 24 (a + b + c) and second moment
det / 120 (a a^T + b b^T + c c^T + s s^T) with s = a + b + c (exact for a tetrahedron);
summed over the surface they give the solid's volume, centroid and second moment.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import Requirement, as_float_array, finite
from ._hull import hull_edges, hull_faces
from ._shapes import AbstractShape, offset_requirement
from ._typing import Mat3


def _triangles(faces) -> np.ndarray:
    """Fan triangles (T, 3) of the polygons `faces` (vertex indices)."""
    return np.array([(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)])


def volume_moments(vertices, faces, xp=jnp):
    """(volume (m^3), first moment (3,) (m^4), second moment sum x x^T dV (3, 3) (m^5)) of
    the solid bounded by the outward, counter-clockwise polygons `faces` of `vertices`;
    `xp`: numpy (when a shape is made) or jax.numpy."""
    tri = _triangles(faces)
    a, b, c = vertices[tri[:, 0]], vertices[tri[:, 1]], vertices[tri[:, 2]]
    det = xp.sum(a * xp.cross(b, c), axis=-1)
    s = a + b + c
    outer = sum(x[:, :, None] * x[:, None, :] for x in (a, b, c, s))
    volume = xp.sum(det) / 6
    first = xp.sum(det[:, None] * s, axis=0) / 24
    second = xp.sum(det[:, None, None] * outer, axis=0) / 120
    return volume, first, second


def face_normals(vertices, faces, xp=jnp):
    """Outward unit normals (F, 3) of the polygons `faces` of `vertices` (Newell's method)."""
    normals = []
    for f in faces:
        v = vertices[np.asarray(f)]
        n = xp.sum(xp.cross(v, xp.roll(v, -1, axis=0)), axis=0)
        normals.append(n / xp.linalg.norm(n))
    return xp.stack(normals)


class ConvexPolyhedron(AbstractShape):
    """A convex polyhedron: the hull of `vertices` (body frame, m).

    The vertices are moved so that the solid's centroid (its geometric centre) is at the
    origin; `offset` (m, body frame) places that centre relative to the mass centre. Points
    inside the hull or on its edges are dropped; coplanar points make one face.

    **Fields:**

    - `vertices`: (V, 3) the hull's corners about its centroid (m);
    - `faces`: the faces as tuples of vertex indices, counter-clockwise seen from outside
      (static);
    - `edges`: the edges (i, j), i < j (static);
    - `offset`: (3,) the centroid relative to the mass centre (m).
    """

    vertices: jnp.ndarray
    offset: jnp.ndarray
    faces: tuple = eqx.field(static=True)
    edges: tuple = eqx.field(static=True)

    def __init__(self, vertices, offset=(0.0, 0.0, 0.0), *, faces=None):
        if faces is None:
            points, faces = hull_faces(vertices)
            volume, first, _ = volume_moments(points, faces, xp=np)
            self.vertices = jnp.asarray(points - first / volume)
        else:  # a copy with the same topology (vertices already about the centroid)
            self.vertices = as_float_array(vertices, "vertices", (3,))
        self.faces = tuple(tuple(int(i) for i in f) for f in faces)
        self.edges = hull_edges(self.faces)
        self.offset = as_float_array(offset, "offset", (3,))

    def requirements(self):
        return (
            Requirement("vertices", self.vertices, "finite", finite(self.vertices)),
            offset_requirement(self.offset),
        )

    @property
    def volume(self):
        """Volume (m^3)."""
        return volume_moments(self.vertices, self.faces)[0]

    def inertia(self, mass) -> Mat3:
        volume, first, second = volume_moments(self.vertices, self.faces)
        centred = second - jnp.outer(first, first) / volume
        return mass / volume * (jnp.trace(centred) * jnp.eye(3, dtype=centred.dtype) - centred)

    def support_point(self, direction):
        heights = self.vertices @ direction
        return self.vertices[jnp.argmax(heights)] + self.offset

    def face_normals(self) -> jnp.ndarray:
        """Outward unit normals (F, 3) of the faces (body frame)."""
        return face_normals(self.vertices, self.faces)
