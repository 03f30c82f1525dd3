"""Contact features of each shape: its contact points, pairs (edges, lines) and faces.

One table maps a shape class to its contact model (as MJX maps a geometry pair to a
collision function); a shape without an entry is an error, never treated as another shape.

Frames: body points and normals are in the body frame (m), from the mass centre: a shape's
`offset` is added to its points. `down` is the floor's normal in
the body frame, d = R(q)^T n: a body point p is at height n . x + d . p above the plane
through the mass centre parallel to the floor, so the lowest point of a curve minimises d . p.
"""

import abc
import itertools

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._polyhedron import ConvexPolyhedron
from .._quaternion import _safe_norm
from .._shapes import AbstractShape, Box, Cylinder, Sphere

# below this |d_xy| a cap counts as flat and its rim points use the mode's seed direction
_FLAT_DIRECTION_EPS = 1e-12


class AbstractContactModel(eqx.Module):
    """Contact geometry of one shape (body frame, m).

    Static structure (Python / numpy, the same for every member of a batch):

    - `num_points`: number of contact points P.
    - `point_features`: indices of the points that can carry the body alone (POINT modes).
    - `flat_points`: mask (P,) of points that only tell that a face has come down (a cap's
      highest rim point): their gap is compared with the flatness tolerance, not with 0.
    - `pairs`: (E, 2) point indices of the edges / lines (PAIR modes).
    - `face_points`: (F, K) point indices of each face (all touch when the face lies flat).
    - `smooth_points`: indices of the points that touch a frictionless part of the surface
      (a roulette wheel's wall): they slide, never stick.
    """

    num_points: int = eqx.field(static=True)
    point_features: tuple = eqx.field(static=True)
    flat_points: tuple = eqx.field(static=True)
    pairs: tuple = eqx.field(static=True)
    face_points: tuple = eqx.field(static=True)
    smooth_points: tuple = eqx.field(static=True)

    @abc.abstractmethod
    def points(self, down, seed):
        """Body-frame contact points (P, 3) at the attitude where the floor normal is `down`
        in the body frame (a ball on a surface of several parts: `down` (P, 3), one normal
        per part); `seed` (3,) is the body-frame direction used for a rim's lowest
        point when its cap lies flat (where that point is not unique)."""

    def impact_points(self, down, seed):
        """Body-frame points (Q, 3) at which impulses act (the contact points, and for a
        shape with curved faces, points spread over each face so that a face landing flat
        is held as a face), with a mask (Q,) of those that touch only when their face lies
        flat (compared with the flatness tolerance)."""
        return self.points(down, seed), jnp.asarray(self.flat_points)

    @abc.abstractmethod
    def face_frame(self):
        """(outward normals (F, 3), reference points (F, 3), friction radii (F,)), body frame."""

    @abc.abstractmethod
    def cop_margin(self, face, normal_force, couple):
        """How far inside face `face`'s support region the centre of pressure lies, times the
        normal force (N m; >= 0 inside): `normal_force` N at the reference point and the couple
        (body frame, N m, in the face plane) of the normal pressure about it."""

    # whether the model's points need the mode's seed direction (a rim on a flat cap)
    needs_seed = False
    # whether the points move over the body as it turns (support points of a curve)
    moving_points = True

    def rim_seed(self, down, cop_offset, old_seed):
        """The seed direction (body) for the next segment (only a rim needs one): the
        current one unless a cap lies flat; `cop_offset` is the direction (body) in which a
        flat face's centre of pressure lies from its centre, or zero."""
        return old_seed

    @property
    def num_faces(self) -> int:
        return len(self.face_points)

    def face_reach(self):
        """(max(F, 1),) per face, the factor by which a function affine on it (a gap, a gap
        rate) can exceed its largest magnitude at three of its points elsewhere on it (see
        `_face_reach`); 1 for a face of fewer than three points (a cap's two)."""
        return jnp.ones(max(self.num_faces, 1))


class SphereContact(AbstractContactModel):
    """A ball: one contact point per part of the surface (`parts`), each the ball's point
    offset - radius d_i against that part's normal d_i; on a surface of two parts (a
    roulette wheel's track and wall) the two points also make a pair, the second smooth."""

    radius: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, shape: Sphere, parts: int = 1):
        self.radius = shape.radius
        self.offset = shape.offset
        self.num_points = parts
        self.point_features = tuple(range(parts))
        self.flat_points = (False,) * parts
        self.pairs = ((0, 1),) if parts == 2 else ()
        self.face_points = ()
        self.smooth_points = (1,) if parts == 2 else ()

    def points(self, down, seed):
        return jnp.broadcast_to(self.offset - self.radius * down, (self.num_points, 3))

    def face_frame(self):
        z = jnp.zeros((0, 3), self.radius.dtype)
        return z, z, jnp.zeros((0,), self.radius.dtype)

    def cop_margin(self, face, normal_force, couple):
        return jnp.full_like(normal_force, jnp.inf)


