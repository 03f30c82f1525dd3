"""Plots of simulated motion (matplotlib). The only library module that imports matplotlib.

`import jaxrb` does not load this module; import it explicitly (`import jaxrb.plotting`).
All functions take a `jaxrb.Trajectory` (unbatched: leaves with one leading time axis) and
the `Scene` it came from, and return a matplotlib `Figure` (or save it when given a path).

Frames: heights and positions are world frame (z up, m); `omega` is plotted in the body
frame (its components on the body axes) and in the world frame; attitude is shown as the
"321" Euler angles (yaw psi about z, pitch theta about the new y, roll phi about the new x:
R = R_3(psi) R_2(theta) R_1(phi), rotations about the moving axes, body -> world).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ._run_files import run_plot_names

__all__ = [
    "animate",
    "euler321_deg",
    "impact_summary",
    "plot_angular_velocity",
    "plot_energy",
    "plot_height_attitude",
    "plot_herpolhode",
    "plot_joint_reaction",
    "plot_polhode",
    "plot_polhode_herpolhode",
    "run_plot_names",
    "save_run_plots",
    "trajectory_arrays",
]


# ---------------------------------------------------------------------------------------------
# data


def _np(x):
    return np.asarray(x, dtype=float)


def euler321_deg(quat) -> np.ndarray:
    """(yaw psi, pitch theta, roll phi) in degrees, sequence "321", unwrapped along time.

    `quat`: (T, 4) scalar-first body -> world quaternions. R = R_3(psi) R_2(theta) R_1(phi).
    """
    q = _np(quat)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    e0, e1, e2, e3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r00 = 2 * (e0**2 + e1**2) - 1
    r10 = 2 * (e1 * e2 + e0 * e3)
    r20 = 2 * (e1 * e3 - e0 * e2)
    r21 = 2 * (e2 * e3 + e0 * e1)
    r22 = 2 * (e0**2 + e3**2) - 1
    psi = np.unwrap(np.arctan2(r10, r00))
    theta = np.arcsin(np.clip(-r20, -1.0, 1.0))
    phi = np.unwrap(np.arctan2(r21, r22))
    return np.degrees(np.stack([psi, theta, phi], axis=-1))


def _axis_tilt_deg(quat) -> np.ndarray:
    """(T, 3): angle (deg) between each body axis and world +z (= row 3 of R(q))."""
    q = _np(quat)
    e0, e1, e2, e3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r2 = np.stack(
        [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), 2 * (e0**2 + e3**2) - 1], axis=-1
    )
    return np.degrees(np.arccos(np.clip(r2, -1.0, 1.0)))


def impact_summary(traj, scene) -> dict:
    """Impact times (s) and energy lost at each impact (J) from the trajectory's records.

    Returns a dict with numpy arrays `times` and `energy_lost` (empty when the scene has no
    floor or nothing hit it).
    """
    from . import _host

    empty = {"times": np.zeros(0), "energy_lost": np.zeros(0)}
    imp = getattr(traj, "impacts", None)
    if imp is None:
        return empty
    times = getattr(imp, "times", getattr(imp, "time", None))
    if times is None:
        return empty
    times = _np(times)
    valid = np.isfinite(times)
    count = getattr(imp, "count", None)  # an ImpactRecord's first `count` slots are used
    if count is not None:
        valid &= np.arange(times.shape[-1]) < _np(count)[..., None]
    times, valid = times.reshape(-1), valid.reshape(-1)
    lost = getattr(imp, "energy_lost", None)
    if lost is None and hasattr(imp, "state_before") and hasattr(imp, "state_after"):
        lost = _np(_host.energy(scene, imp.state_before)) - _np(
            _host.energy(scene, imp.state_after)
        )
    lost = np.full_like(times, np.nan) if lost is None else _np(lost).reshape(-1)
    return {"times": times[valid], "energy_lost": lost[valid]}


def trajectory_arrays(traj, scene) -> dict:
    """The trajectory as numpy arrays (one row per save time).

    Keys: `t` (s); `pos`, `vel` (world, m, m/s); `quat` (scalar first, body -> world);
    `omega` (body frame, rad/s); `omega_world` (rad/s); `euler321_deg`; `energy`,
    `kinetic_translation`, `kinetic_rotation`, `potential` (J); `lowest_z` (m, world z of the
    lowest point of the shape, or of the mass centre without a shape).
    """
    from . import _host

    s = traj.states
    body = scene.body
    quat = _np(s.quat)
    omega = _np(s.omega)
    vel = _np(s.vel)
    pos = _np(s.pos)
    mass = float(body.mass)
    J = _np(body.inertia_matrix)
    energy = _np(_host.energy(scene, s))
    kin_t = 0.5 * mass * np.sum(vel**2, axis=-1)
    kin_r = 0.5 * np.einsum("ti,ij,tj->t", omega, J, omega)
    omega_world = _np(_host.omega_world(s))
    lowest_z = _np(_host.lowest_z(body.shape, s)) if body.shape is not None else pos[:, 2].copy()
    return {
        "t": _np(traj.ts),
        "pos": pos,
        "vel": vel,
        "quat": quat,
        "omega": omega,
        "omega_world": omega_world,
        "euler321_deg": euler321_deg(quat),
        "axis_tilt_deg": _axis_tilt_deg(quat),
        "energy": energy,
        "kinetic_translation": kin_t,
        "kinetic_rotation": kin_r,
        "potential": energy - kin_t - kin_r,
        "lowest_z": lowest_z,
    }


def _finish(fig, path):
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110, bbox_inches="tight")
    return fig


def _legend(ax, ncol=1):
    """A legend outside the axes, to their right, so that it never covers data."""
    ax.legend(
        loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small", ncol=ncol
    )


def _mark_impacts(ax, times):
    """A dotted vertical line across `ax` at each impact time (s): one artist for all."""
    if len(times):
        transform = ax.get_xaxis_transform()  # x in data, y from 0 to 1 of the axes
        ax.vlines(times, 0, 1, transform=transform, colors="0.6", lw=0.8, ls=":", label="impact")


# ---------------------------------------------------------------------------------------------
# time histories


def plot_height_attitude(traj, scene, path=None, title=None):
    """Height (world z, m) and attitude over time.

    Panels: the mass centre's height and that of the body's lowest point; the attitude
    quaternion (scalar first, body -> world; continuous, never singular); the angle of each
    body axis to the world vertical +z (deg; for a die, the axis near 0 or 180 deg tells which
    face is up).

    **Returns:** the `Figure` (saved to `path` if given).
    """
    a = trajectory_arrays(traj, scene)
    imp = impact_summary(traj, scene)
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    ax1.plot(a["t"], a["pos"][:, 2], label="mass centre z")
    if scene.body.shape is not None:
        ax1.plot(a["t"], a["lowest_z"], label="lowest point z", lw=1)
    level = scene.floor is not None and not scene.floor.curved
    if level and float(np.asarray(scene.floor.normal)[2]) == 1.0:  # a level floor
        ax1.axhline(float(scene.floor.height), color="k", lw=1, label="floor")
    ax1.set_ylabel("height z (m)")
    for k in range(4):
        ax2.plot(a["t"], a["quat"][:, k], label=f"e{k}")
    ax2.set_ylabel("attitude quaternion")
    for k, name in enumerate(("xi (body 1)", "eta (body 2)", "zeta (body 3)")):
        ax3.plot(a["t"], a["axis_tilt_deg"][:, k], label=name)
    ax3.set_ylabel("body axis to world +z (deg)")
    ax3.set_yticks([0, 45, 90, 135, 180])
    ax3.set_xlabel("time t (s)")
    for ax in (ax1, ax2, ax3):
        _mark_impacts(ax, imp["times"])
        _legend(ax)
        ax.grid(alpha=0.3)
    if title:
        ax1.set_title(title)
    return _finish(fig, path)


def plot_angular_velocity(traj, scene, path=None, title=None):
    """Angular velocity (rad/s): body-frame components and |omega|, and world-frame components."""
    a = trajectory_arrays(traj, scene)
    imp = impact_summary(traj, scene)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for k, name in enumerate(("xi", "eta", "zeta")):
        ax1.plot(a["t"], a["omega"][:, k], label=f"omega_{name} (body {k + 1})")
    ax1.plot(a["t"], np.linalg.norm(a["omega"], axis=-1), "k--", lw=1, label="|omega|")
    ax1.set_ylabel("body frame (rad/s)")
    for k, name in enumerate("xyz"):
        ax2.plot(a["t"], a["omega_world"][:, k], label=f"omega_{name} (world)")
    ax2.set_ylabel("world frame (rad/s)")
    ax2.set_xlabel("time t (s)")
    for ax in (ax1, ax2):
        _mark_impacts(ax, imp["times"])
        _legend(ax)
        ax.grid(alpha=0.3)
    if title:
        ax1.set_title(title)
    return _finish(fig, path)


def plot_energy(traj, scene, path=None, title=None):
    """Energy over time (J), what physics took out, and the solver's drift, each on its own axes.

    Panels: total, kinetic (translation, rotation) and potential energy; the physical losses:
    the energy lost at each impact (a scene with a floor) or the energy removed by the forces
    without a potential (drag, damping, wrenches), -W(t); and, without a floor, the solver's
    drift E(t) - E(0) - W(t), which physics says is zero (`jaxrb._energy_budget`). With a floor
    the drift is not separated: the work of sliding friction is not recorded.
    """
    from ._energy_budget import energy_budget

    a = trajectory_arrays(traj, scene)
    imp = impact_summary(traj, scene)
    budget = energy_budget(traj, scene)
    panels = [_energy_parts]
    if scene.floor is not None:
        panels.append(_impact_losses)
    elif budget["nonpotential"]:
        panels.append(_work_removed)
    if budget["drift"] is not None:
        panels.append(_solver_drift)
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 1.0 + 2.6 * len(panels)))
    for ax, panel in zip(np.atleast_1d(axes), panels, strict=True):
        panel(ax, a, imp, budget)
        ax.grid(alpha=0.3)
    if title:
        np.atleast_1d(axes)[0].set_title(title)
    return _finish(fig, path)


def _energy_parts(ax, a, imp, budget):
    ax.plot(a["t"], a["energy"], "k", label="total E")
    ax.plot(a["t"], a["kinetic_translation"], label="kinetic, translation")
    ax.plot(a["t"], a["kinetic_rotation"], label="kinetic, rotation")
    ax.plot(a["t"], a["potential"], label="potential")
    _mark_impacts(ax, imp["times"])
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("energy (J)")
    _legend(ax)


def _impact_losses(ax, a, imp, budget):
    if imp["times"].size:
        n = np.arange(1, imp["times"].size + 1)
        ax.bar(n, imp["energy_lost"], color="C3")
        ax.set_xticks(n if n.size <= 20 else n[:: max(1, n.size // 10)])
    else:
        ax.text(0.02, 0.85, "no impacts", transform=ax.transAxes, fontsize="small")
    ax.set_xlabel("impact number")
    ax.set_ylabel("lost at impact (J)")
    ax.set_title(
        "energy lost at each impact (sliding friction and solver drift are not separated)",
        fontsize="small",
    )


def _work_removed(ax, a, imp, budget):
    names = ", ".join(budget["nonpotential"])
    ax.plot(a["t"], -budget["work"], "C3", label=f"-W(t): {names}")
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("energy removed (J)")
    ax.set_title("physical: work of the forces without a potential", fontsize="small")
    _legend(ax)


def _solver_drift(ax, a, imp, budget):
    label = "E(t) - E(0) - W(t)" if budget["nonpotential"] else "E(t) - E(0)"
    ax.plot(a["t"], budget["drift"], "C7", label=label)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("solver drift (J)")
    ax.set_title("numerical: the solver's energy drift (physics: zero)", fontsize="small")
    _legend(ax)


def plot_joint_reaction(traj, scene, path=None, title=None):
    """The joint reaction O (N), the force the joint exerts on the body (`jaxrb._reaction`).

    Hinge: O_n (along the line from the mass centre to the axis, positive towards the axis),
    O_t (across it, positive against increasing angle) and |O| against the hinge angle theta
    (deg), over their closed forms when the body was released from rest with its mass centre
    level with a horizontal axis (docs/theory.md, section 6); then the world components and
    the axial one against theta. Pivot: the world components and |O| against time.
    """
    import jax

    import jaxrb

    from ._reaction import reaction_arrays, released_pendulum

    r = reaction_arrays(traj, scene)
    if not isinstance(scene.joint, jaxrb.Hinge):
        fig, ax = plt.subplots(figsize=(10, 4))
        _reaction_world(ax, np.asarray(traj.ts, float), r)
        ax.set_xlabel("time t (s)")
        axes = [ax]
    else:
        fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
        release = released_pendulum(scene, jax.tree.map(lambda x: x[0], traj.states))
        _reaction_hinge(axes[0], r, release)
        theta = np.degrees(r["joint_angle"])
        _reaction_world(axes[1], theta, r)
        axes[1].plot(theta, r["reaction_axial"], ":", label="O_a (along the axis)")
        _legend(axes[1])
        axes[1].set_xlabel("hinge angle theta (deg, about the axis, 0 at the start)")
    if title:
        axes[0].set_title(title)
    return _finish(fig, path)


def _reaction_world(ax, x, r):
    for k, name in enumerate("xyz"):
        ax.plot(x, r["reaction"][:, k], label=f"O_{name} (world)")
    ax.plot(x, r["reaction_magnitude"], "k--", lw=1, label="|O|")
    ax.set_ylabel("joint reaction (N)")
    ax.grid(alpha=0.3)
    _legend(ax)


def _reaction_hinge(ax, r, release):
    theta = np.degrees(r["joint_angle"])
    ax.plot(theta, r["reaction_normal"], "C0", label="O_n (towards the axis)")
    ax.plot(theta, r["reaction_tangential"], "C1", label="O_t (against increasing theta)")
    ax.plot(theta, r["reaction_magnitude"], "C2", label="|O|")
    if release is not None:
        on, ot = release.reaction(r["joint_angle"])
        ax.plot(theta, on, "k--", lw=1, label="closed form m g (1 + 2 rbar^2/k_O^2) sin(theta)")
        ax.plot(theta, ot, "k:", lw=1.2, label="closed form m g (1 - rbar^2/k_O^2) cos(theta)")
    ax.set_ylabel("bearing force (N)")
    ax.grid(alpha=0.3)
    _legend(ax)


def save_run_plots(traj, scene, outdir, title=None) -> list[Path]:
    """Write the standard PNGs of `jaxrb run` into `outdir`; returns their paths.

    Files (`run_plot_names`): `height_attitude.png`, `angular_velocity.png`, `energy.png`,
    and for a scene with a joint `reaction.png`.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    plots = {
        "height_attitude.png": plot_height_attitude,
        "angular_velocity.png": plot_angular_velocity,
        "energy.png": plot_energy,
        "reaction.png": plot_joint_reaction,
    }
    paths = []
    for name in run_plot_names(scene):
        fig = plots[name](traj, scene, path=outdir / name, title=title)
        plt.close(fig)
        paths.append(outdir / name)
    return paths


