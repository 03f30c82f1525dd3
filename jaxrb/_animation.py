"""3D animation of a tumbling body (matplotlib; imported lazily by `jaxrb.plotting.animate`)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib import animation
from mpl_toolkits.mplot3d.art3d import Poly3DCollection


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

    Without a shape: the box with the same principal moments (equivalent uniform cuboid).
    """
    import jaxrb

    shape = scene.body.shape
    if isinstance(shape, jaxrb.Box):
        return _box_faces(np.asarray(shape.half_extents, float))
    if isinstance(shape, jaxrb.Cylinder):
        return _cylinder_faces(float(shape.radius), float(shape.half_height))
    if isinstance(shape, jaxrb.Sphere):
        return _sphere_faces(float(shape.radius))
    J = np.asarray(scene.body.inertia_matrix, float)
    moments = np.linalg.eigvalsh(J) if not np.allclose(J, np.diag(np.diag(J))) else np.diag(J)
    m = float(scene.body.mass)
    i1, i2, i3 = moments
    sq = np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3]) * 6 / m
    return _box_faces(np.sqrt(np.maximum(sq, 1e-12 * sq.max())) / 2)


def animate(traj, scene, path=None, *, fps=20, max_frames=60, view="auto", trail=True, title=None):
    """Animate the body's motion in 3D.

    **Arguments:**

    - `traj`, `scene`: an unbatched `jaxrb.Trajectory` and its `Scene`.
    - `path`: if given, save a GIF there (pillow writer).
    - `fps`: frames per second of the GIF; `max_frames`: the save times are subsampled to at
      most this many frames.
    - `view`: "world" (fixed axes covering the whole trajectory), "follow" (axes centred on
      the body, a few body sizes wide) or "auto" (follow when the body is small compared
      with the distance it travels).
    - `trail`: draw the path of the mass centre.

    **Returns:** the `matplotlib.animation.FuncAnimation`.

    World frame, z up; the body is drawn at R(q) x + pos, q scalar-first body -> world.
    """
    ts = np.asarray(traj.ts, float)
    pos = np.asarray(traj.states.pos, float)
    quat = np.asarray(traj.states.quat, float)
    quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    e0, e = quat[:, 0], quat[:, 1:]
    # R = (2 e0^2 - 1) I + 2 e e^T + 2 e0 skew(e)
    skew = np.zeros((len(ts), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -e[:, 2], e[:, 1], -e[:, 0]
    skew = skew - np.swapaxes(skew, 1, 2)
    R = (
        (2 * e0**2 - 1)[:, None, None] * np.eye(3)
        + 2 * e[:, :, None] * e[:, None, :]
        + 2 * e0[:, None, None] * skew
    )
    faces = body_faces(scene)
    size = max(float(np.max(np.abs(np.concatenate(faces)))), 1e-9)
    extent = float(np.max(np.ptp(pos, axis=0)))
    if view == "auto":
        view = "follow" if extent > 12 * size else "world"
    if view not in ("world", "follow"):
        raise ValueError(f"view must be 'auto', 'world' or 'follow', got {view!r}")
    frames = np.unique(np.linspace(0, len(ts) - 1, min(max_frames, len(ts))).round().astype(int))

    fig = plt.figure(figsize=(5.5, 5.5))
    ax = fig.add_subplot(projection="3d")
    colors = ["#d9534f", "#5bc0de", "#5cb85c", "#f0ad4e", "#8e6fd8", "#eeeeee"]
    poly = Poly3DCollection([], edgecolor="k", linewidths=0.5)
    ax.add_collection3d(poly)
    (trail_line,) = ax.plot([], [], [], "C0", lw=1)
    half = 3 * size if view == "follow" else 0.5 * extent + 1.5 * size
    centre_world = 0.5 * (pos.min(0) + pos.max(0))
    floor_z = float(scene.floor.height) if scene.floor is not None else None
    floor = Poly3DCollection([], facecolor="0.75", alpha=0.4, edgecolor="0.5")
    if floor_z is not None:
        ax.add_collection3d(floor)
    time_text = ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_box_aspect((1, 1, 1))
    if title:
        ax.set_title(title)

    def set_view(centre):
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
            setter(c - half, c + half)
        if floor_z is not None:
            x0, x1, y0, y1 = centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half
            floor.set_verts(
                [
                    np.array(
                        [[x0, y0, floor_z], [x1, y0, floor_z], [x1, y1, floor_z], [x0, y1, floor_z]]
                    )
                ]
            )

    if view == "world":
        set_view(centre_world)

    def update(k):
        polys = [f @ R[k].T + pos[k] for f in faces]
        poly.set_verts(polys)
        poly.set_facecolor([colors[i % len(colors)] for i in range(len(polys))])
        if trail:
            path = pos[: k + 1].copy()
            if view == "follow":  # 3D lines are not clipped: hide the part outside the view
                path[np.any(np.abs(path - pos[k]) > half, axis=-1)] = np.nan
            trail_line.set_data_3d(path[:, 0], path[:, 1], path[:, 2])
        if view == "follow":
            set_view(pos[k])
        time_text.set_text(f"t = {ts[k]:.3f} s")
        return poly, trail_line, time_text

    anim = animation.FuncAnimation(fig, update, frames=frames, interval=1000 / fps, blit=False)
    if path is not None:
        anim.save(path, writer=animation.PillowWriter(fps=fps))
    return anim