def _box_tables():
    """Corner signs (8, 3) (index 4 ix + 2 iy + iz), edges (12, 2), faces (6, 4) in cyclic
    order with their (axis, sign)."""
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    edges = [
        (i, j) for i, j in itertools.combinations(range(8), 2) if np.sum(signs[i] != signs[j]) == 1
    ]
    faces, axes = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            j, k = (axis + 1) % 3, (axis + 2) % 3
            ring = []
            for sj, sk in ((-1, -1), (1, -1), (1, 1), (-1, 1)):  # cyclic around the face
                s = np.zeros(3)
                s[axis], s[j], s[k] = sign, sj, sk
                ring.append(int(np.flatnonzero(np.all(signs == s, axis=1))[0]))
            faces.append(tuple(ring))
            axes.append((axis, sign))
    return signs, tuple(edges), tuple(faces), tuple(axes)


_BOX_SIGNS, _BOX_EDGES, _BOX_FACES, _BOX_FACE_AXES = _box_tables()


def _polygon_mean_distance(vertices, centre):
    """Mean distance (m) from `centre` (..., 3) of the points of the convex polygons
    `vertices` (..., K, 3) (uniform density): the sum over the triangles (centre, v_k, v_k+1)
    of (h^3 / 3) [F(t)] with F(t) = (t sqrt(1 + t^2) + asinh t) / 2, h the centre's distance
    to the edge and t the edge coordinate over h, divided by the area. All edges at once."""
    a = vertices - centre[..., None, :]
    b = jnp.roll(a, -1, axis=-2)
    edge = b - a
    length = _safe_norm(edge, keepdims=True)
    along = edge / length
    h = _safe_norm(jnp.cross(a, along))
    ta, tb = jnp.sum(a * along, axis=-1) / h, jnp.sum(b * along, axis=-1) / h

    def F(t):
        return 0.5 * (t * jnp.sqrt(1 + t * t) + jnp.arcsinh(t))

    total = jnp.sum(h**3 / 3 * (F(tb) - F(ta)), axis=-1)
    area = jnp.sum(0.5 * h * length[..., 0], axis=-1)
    return total / area


def _face_reach(corners, face_points):
    """(F,) for each face of `corners` (P, 3) listed by `face_points`: the largest sum of the
    absolute barycentric coordinates of one of its points with respect to three others, the
    factor by which a function affine on the face can exceed its largest magnitude at three
    points elsewhere on it: 1 on a triangle, 3 on a parallelogram, 2 + sqrt(5) on a regular
    pentagon. Three points in a line (which do not fix the face's plane) are left out."""
    combos = [
        (f, tri, k)
        for f, points in enumerate(face_points)
        for tri in itertools.combinations(points, 3)
        for k in points
    ]
    face, tri, k = (np.asarray(x) for x in zip(*combos, strict=True))
    v0, v1, v2, p = corners[tri[:, 0]], corners[tri[:, 1]], corners[tri[:, 2]], corners[k]
    n = jnp.cross(v1 - v0, v2 - v0)
    twice_area = jnp.sum(n * n, axis=-1)
    weights = jnp.stack(
        [jnp.cross(v1 - p, v2 - p), jnp.cross(v2 - p, v0 - p), jnp.cross(v0 - p, v1 - p)]
    )
    spread = twice_area > 0
    reach = jnp.sum(jnp.abs(jnp.sum(weights * n, axis=-1)), axis=0)
    reach = jnp.where(spread, reach / jnp.where(spread, twice_area, 1.0), 1.0)
    of_face = face[None, :] == np.arange(len(face_points))[:, None]
    return jnp.max(jnp.where(of_face, reach, 1.0), axis=1)


class CornerContact(AbstractContactModel):
    """A solid whose contact points are its corners (fixed on the body) and whose faces are
    polygons: `corners` (P, 3); per face its outward `normals`, `centres` and friction radii
    `rho` (body frame, m), and `reach` (`face_reach`)."""

    corners: jnp.ndarray
    normals: jnp.ndarray
    centres: jnp.ndarray
    rho: jnp.ndarray
    reach: jnp.ndarray

    moving_points = False

    def points(self, down, seed):
        return self.corners

    def face_frame(self):
        return self.normals, self.centres, self.rho

    def face_reach(self):
        return self.reach


