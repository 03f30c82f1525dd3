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
    traj = jaxrb.Trajectory(
        ts=ts,
        states=states,
        result=jaxrb.RESULTS.successful,
        quat_norm_drift=jnp.zeros(()),
        num_steps=jnp.zeros((), int),
    )
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