# ---------------------------------------------------------------------------------------------
# torque-free motion: polhode and herpolhode


def plot_polhode(inertia, omegas, ax=None, path=None, labels=None):
    """Polhodes: paths of the BODY-frame angular velocity on the energy ellipsoid.

    **Arguments:**

    - `inertia`: principal moments (I1, I2, I3), kg m^2.
    - `omegas`: a (T, 3) array or a list of them: body-frame omega(t) of torque-free motions.
      The ellipsoid drawn is w.I w = 2 E of the first one; curves of other energies are
      scaled onto it (the polhode's shape depends only on L^2 / (2 E)).
    - `ax`: an existing 3D axes; `path`: save the figure there.

    **Returns:** the `Figure`.
    """
    inertia = _np(inertia)
    if isinstance(omegas, np.ndarray | list | tuple) and np.ndim(omegas[0]) == 1:
        omegas = [omegas]
    omegas = [_np(w) for w in omegas]
    twoE = float(np.einsum("i,i,i->", omegas[0][0], inertia, omegas[0][0]))
    if ax is None:
        fig = plt.figure(figsize=(6, 6))
        ax = fig.add_subplot(projection="3d")
    fig = ax.figure
    axes = np.sqrt(twoE / inertia)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40), np.linspace(0, np.pi, 20))
    ax.plot_wireframe(
        axes[0] * np.cos(u) * np.sin(v),
        axes[1] * np.sin(u) * np.sin(v),
        axes[2] * np.cos(v),
        color="0.8",
        lw=0.4,
    )
    for i, w in enumerate(omegas):
        scale = np.sqrt(twoE / np.einsum("i,i,i->", w[0], inertia, w[0]))
        ws = w * scale
        ax.plot(ws[:, 0], ws[:, 1], ws[:, 2], lw=1.5, label=None if labels is None else labels[i])
    ax.set_xlabel("omega_1 (rad/s)")
    ax.set_ylabel("omega_2 (rad/s)")
    ax.set_zlabel("omega_3 (rad/s)")
    ax.set_box_aspect(axes)
    moments = ", ".join(f"{x:.3g}" for x in inertia)
    ax.set_title(f"polhode on the energy ellipsoid\nI = ({moments}) kg m^2")
    if labels is not None:
        ax.legend(fontsize="small")
    return _finish(fig, path)