class BoxContact(CornerContact):
    """A cuboid: its 8 corners, 12 edges and 6 rectangular faces."""

    half_extents: jnp.ndarray

    def __init__(self, shape: Box):
        a = shape.half_extents
        self.half_extents = a
        self.num_points = 8
        self.point_features = tuple(range(8))
        self.flat_points = (False,) * 8
        self.pairs = _BOX_EDGES
        self.face_points = _BOX_FACES
        self.smooth_points = ()
        self.corners = jnp.asarray(_BOX_SIGNS, a.dtype) * a + shape.offset
        eye = jnp.eye(3, dtype=a.dtype)
        self.normals = jnp.stack([sign * eye[axis] for axis, sign in _BOX_FACE_AXES])
        self.centres = self.normals * a + shape.offset
        self.rho = _polygon_mean_distance(self.corners[np.asarray(_BOX_FACES)], self.centres)
        self.reach = _face_reach(self.corners, self.face_points)

    def cop_margin(self, face, normal_force, couple):
        # the face of `axis` is bounded by |x_j| <= a_j, |x_k| <= a_k; the centre of pressure
        # is offset by n x M / N = M x nu / N from the face centre (floor normal n = -nu)
        nu = self.normals[face]
        offset_times_n = jnp.cross(couple, nu)  # N * (CoP - centre), body frame
        a = self.half_extents
        margins = normal_force * a - jnp.abs(offset_times_n)  # per axis; the face's axis is 0
        on_face = jnp.abs(nu) < 0.5
        return jnp.min(jnp.where(on_face, margins, jnp.inf))


class CylinderContact(AbstractContactModel):
    """A cylinder (axis body z): per cap its lowest and highest rim points, the side line,
    and the two caps (discs).

    Points: 0 top cap lowest rim point, 1 bottom cap lowest, 2 top cap highest, 3 bottom cap
    highest. The highest rim point of a cap is as low as its lowest one exactly when the cap
    lies flat.
    """

    radius: jnp.ndarray
    half_height: jnp.ndarray
    offset: jnp.ndarray

    def __init__(self, shape: Cylinder):
        self.radius = shape.radius
        self.half_height = shape.half_height
        self.offset = shape.offset
        self.num_points = 4
        self.point_features = (0, 1)
        self.flat_points = (False, False, True, True)
        self.pairs = ((0, 1),)
        self.face_points = ((0, 2), (1, 3))
        self.smooth_points = ()

    def rim_direction(self, down, seed):
        """Unit body-frame direction (x, y, 0) of the highest rim point: d_xy / |d_xy|."""
        dxy = down * jnp.array([1.0, 1.0, 0.0], down.dtype)
        n = _safe_norm(dxy)
        flat = n < _FLAT_DIRECTION_EPS
        return jnp.where(flat, seed, dxy / jnp.where(flat, 1.0, n))

    needs_seed = True

    def rim_seed(self, down, cop_offset, old_seed):
        # tipping over the rim from a flat cap: the lowest rim point is where the centre of
        # pressure reached the rim, i.e. d_xy points away from it
        dxy = down * jnp.array([1.0, 1.0, 0.0], down.dtype)
        flat = _safe_norm(dxy) < _FLAT_DIRECTION_EPS
        towards_cop = cop_offset * jnp.array([1.0, 1.0, 0.0], down.dtype)
        has_cop = _safe_norm(towards_cop) > 0
        from_cop = -towards_cop / jnp.where(has_cop, _safe_norm(towards_cop), 1.0)
        return jnp.where(
            flat, jnp.where(has_cop, from_cop, old_seed), self.rim_direction(down, old_seed)
        )

    def points(self, down, seed):
        u = self.rim_direction(down, seed)
        r, h = self.radius, self.half_height
        ez = jnp.array([0.0, 0.0, 1.0], down.dtype)
        corners = jnp.stack([-r * u + h * ez, -r * u - h * ez, r * u + h * ez, r * u - h * ez])
        return corners + self.offset

    def impact_points(self, down, seed):
        # per cap: its lowest rim point, its highest, and the two half-way between, which
        # hold a cap landing flat (they touch only when it is flat: the flatness tolerance)
        u = self.rim_direction(down, seed)
        side = jnp.stack([-u[1], u[0], jnp.zeros_like(u[0])])
        r = self.radius
        h = self.half_height * jnp.array([0.0, 0.0, 1.0], down.dtype)
        ring = jnp.stack([-r * u, r * u, r * side, -r * side])
        everything = jnp.concatenate([ring + h, ring - h]) + self.offset
        flat = jnp.asarray([False, True, True, True] * 2)
        return everything, flat

    def face_frame(self):
        dtype = self.radius.dtype
        normals = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], dtype)
        centres = normals * self.half_height + self.offset
        rho = jnp.full((2,), 2.0 / 3.0, dtype) * self.radius  # disc, uniform pressure
        return normals, centres, rho

    def cop_margin(self, face, normal_force, couple):
        return normal_force * self.radius - _safe_norm(couple)


