"""3D animation of a tumbling body (matplotlib; imported lazily by `jaxrb.plotting.animate`)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib import animation
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ._surfaces import Bowl, Wheel


def _box_faces(half):
    hx, hy, hz = half
    c = np.array(
        [[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    )
    idx = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [c[list(f)] for f in idx]


def _cylinder_faces(radius, half_height, n=24):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)], -1)
    top, bottom = ring + [0, 0, half_height], ring - [0, 0, half_height]
    sides = [np.array([bottom[i], bottom[(i + 1) % n], top[(i + 1) % n], top[i]]) for i in range(n)]
    return [top, bottom, *sides]


def _sphere_faces(radius, n=10):
    u = np.linspace(0, 2 * np.pi, 2 * n + 1)
    v = np.linspace(0, np.pi, n + 1)
    p = lambda i, j: (
        radius * np.array([np.cos(u[i]) * np.sin(v[j]), np.sin(u[i]) * np.sin(v[j]), np.cos(v[j])])
    )
    return [
        np.array([p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)])
        for i in range(2 * n)
        for j in range(n)
    ]


def body_faces(scene):
    """Polygons (body frame, m) drawing the scene's body; face colours alternate per face.

    Without a shape (or with one it cannot draw): the box with the same principal moments
    (equivalent uniform cuboid).
    """
    import jaxrb

    shape = scene.body.shape
    faces = None
    if isinstance(shape, jaxrb.Box):
        faces = _box_faces(np.asarray(shape.half_extents, float))
    elif isinstance(shape, jaxrb.Cylinder):
        faces = _cylinder_faces(float(shape.radius), float(shape.half_height))
    elif isinstance(shape, jaxrb.Sphere):
        faces = _sphere_faces(float(shape.radius))
    elif isinstance(shape, jaxrb.ConvexPolyhedron):
        vertices = np.asarray(shape.vertices, float)
        faces = [vertices[list(f)] for f in shape.faces]
    if faces is not None:  # the shape's centre sits at its offset from the mass centre
        return [f + np.asarray(shape.offset, float) for f in faces]
    J = np.asarray(scene.body.inertia_matrix, float)
    moments = np.linalg.eigvalsh(J) if not np.allclose(J, np.diag(np.diag(J))) else np.diag(J)
    m = float(scene.body.mass)
    i1, i2, i3 = moments
    sq = np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3]) * 6 / m
    return _box_faces(np.sqrt(np.maximum(sq, 1e-12 * sq.max())) / 2)


def _rotations(quat) -> np.ndarray:
    """R(q) (T, 3, 3) of unit quaternions (T, 4), scalar first, body -> world."""
    q = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    e0, e = q[:, 0], q[:, 1:]
    # R = (2 e0^2 - 1) I + 2 e e^T + 2 e0 skew(e)
    skew = np.zeros((len(q), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -e[:, 2], e[:, 1], -e[:, 0]
    skew = skew - np.swapaxes(skew, 1, 2)
    return (
        (2 * e0**2 - 1)[:, None, None] * np.eye(3)
        + 2 * e[:, :, None] * e[:, None, :]
        + 2 * e0[:, None, None] * skew
    )


def surface_mesh(surface, limits, num=25):
    """Grids (X, Y, Z) (m, world) of a curved surface (a `Bowl` or `Cone` over the view's
    horizontal extent `limits` (3, 2); a `Wheel`'s track and the foot of its wall), for a
    wireframe."""
    reach = float(np.max(np.abs(limits[:2])))
    phi = np.linspace(0.0, 2 * np.pi, 2 * num)
    if isinstance(surface, Bowl):
        R, h = float(surface.radius), float(surface.height)
        top = min(np.arcsin(min(reach / R, 1.0)), 0.5 * np.pi)
        theta = np.linspace(0.0, top, num)[:, None]
        rho, z = R * np.sin(theta), h + R - R * np.cos(theta)
    elif isinstance(surface, Wheel):  # the track up to the wall, then the wall's lower part
        R, slope = float(surface.wall_radius), np.tan(float(surface.inclination))
        rim = float(surface.height) + slope * R
        rho = np.concatenate([np.linspace(0.0, R, num), np.full(4, R)])[:, None]
        wall = rim + 0.05 * R * np.arange(1, 5)
        z = np.concatenate([float(surface.height) + slope * rho[:num, 0], wall])[:, None]
    else:
        rho = np.linspace(0.0, reach, num)[:, None]
        z = float(surface.height) + np.tan(float(surface.inclination)) * rho
    return rho * np.cos(phi), rho * np.sin(phi), z + 0.0 * phi


def world_limits(points, floor_z=None, margin=0.08, min_fraction=0.25):
    """Fixed axis limits (3, 2) in m that hold `points` (N, 3, world) and the floor plane.

    Each range is padded by `margin` of the largest range and widened to at least
    `min_fraction` of it, so that a flat motion still gets a visible depth.
    """
    lo, hi = points.min(axis=0), points.max(axis=0)
    if floor_z is not None:
        lo[2], hi[2] = min(lo[2], floor_z), max(hi[2], floor_z)
    span = max(float(np.max(hi - lo)), 1e-9)
    half = np.maximum(0.5 * (hi - lo), 0.5 * min_fraction * span) + margin * span
    centre = 0.5 * (lo + hi)
    return np.stack([centre - half, centre + half], axis=-1)


def animate(traj, scene, path=None, *, fps=20, max_frames=60, view="world", trail=True, title=None):
    """Animate the body's motion in 3D.

    **Arguments:**

    - `traj`, `scene`: an unbatched `jaxrb.Trajectory` and its `Scene`.
    - `path`: if given, save a GIF there (pillow writer).
    - `fps`: frames per second of the GIF; `max_frames`: the save times are subsampled to at
      most this many frames.
    - `view`: "world" (a fixed camera: the same limits in every frame, holding the whole
      motion of the body, the floor and a joint's fixed point, equal scales on the three
      axes) or "follow" (axes centred on the body, a few body sizes wide; the floor may
      leave the view).
    - `trail`: draw the path of the mass centre.

    **Returns:** the `matplotlib.animation.FuncAnimation`.

    World frame, z up; the body is drawn at R(q) x + pos, q scalar-first body -> world.
    """
    if view not in ("world", "follow"):
        raise ValueError(f"view must be 'world' or 'follow', got {view!r}")
    ts = np.asarray(traj.ts, float)
    pos = np.asarray(traj.states.pos, float)
    R = _rotations(np.asarray(traj.states.quat, float))
    faces = body_faces(scene)
    size = max(float(np.max(np.abs(np.concatenate(faces)))), 1e-9)
    frames = np.unique(np.linspace(0, len(ts) - 1, min(max_frames, len(ts))).round().astype(int))
    plane = scene.floor is not None and not scene.floor.curved  # a bowl or cone: not drawn
    floor_z = float(scene.floor.height) if plane else None
    floor_n = np.asarray(scene.floor.normal, float) if plane else None
    anchor = None
    if scene.joint is not None:
        anchor = pos[0] + R[0] @ np.asarray(scene.joint.point, float)
    corners = np.concatenate(faces)
    points = np.concatenate([corners @ R[k].T + pos[k] for k in range(len(ts))])
    limits = world_limits(points if anchor is None else np.vstack([points, anchor]), floor_z)

    fig = plt.figure(figsize=(5.5, 5.5))
    ax = fig.add_subplot(projection="3d")
    ax.computed_zorder = False  # drawn in zorder: floor, body, trail, the joint's fixed point
    colors = ["#d9534f", "#5bc0de", "#5cb85c", "#f0ad4e", "#8e6fd8", "#eeeeee"]
    poly = Poly3DCollection([], edgecolor="k", linewidths=0.5, zorder=1)
    ax.add_collection3d(poly)
    (trail_line,) = ax.plot([], [], [], "C0", lw=1, zorder=2)
    if anchor is not None:  # the joint's fixed point and the line from it to the mass centre
        ax.plot(*([c] for c in anchor), "ko", ms=5, zorder=3)
    (stem,) = ax.plot([], [], [], "k-", lw=1.2, zorder=3)
    floor = Poly3DCollection([], facecolor="0.75", alpha=0.4, edgecolor="0.5", zorder=0)
    if floor_z is not None:
        ax.add_collection3d(floor)
    elif scene.floor is not None:  # a bowl or cone: a wireframe of it under the view
        ax.plot_wireframe(*surface_mesh(scene.floor, limits), color="0.55", lw=0.4, zorder=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(plt.MaxNLocator(4))
    time_text = ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    if title:
        ax.set_title(title)

    def set_view(lims):
        for setter, (lo, hi) in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), lims, strict=True):
            setter(lo, hi)
        ax.set_box_aspect(tuple(lims[:, 1] - lims[:, 0]))
        if floor_z is not None:
            (x0, x1), (y0, y1) = lims[0], lims[1]
            corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
            # the plane n . (p - (0, 0, h)) = 0 over the view (a tilted floor's normal has
            # n_z > 0 wherever it can carry a body under gravity)
            nx, ny, nz = floor_n
            z = [floor_z - (nx * x + ny * y) / max(nz, 1e-6) for x, y in corners]
            floor.set_verts([np.array([[x, y, zz] for (x, y), zz in zip(corners, z, strict=True)])])

    half = 3 * size
    set_view(limits)

    def update(k):
        polys = [f @ R[k].T + pos[k] for f in faces]
        poly.set_verts(polys)
        poly.set_facecolor([colors[i % len(colors)] for i in range(len(polys))])
        if trail:
            path = pos[: k + 1].copy()
            if view == "follow":  # 3D lines are not clipped: hide the part outside the view
                path[np.any(np.abs(path - pos[k]) > half, axis=-1)] = np.nan
            trail_line.set_data_3d(path[:, 0], path[:, 1], path[:, 2])
        if anchor is not None:
            stem.set_data_3d(*np.stack([anchor, pos[k]], axis=-1))
        if view == "follow":
            set_view(pos[k][:, None] + np.array([-half, half]))
        time_text.set_text(f"t = {ts[k]:.3f} s")
        return poly, trail_line, stem, time_text

    anim = animation.FuncAnimation(fig, update, frames=frames, interval=1000 / fps, blit=False)
    if path is not None:
        # mplot3d pads polygons with fewer vertices (a cylinder's sides next to its caps) with
        # NaN, which numpy reports as an overflow when projecting them: not an error here
        with np.errstate(over="ignore", invalid="ignore"):
            anim.save(path, writer=animation.PillowWriter(fps=fps))
    return anim