def plot_herpolhode(omega_world, angular_momentum_world, ax=None, path=None):
    """Herpolhode: the WORLD-frame angular velocity's tip on the invariable plane.

    The invariable plane is perpendicular to the (constant) angular momentum L; the tip of
    omega stays in it (omega . L = 2 E). The curve is drawn in plane coordinates (rad/s).
    """
    w = _np(omega_world)
    L = _np(angular_momentum_world).reshape(-1, 3)[0]
    n = L / np.linalg.norm(L)
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 6))
    fig = ax.figure
    ax.plot(w @ e1, w @ e2, lw=1)
    ax.plot([0], [0], "k+", ms=10, label="foot of L")
    ax.set_aspect("equal")
    ax.set_xlabel("in-plane component 1 (rad/s)")
    ax.set_ylabel("in-plane component 2 (rad/s)")
    height = np.mean(w @ n)
    ax.set_title(f"herpolhode on the invariable plane\n(omega . L/|L| = {height:.3g} rad/s)")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return _finish(fig, path)


def plot_polhode_herpolhode(traj, scene, path=None):
    """Polhode (body frame) and herpolhode (world frame) of a torque-free trajectory side by side.

    The scene must have principal inertia (three moments).
    """
    import jaxrb

    a = trajectory_arrays(traj, scene)
    inertia = np.diag(_np(scene.body.inertia_matrix))
    fig = plt.figure(figsize=(12, 5.5))
    ax1 = fig.add_subplot(1, 2, 1, projection="3d")
    plot_polhode(inertia, a["omega"], ax=ax1)
    ax2 = fig.add_subplot(1, 2, 2)
    L = _np(jaxrb.angular_momentum(scene, traj.states))
    plot_herpolhode(a["omega_world"], L, ax=ax2)
    return _finish(fig, path)


def animate(traj, scene, path=None, **kwargs):
    """A 3D animation of the tumbling body (see `jaxrb._animation.animate`); GIF when `path`."""
    from ._animation import animate as _animate

    return _animate(traj, scene, path=path, **kwargs)