def _polygon_centroid(vertices):
    """Area centroid (3,) of the planar convex polygon `vertices` (K, 3)."""
    v0 = vertices[0]
    centre, area = 0.0, 0.0
    for k in range(1, vertices.shape[0] - 1):
        a = 0.5 * _safe_norm(jnp.cross(vertices[k] - v0, vertices[k + 1] - v0))
        centre = centre + a * (v0 + vertices[k] + vertices[k + 1]) / 3
        area = area + a
    return centre / area


class PolyhedronContact(CornerContact):
    """A convex polyhedron: its corners, edges and polygonal faces.

    A face's centre is its area centroid; its support region for the centre of pressure is
    the polygon, bounded by the edge lines m_k . (x - c) <= h_k (m_k the in-plane outward
    normal of edge k, h_k its distance from the centre c).
    """

    edge_normals: jnp.ndarray  # (F, K, 3), K the most edges of a face (padded)
    edge_distances: jnp.ndarray  # (F, K)
    edge_used: tuple = eqx.field(static=True)  # (F, K) which of the K slots are edges

    def __init__(self, shape: ConvexPolyhedron):
        v = shape.vertices
        faces = shape.faces
        self.num_points = v.shape[0]
        self.point_features = tuple(range(self.num_points))
        self.flat_points = (False,) * self.num_points
        self.pairs = shape.edges
        self.face_points = faces
        self.smooth_points = ()
        self.corners = v + shape.offset
        self.normals = shape.face_normals()
        K = max(len(f) for f in faces)
        centres, rhos, m_all, h_all, used = [], [], [], [], []
        for f, nu in zip(faces, self.normals, strict=True):
            ring = v[jnp.asarray(f)]
            c = _polygon_centroid(ring)
            centres.append(c)
            rhos.append(_polygon_mean_distance(ring, c))
            edge = jnp.roll(ring, -1, axis=0) - ring
            m = jnp.cross(edge, nu)
            m = m / _safe_norm(m, keepdims=True)
            h = jnp.sum(m * (ring - c), axis=1)
            pad = K - len(f)
            m_all.append(jnp.concatenate([m, jnp.zeros((pad, 3), v.dtype)]))
            h_all.append(jnp.concatenate([h, jnp.zeros(pad, v.dtype)]))
            used.append((True,) * len(f) + (False,) * pad)
        self.centres = jnp.stack(centres) + shape.offset
        self.rho = jnp.stack(rhos)
        self.reach = _face_reach(self.corners, self.face_points)
        self.edge_normals = jnp.stack(m_all)
        self.edge_distances = jnp.stack(h_all)
        self.edge_used = tuple(used)

    def cop_margin(self, face, normal_force, couple):
        offset_times_n = jnp.cross(couple, self.normals[face])  # N * (CoP - centre)
        inside = normal_force * self.edge_distances[face]
        margins = inside - self.edge_normals[face] @ offset_times_n
        return jnp.min(jnp.where(jnp.asarray(self.edge_used)[face], margins, jnp.inf))


CONTACT_MODELS = {
    Sphere: SphereContact,
    Box: BoxContact,
    Cylinder: CylinderContact,
    ConvexPolyhedron: PolyhedronContact,
}
"""The contact model of each shape class (`contact_model` looks a shape up here)."""


def contact_model_class(shape: AbstractShape, parts: int = 1) -> type[AbstractContactModel]:
    """The class of `shape`'s contact model in the table, against a surface of `parts` parts
    (only a ball meets a surface of several); raises a TypeError for a shape with none. Builds
    nothing (a scene's checks call it; building a model computes its geometry)."""
    try:
        build = CONTACT_MODELS[type(shape)]
    except KeyError:
        known = ", ".join(cls.__name__ for cls in CONTACT_MODELS)
        raise TypeError(
            f"no contact model for shape {type(shape).__name__} (floor contact is modelled "
            f"for {known})"
        ) from None
    if parts != 1 and build is not SphereContact:
        raise TypeError(f"a surface of {parts} parts meets only a Sphere")
    return build


def contact_model(shape: AbstractShape, parts: int = 1) -> AbstractContactModel:
    """The contact model of `shape` from the table, against a surface of `parts` parts (only
    a ball meets a surface of several); an unknown shape is an error."""
    build = contact_model_class(shape, parts)
    if parts != 1:
        return build(shape, parts)
    return build(shape)
