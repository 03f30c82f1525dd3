"""The regular dice d4, d6, d8, d12 and d20 as convex polyhedra, with their face numbers.

Each builder returns a `Die`: its `shape` (a `ConvexPolyhedron` about its centroid; put it in
`RigidBody(mass, shape=die.shape)`, which then takes the uniform solid's inertia) and the
number on each face. Opposite faces sum to n + 1 (d6, d8, d12, d20); a d4 has no opposite
faces and is numbered 1-4 in face order.

A throw's outcome is read off the attitude: the number of the face pointing most nearly up,
or for a d4 the face it lies on (a d4 shows that number at its top corner). Default sizes are
those of common gaming dice (edge lengths in m); `offset` (m, body frame) is the centroid's
position relative to the mass centre, for a loaded die.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._hull import hull_faces
from ._polyhedron import ConvexPolyhedron, face_normals
from ._quaternion import quat_rotate

__all__ = ["Die", "d4", "d6", "d8", "d12", "d20", "BUILDERS"]

_PHI = (1 + 5**0.5) / 2


class Die(eqx.Module):
    """A die: its `shape` (a `ConvexPolyhedron`), `numbers` (F,) the number on each of its
    faces (static), and `read_bottom`, whether the outcome is the face it lies on (d4)."""

    shape: ConvexPolyhedron
    numbers: tuple = eqx.field(static=True)
    read_bottom: bool = eqx.field(static=True, default=False)

    @property
    def sides(self) -> int:
        return len(self.numbers)

    def face_index(self, quat) -> jnp.ndarray:
        """Index of the face that gives the outcome at the attitude `quat` (scalar first, body
        to world; any batch shape): the face whose outward normal is most nearly up (down for
        a d4)."""
        normals = self.shape.face_normals()  # (F, 3) body frame
        q = jnp.asarray(quat)[..., None, :]
        z = quat_rotate(q, normals)[..., 2]  # world z of each normal
        return jnp.argmin(z, axis=-1) if self.read_bottom else jnp.argmax(z, axis=-1)

    def outcome(self, quat) -> jnp.ndarray:
        """The number the die shows at the attitude `quat` (any batch shape)."""
        return jnp.asarray(self.numbers)[self.face_index(quat)]

    def face_alignment(self, quat) -> jnp.ndarray:
        """How squarely the die lies on a face: the cosine between the outcome face's normal
        and the vertical (1 when the die rests on a face)."""
        normals = self.shape.face_normals()
        z = quat_rotate(jnp.asarray(quat)[..., None, :], normals)[..., 2]
        return jnp.max(-z if self.read_bottom else z, axis=-1)


def _opposite_numbers(normals: np.ndarray) -> tuple[int, ...]:
    """Numbers 1..F with opposite faces summing to F + 1, lower numbers to faces in order."""
    F = len(normals)
    numbers = [0] * F
    k = 1
    for i in range(F):
        if numbers[i]:
            continue
        j = int(np.argmin(normals @ normals[i]))
        if not np.allclose(normals[j], -normals[i], atol=1e-9):
            raise ValueError("a die with opposite faces numbered n + 1 needs parallel faces")
        numbers[i], numbers[j] = k, F + 1 - k
        k += 1
    return tuple(numbers)


def _die(points, edge_of_points: float, edge: float, offset, read_bottom=False) -> Die:
    if not (np.isfinite(edge) and edge > 0):
        raise ValueError(f"edge must be finite and > 0, got {edge}")
    points = np.asarray(points, float) * (edge / edge_of_points)
    shape = ConvexPolyhedron(points, offset)
    # the same hull in numpy (a die may be built under jit, where the shape's arrays trace)
    normals = face_normals(*hull_faces(points), xp=np)
    if read_bottom:
        numbers = tuple(range(1, len(shape.faces) + 1))
    else:
        numbers = _opposite_numbers(normals)
    return Die(shape, numbers, read_bottom)


def _signs(*columns):
    """All sign combinations of the given coordinates (each a tuple of three)."""
    out = []
    for base in columns:
        for sx in (-1, 1) if base[0] else (1,):
            for sy in (-1, 1) if base[1] else (1,):
                for sz in (-1, 1) if base[2] else (1,):
                    out.append((sx * base[0], sy * base[1], sz * base[2]))
    return out


def d4(edge: float = 0.018, offset=(0.0, 0.0, 0.0)) -> Die:
    """A regular tetrahedron of the given edge (m); the outcome is the face it lies on."""
    points = [(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)]
    return _die(points, 2 * 2**0.5, edge, offset, read_bottom=True)


def d6(edge: float = 0.016, offset=(0.0, 0.0, 0.0)) -> Die:
    """A cube of the given edge (m) as a polyhedron (`Box` is the same solid)."""
    return _die(_signs((1, 1, 1)), 2.0, edge, offset)


def d8(edge: float = 0.015, offset=(0.0, 0.0, 0.0)) -> Die:
    """A regular octahedron of the given edge (m)."""
    return _die(_signs((1, 0, 0), (0, 1, 0), (0, 0, 1)), 2**0.5, edge, offset)


def d12(edge: float = 0.009, offset=(0.0, 0.0, 0.0)) -> Die:
    """A regular dodecahedron of the given edge (m)."""
    a, b = 1 / _PHI, _PHI
    points = _signs((1, 1, 1), (0, a, b), (a, b, 0), (b, 0, a))
    return _die(points, 2 / _PHI, edge, offset)


def d20(edge: float = 0.011, offset=(0.0, 0.0, 0.0)) -> Die:
    """A regular icosahedron of the given edge (m)."""
    return _die(_signs((0, 1, _PHI), (1, _PHI, 0), (_PHI, 0, 1)), 2.0, edge, offset)


BUILDERS = {4: d4, 6: d6, 8: d8, 12: d12, 20: d20}
"""The builder of each regular die, by its number of faces."""
