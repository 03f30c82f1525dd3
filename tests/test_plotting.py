"""Plots: `import jaxrb` does not load matplotlib; each plot writes a PNG (Agg backend)."""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
import jaxrb.analytic

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import jaxrb.plotting as plotting  # noqa: E402


def test_import_jaxrb_does_not_import_matplotlib():
    code = "import sys, jaxrb; assert not any(m.startswith('matplotlib') for m in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


def _trajectory(ts, states):
    """A `jaxrb.Trajectory` made by hand from known states (no solver)."""
    return jaxrb.Trajectory(
        ts=ts,
        states=states,
        result=jaxrb.RESULTS.successful,
        quat_norm_drift=jnp.zeros(()),
        num_steps=jnp.zeros((), int),
    )


@pytest.fixture(scope="module")
def traj_scene():
    """A hand-made torque-free trajectory (exact symmetric-top omega; no solver, no compile)."""
    body = jaxrb.RigidBody(1.0, jnp.array([1.0, 1.0, 2.0]), shape=jaxrb.Box((0.3, 0.2, 0.1)))
    scene = jaxrb.Scene(body, floor=jaxrb.Floor(0.5))
    ts = jnp.linspace(0.0, 2.0, 41)
    exact = jaxrb.analytic.symmetric_top(ts, 1.0, 2.0, jnp.array([0.4, 0.0, 1.0]))
    states = jaxrb.State(
        pos=jnp.stack([ts, 0 * ts, 1.0 + 0 * ts], -1),
        quat=exact.quat,
        vel=jnp.stack([1.0 + 0 * ts, 0 * ts, 0 * ts], -1),
        omega=exact.omega,
    )
    traj = _trajectory(ts, states)
    return traj, scene


def test_trajectory_arrays(traj_scene):
    traj, scene = traj_scene
    a = plotting.trajectory_arrays(traj, scene)
    # body x, y, z axes at 90, 90, 0 deg to world z at t = 0 (identity attitude)
    np.testing.assert_allclose(a["axis_tilt_deg"][0], [90.0, 90.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(
        a["lowest_z"],
        1.0
        - np.asarray(
            [
                float(jnp.abs(jaxrb.quat_to_matrix(q)[2]) @ jnp.array([0.3, 0.2, 0.1]))
                for q in traj.states.quat
            ]
        ),
        atol=1e-12,
    )
    np.testing.assert_allclose(a["kinetic_rotation"], 0.5 * (0.4**2 + 2.0), rtol=1e-12)
    np.testing.assert_allclose(a["euler321_deg"][0], 0.0, atol=1e-12)


def test_run_plots_and_polhode(traj_scene, tmp_path):
    traj, scene = traj_scene
    paths = plotting.save_run_plots(traj, scene, tmp_path, title="test")
    assert [p.name for p in paths] == ["height_attitude.png", "angular_velocity.png", "energy.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    plotting.plot_polhode_herpolhode(
        traj,
        jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([1.0, 1.0, 2.0]))),
        path=tmp_path / "polhode.png",
    )
    assert (tmp_path / "polhode.png").stat().st_size > 1000


def test_animation_gif(traj_scene, tmp_path):
    from PIL import Image

    traj, scene = traj_scene
    plotting.animate(traj, scene, tmp_path / "a.gif", max_frames=5, view="world")
    with Image.open(tmp_path / "a.gif") as im:
        assert im.n_frames == 5


