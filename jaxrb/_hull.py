"""The convex hull of a few points, as faces (numpy; run once, when a shape is made).

`hull_faces(points)` returns the hull's vertices and its faces as polygons of vertex indices,
counter-clockwise seen from outside (so that (v1 - v0) x (v2 - v0) points out). Coplanar
points make one face (a cube has 6 square faces, not 12 triangles), and points inside the hull
or on its edges are dropped.

The method is direct: every triple of points spans a plane, and the plane is a face's when all
points lie on one side of it. That is O(n^4) for n points; it is meant for dice and small
hulls (at most `MAX_POINTS` points).
"""

import itertools

import numpy as np

MAX_POINTS = 200
_RELATIVE_TOL = 1e-9  # a point within this (times the hull's size) of a plane lies on it
_CHUNK = 20_000  # triples tested at once


def _planar_hull(xy: np.ndarray, tol: float) -> list[int]:
    """Indices of the 2-D convex hull of `xy` (K, 2), counter-clockwise, collinear points
    dropped (Andrew's monotone chain)."""
    order = sorted(range(len(xy)), key=lambda i: (xy[i, 0], xy[i, 1]))

    def turn(o, a, b):
        return (xy[a, 0] - xy[o, 0]) * (xy[b, 1] - xy[o, 1]) - (xy[a, 1] - xy[o, 1]) * (
            xy[b, 0] - xy[o, 0]
        )

    def chain(indices):
        out: list[int] = []
        for i in indices:
            while len(out) >= 2 and turn(out[-2], out[-1], i) <= tol:
                out.pop()
            out.append(i)
        return out

    lower, upper = chain(order), chain(order[::-1])
    return lower[:-1] + upper[:-1]


def hull_faces(points) -> tuple[np.ndarray, tuple[tuple[int, ...], ...]]:
    """(vertices (V, 3), faces): the convex hull of `points` (N, 3).

    Raises a ValueError when the points are not finite, too many, or do not span a solid.
    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("vertices must be finite")
    if not 4 <= len(p) <= MAX_POINTS:
        raise ValueError(f"a convex polyhedron needs 4 to {MAX_POINTS} vertices, got {len(p)}")
    size = float(np.max(np.ptp(p, axis=0)))
    if size <= 0:
        raise ValueError("vertices must span a solid, got coincident points")
    tol = _RELATIVE_TOL * size

    planes = []  # (unit outward normal, offset)
    triples = itertools.combinations(range(len(p)), 3)
    while len(chunk := np.array(list(itertools.islice(triples, _CHUNK)), int).reshape(-1, 3)):
        a, b, c = p[chunk[:, 0]], p[chunk[:, 1]], p[chunk[:, 2]]
        normal = np.cross(b - a, c - a)
        length = np.linalg.norm(normal, axis=1)
        spans = length > tol * size
        normal = normal[spans] / length[spans, None]
        offset = np.sum(normal * a[spans], axis=1)
        height = p @ normal.T - offset  # (N, T)
        below = np.all(height <= tol, axis=0)
        above = np.all(height >= -tol, axis=0)
        for n, o in zip(
            np.concatenate([normal[below], -normal[above & ~below]]),
            np.concatenate([offset[below], -offset[above & ~below]]),
            strict=True,
        ):
            if not any(n @ m > 1 - 1e-9 and abs(o - q) <= tol for m, q in planes):
                planes.append((n, o))
    if len(planes) < 4:
        raise ValueError("vertices must span a solid, got points in one plane")

    faces_in_points = []
    for n, o in planes:
        on = np.flatnonzero(np.abs(p @ n - o) <= tol)
        u = p[on[1]] - p[on[0]]
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        xy = np.stack([(p[on] - p[on[0]]) @ u, (p[on] - p[on[0]]) @ v], axis=1)
        ring = _planar_hull(xy, tol * size)  # counter-clockwise about n: outward
        faces_in_points.append([int(on[i]) for i in ring])

    used = sorted({i for face in faces_in_points for i in face})
    index = {old: new for new, old in enumerate(used)}
    faces = tuple(tuple(index[i] for i in face) for face in faces_in_points)
    return p[used], faces


def hull_edges(faces) -> tuple[tuple[int, int], ...]:
    """The edges (i, j), i < j, of the polygons `faces`."""
    edges = set()
    for face in faces:
        for i, j in zip(face, face[1:] + face[:1], strict=True):
            edges.add((min(i, j), max(i, j)))
    return tuple(sorted(edges))