def _legends_outside(fig):
    """Every legend of `fig` lies beside its axes (never over data) and inside the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axes = [ax for ax in fig.axes if ax.get_legend() is not None]
    for ax in axes:
        box = ax.get_legend().get_window_extent(renderer)
        assert not box.overlaps(ax.get_window_extent(renderer)), ax.get_ylabel()
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1, ax.get_ylabel()
    return len(axes)


def test_legends_never_cover_data(traj_scene):
    traj, scene = traj_scene
    for plot in (plotting.plot_height_attitude, plotting.plot_angular_velocity):
        fig = plot(traj, scene)
        assert _legends_outside(fig) == len(fig.axes)
        plotting.plt.close(fig)


@pytest.fixture(scope="module")
def pendulum():
    """The sample pendulum's exact motion (Jacobi elliptic functions; no solver), expanded
    through its hinge: m = 7.5 kg, rbar = 0.25 m, k_O = 0.295 m, released with OC level."""
    m, rbar, k_O = 7.5, 0.25, 0.295
    J_C = m * (k_O**2 - rbar**2)

    def make(axis_sign):
        hinge = jaxrb.Hinge((-rbar, 0.0, 0.0), (0.0, axis_sign, 0.0))
        body = jaxrb.RigidBody(m, jnp.array([0.02, J_C, 0.17]))
        scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=hinge)
        state0 = jaxrb.make_state(pos=(rbar, 0.0, 0.0))
        ts = jnp.linspace(0.0, 0.69, 47)
        theta = jaxrb.analytic.pendulum_theta(ts, rbar, k_O)
        theta_dot = jaxrb.analytic.pendulum_theta_dot(ts, rbar, k_O)
        states = hinge.expand((axis_sign * theta, axis_sign * theta_dot), state0)
        traj = _trajectory(ts, states)
        return traj, scene, np.asarray(theta)

    return make


@pytest.mark.parametrize("axis_sign", [1.0, -1.0])
def test_hinge_reaction_components(pendulum, axis_sign):
    """On the exact motion the reaction's O_n, O_t are the closed forms of docs/theory.md,
    section 6, to roundoff. With the axis reversed the body falls the same way while the hinge
    angle runs negative: O_n (towards the axis) is unchanged, O_t (against increasing hinge
    angle) changes sign, and `PendulumRelease.reaction` of the hinge angle says the same."""
    from jaxrb._reaction import reaction_arrays, released_pendulum

    traj, scene, theta = pendulum(axis_sign)
    r = reaction_arrays(traj, scene)
    np.testing.assert_allclose(r["joint_angle"], axis_sign * theta, atol=1e-12)
    On, Ot, mag = jaxrb.analytic.pendulum_bearing_force(theta, 7.5, 0.25, 0.295)
    tol = 1e-12 * 7.5 * 9.81
    np.testing.assert_allclose(r["reaction_normal"], On, atol=tol)
    np.testing.assert_allclose(r["reaction_tangential"], axis_sign * np.asarray(Ot), atol=tol)
    np.testing.assert_allclose(r["reaction_magnitude"], mag, atol=tol)
    release = released_pendulum(scene, jaxrb.make_state(pos=(0.25, 0.0, 0.0)))
    assert release.sign == axis_sign
    on, ot = release.reaction(r["joint_angle"])
    np.testing.assert_allclose(on, r["reaction_normal"], atol=tol)
    np.testing.assert_allclose(ot, r["reaction_tangential"], atol=tol)


def test_released_pendulum_only_when_it_applies(pendulum):
    from jaxrb._reaction import released_pendulum

    _, scene, _ = pendulum(1.0)
    level = jaxrb.make_state(pos=(0.25, 0.0, 0.0))
    assert released_pendulum(scene, level) is not None
    tilted = jaxrb.make_state(quat=jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, 0.0]), 0.1))
    assert released_pendulum(scene, tilted) is None  # OC not horizontal
    moving = jaxrb.make_state(omega=(0.0, 1.0, 0.0))
    assert released_pendulum(scene, moving) is None  # not at rest
    dragged = jaxrb.Scene(scene.body, (*scene.forces, jaxrb.LinearDrag(0.1)), joint=scene.joint)
    assert released_pendulum(dragged, level) is None


def test_pendulum_plots(pendulum, tmp_path):
    """reaction.png overlays the closed forms; energy.png shows the solver's drift on its own
    axes (no 'dissipated' curve for a conservative motion); legends beside the axes."""
    traj, scene, _ = pendulum(1.0)
    paths = plotting.save_run_plots(traj, scene, tmp_path)
    assert [p.name for p in paths] == plotting.run_plot_names(scene)
    assert paths[-1].name == "reaction.png"
    fig = plotting.plot_joint_reaction(traj, scene)
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert any(label.startswith("closed form m g (1 + 2") for label in labels), labels
    assert _legends_outside(fig) == 2
    fig = plotting.plot_energy(traj, scene)
    assert [ax.get_ylabel() for ax in fig.axes] == ["energy (J)", "solver drift (J)"]
    assert _legends_outside(fig) == 2
    plotting.plt.close("all")


def test_energy_budget_separates_drag_from_drift():
    """A ball with linear drag (exact motion): -W(t) grows from 0 and never decreases, and
    E(t) - E(0) - W(t) is only the quadrature error of W (fourth order: 5e-10 W here)."""
    from jaxrb._energy_budget import energy_budget

    c, m, g = 0.6, 2.0, 9.81
    ts = jnp.linspace(0.0, 0.4, 81)
    k = c / m
    vz = (3.0 + g / k) * jnp.exp(-k * ts) - g / k
    z = 1.0 + (3.0 + g / k) * (1 - jnp.exp(-k * ts)) / k - g * ts / k
    states = jaxrb.make_state(
        pos=jnp.stack([0 * ts, 0 * ts, z], -1), vel=jnp.stack([0 * ts, 0 * ts, vz], -1)
    )
    traj = _trajectory(ts, states)
    body = jaxrb.RigidBody(m, jnp.array([1.0, 1.0, 1.0]))
    budget = energy_budget(traj, jaxrb.Scene(body, (jaxrb.Gravity(), jaxrb.LinearDrag(c))))
    removed = -budget["work"]
    assert budget["nonpotential"] == ["LinearDrag"]
    assert removed[0] == 0 and np.all(np.diff(removed) > 0)
    assert np.max(np.abs(budget["drift"])) < 1e-8 * removed[-1]


def test_animation_camera_is_fixed_with_the_floor_in_view(traj_scene, tmp_path):
    """The default view holds the whole motion and the floor, the same in every frame."""
    traj, scene = traj_scene
    plotting.animate(traj, scene, tmp_path / "first.gif", max_frames=1)  # only t = 0
    ax = plotting.plt.gcf().axes[0]
    first = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()])
    plotting.plt.close("all")
    plotting.animate(traj, scene, tmp_path / "all.gif", max_frames=6)  # after the last frame
    ax = plotting.plt.gcf().axes[0]
    np.testing.assert_array_equal([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()], first)
    (x0, x1), (y0, y1), (z0, z1) = first
    pos = np.asarray(traj.states.pos)
    assert x0 < pos[:, 0].min() and pos[:, 0].max() < x1 and y0 < 0 < y1
    assert z0 < float(scene.floor.height) < pos[:, 2].min() <= pos[:, 2].max() < z1
    plotting.plt.close("all")


@pytest.mark.parametrize(
    "surface", [jaxrb.Bowl(0.5, radius=0.5), jaxrb.Cone(0.5, inclination=0.3)], ids=["bowl", "cone"]
)
def test_animation_draws_a_curved_surface_under_the_ball(surface, tmp_path):
    """A ball on a bowl or cone: the surface is drawn as a wireframe lying on it (every mesh
    point has gap 0), and the run plots draw without a plane."""
    from jaxrb._animation import surface_mesh

    ball = jaxrb.RigidBody(0.05, shape=jaxrb.Sphere(0.02))
    scene = jaxrb.Scene(ball, (jaxrb.Gravity(),), floor=surface)
    ts = jnp.linspace(0.0, 1.0, 5)
    circle = jnp.stack([0.2 * jnp.cos(ts), 0.2 * jnp.sin(ts), 0.1 + 0 * ts], -1)
    zeros = jnp.zeros((5, 3))
    states = jaxrb.State(circle, jnp.tile(jnp.array([1.0, 0, 0, 0]), (5, 1)), zeros, zeros)
    traj = _trajectory(ts, states)
    plotting.animate(traj, scene, tmp_path / "a.gif", max_frames=3)
    assert (tmp_path / "a.gif").stat().st_size > 0
    X, Y, Z = surface_mesh(surface, np.array([[-0.3, 0.3], [-0.3, 0.3], [0.0, 0.3]]))
    mesh = jnp.asarray(np.stack([X, Y, Z], -1))
    np.testing.assert_allclose(np.asarray(surface.gap(mesh)), 0.0, atol=1e-12)
    assert len(plotting.save_run_plots(traj, scene, tmp_path)) == 3
