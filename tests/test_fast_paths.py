"""Fast paths: a batch as one diffrax solve (`simulate_batch`), the exact torque-free flow
and the Lie-group splitting."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb
from jaxrb._batched import simulate_batch
from jaxrb._exact_flow import torque_free_flow
from jaxrb.analytic import asymmetric_top

INERTIA = jnp.array([1.0, 2.0, 3.0])


def _random_states(n, seed=0, spin=1.0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return jaxrb.make_state(
        pos=rng.normal(size=(n, 3)),
        quat=q,
        vel=rng.normal(size=(n, 3)),
        omega=spin * rng.normal(size=(n, 3)),
    )


@pytest.fixture(scope="module")
def batch():
    return _random_states(6)


@pytest.fixture(scope="module")
def reference(batch):
    """diffrax Dopri8 at rtol = atol = 1e-13 through `jaxrb.simulate` (independent path)."""
    ts = jnp.array([0.0, 2.5, 10.0])
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    run = jax.vmap(
        lambda s: jaxrb.simulate(scene, s, ts, solver=dfx.Dopri8(), rtol=1e-13, atol=1e-13).states
    )
    return ts, run(batch)


def test_simulate_batch_torque_free_exact(batch, reference):
    ts, ref = reference
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    traj = simulate_batch(scene, batch, ts, rtol=1e-11, atol=1e-11)
    assert traj.states.quat.shape == (6, 3, 4)
    assert traj.states.omega.shape == (6, 3, 3)
    w_exact = jax.vmap(lambda w: asymmetric_top(ts, INERTIA, w))(batch.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9
    assert float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, ref.quat))) < 1e-9
    np.testing.assert_allclose(traj.states.pos, ref.pos, atol=1e-9)
    np.testing.assert_allclose(traj.states.vel, ref.vel, atol=1e-12)
    assert bool(jnp.all(traj.result == jaxrb.RESULTS.successful))
    assert float(jnp.max(traj.quat_norm_drift)) < 1e-9


def test_simulate_batch_error_tracks_tolerance(batch):
    """Work-precision: tighter tolerance -> smaller error, more steps (8th order)."""
    ts = jnp.array([0.0, 5.0, 10.0])
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    w_exact = jax.vmap(lambda w: asymmetric_top(10.0, INERTIA, w))(batch.omega)
    errs, steps = [], []
    for tol in (1e-6, 1e-9):
        traj = simulate_batch(scene, batch, ts, rtol=tol, atol=tol, solver=dfx.Dopri8())
        errs.append(float(jnp.max(jnp.abs(traj.states.omega[:, -1] - w_exact))))
        steps.append(int(traj.num_steps[0]))
    assert errs[1] < 1e-2 * errs[0]
    assert errs[0] < 1e-4 and errs[1] < 1e-7
    assert steps[1] > steps[0]
    # 8th order: 1000x smaller error for about 1000^(1/8) = 2.4x more steps (allow 1.5 - 4)
    assert 1.5 < steps[1] / steps[0] < 4.0


def test_simulate_batch_heavy_top_matches_simulate():
    """A jointed scene (pivot + gravity): same coordinates and right-hand side as `simulate`."""
    body = jaxrb.RigidBody(1.0, jnp.array([0.5, 0.5, 0.2]))
    scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=jaxrb.Pivot((0.0, 0.0, -0.5)))
    states = jaxrb.make_state(
        quat=jaxrb.axis_angle_to_quat(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.3, 0.5, 0.7])),
        omega=jnp.array([[0.0, 0.0, 20.0], [0.1, 0.0, 15.0], [0.0, 0.2, 25.0]]),
    )
    ts = jnp.linspace(0.0, 1.0, 5)
    traj = simulate_batch(scene, states, ts, rtol=1e-11, atol=1e-11)
    ref = jax.vmap(
        lambda s: jaxrb.simulate(scene, s, ts, solver=dfx.Dopri8(), rtol=1e-12, atol=1e-12).states
    )(states)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, ref.quat))) < 1e-8
    np.testing.assert_allclose(traj.states.omega, ref.omega, atol=1e-7)
    np.testing.assert_allclose(traj.states.pos, ref.pos, atol=1e-9)
    e = jax.vmap(jax.vmap(lambda s: jaxrb.energy(scene, s)))(traj.states)
    assert float(jnp.max(jnp.abs(e - e[:, :1]))) < 1e-8


def test_simulate_batch_gravity_with_one_inertia_per_body(batch):
    """Gravity only: the mass centre follows the exact parabola and the rotation the
    torque-free solution of each body's own inertia (`batched_scene=True`)."""
    inertias = jnp.array([[1.0, 2.0, 3.0], [3.0, 1.0, 2.0], [2.0, 3.0, 1.5]] * 2)
    scene = jax.vmap(lambda i: jaxrb.Scene(jaxrb.RigidBody(2.0, i), forces=(jaxrb.Gravity(),)))(
        inertias
    )
    ts = jnp.array([0.0, 1.5, 4.0])
    traj = simulate_batch(scene, batch, ts, rtol=1e-11, atol=1e-11, batched_scene=True)
    w_exact = jax.vmap(lambda i, w: asymmetric_top(ts, i, w))(inertias, batch.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9
    g = jnp.array([0.0, 0.0, -9.81])
    t = ts[None, :, None]
    pos = batch.pos[:, None] + batch.vel[:, None] * t + 0.5 * g * t**2
    np.testing.assert_allclose(traj.states.pos, pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.states.vel, batch.vel[:, None] + g * t, rtol=0, atol=1e-12)


GRAVITY_SCENE = jaxrb.Scene(jaxrb.RigidBody(2.0, INERTIA), forces=(jaxrb.Gravity(),))
PART_TS = jnp.array([0.0, 1.5, 4.0])


def _exact_gravity_checks(traj, states, inertias):
    w_exact = jax.vmap(lambda i, w: asymmetric_top(PART_TS, i, w))(inertias, states.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9
    t = PART_TS[None, :, None]
    g = jnp.array([0.0, 0.0, -9.81])
    pos = states.pos[:, None] + states.vel[:, None] * t + 0.5 * g * t**2
    np.testing.assert_allclose(traj.states.pos, pos, rtol=0, atol=1e-12)


def test_simulate_batch_in_parts(batch):
    """`part_size=4` on 6 bodies: two solves (the second padded), each with its own step
    control; both against the exact solution and the one-solve run, and a bad body in the
    second part flagged while the others are computed."""
    whole = simulate_batch(GRAVITY_SCENE, batch, PART_TS, rtol=1e-11, atol=1e-11)
    parts = simulate_batch(GRAVITY_SCENE, batch, PART_TS, rtol=1e-11, atol=1e-11, part_size=4)
    assert parts.ts.shape == (3,) and parts.states.quat.shape == (6, 3, 4)
    assert parts.result._value.shape == (6,) and parts.num_steps.shape == (6,)
    _exact_gravity_checks(parts, batch, jnp.tile(INERTIA, (6, 1)))
    assert float(jnp.max(jaxrb.quat_geodesic_angle(parts.states.quat, whole.states.quat))) < 1e-9
    steps = np.asarray(parts.num_steps)
    assert len(set(steps[:4])) == 1 and len(set(steps[4:])) == 1
    # each part's steps are those of its hardest member: no more than the whole batch's
    assert steps.max() == int(whole.num_steps[0])
    bad = jaxrb.State(batch.pos, batch.quat, batch.vel, batch.omega.at[5, 0].set(jnp.nan))
    flagged = simulate_batch(
        GRAVITY_SCENE, bad, PART_TS, rtol=1e-11, atol=1e-11, part_size=4, throw=False
    )
    codes = [int(r) for r in flagged.result._value]
    ok = jaxrb.RESULTS.successful._value
    assert codes[:5] == [ok] * 5 and codes[5] == jaxrb.RESULTS.nonfinite_state._value
    assert bool(jnp.all(jnp.isnan(flagged.states.omega[5])))
    np.testing.assert_allclose(flagged.states.omega[:4], parts.states.omega[:4], atol=1e-13)


def test_simulate_batch_in_parts_with_one_inertia_per_body(batch):
    """`batched_scene=True` split in parts: each body keeps its own inertia."""
    inertias = jnp.array([[1.0, 2.0, 3.0], [3.0, 1.0, 2.0], [2.0, 3.0, 1.5]] * 2)
    scene = jax.vmap(lambda i: jaxrb.Scene(jaxrb.RigidBody(2.0, i), forces=(jaxrb.Gravity(),)))(
        inertias
    )
    traj = simulate_batch(
        scene, batch, PART_TS, rtol=1e-11, atol=1e-11, batched_scene=True, part_size=4
    )
    _exact_gravity_checks(traj, batch, inertias)


def _final_spin(batch, omega0, part_size):
    """A weighted sum of the members' final spins about body x, the batch in parts of
    `part_size` members (None: one solve)."""
    states = jaxrb.State(batch.pos, batch.quat, batch.vel, omega0)
    traj = simulate_batch(
        GRAVITY_SCENE, states, PART_TS, rtol=1e-11, atol=1e-11, part_size=part_size
    )
    return jnp.sum(traj.states.omega[:, -1, 0] * jnp.arange(1.0, 7.0))


@persistent(static_argnames="part_size")
def _final_spin_gradient(batch, omega0, part_size):
    return jax.grad(_final_spin, argnums=1)(batch, omega0, part_size)


def test_reverse_gradient_through_the_parts(batch):
    """The reverse-mode gradient of a batch in parts (`jax.lax.map` over the solves) equals
    the one-solve batch's and central differences (float64)."""
    parts = _final_spin_gradient(batch, batch.omega, 4)
    whole = _final_spin_gradient(batch, batch.omega, None)
    np.testing.assert_allclose(parts, whole, rtol=1e-7, atol=1e-8)
    h = 1e-5
    bump = jnp.zeros_like(batch.omega).at[5, 1].set(h)  # a member of the second part
    central = (
        _final_spin(batch, batch.omega + bump, 4) - _final_spin(batch, batch.omega - bump, 4)
    ) / (2 * h)
    np.testing.assert_allclose(parts[5, 1], central, rtol=1e-6)


@pytest.mark.parametrize("bad", [0, -3, 2.5, True])
def test_simulate_batch_rejects_a_bad_part_size(batch, bad):
    with pytest.raises(ValueError, match="part_size must be a positive int"):
        simulate_batch(GRAVITY_SCENE, batch, PART_TS, part_size=bad)


_SHARDED = """
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxrb
from jaxrb._batched import simulate_batch
from jaxrb.analytic import asymmetric_top
assert len(jax.devices()) == 2
inertia = jnp.array([1.0, 2.0, 3.0])
rng = np.random.default_rng(1)
states = jaxrb.make_state(quat=jnp.tile(jnp.array([1.0, 0, 0, 0]), (5, 1)),
                          omega=rng.normal(size=(5, 3)), vel=rng.normal(size=(5, 3)))
ts = jnp.array([0.0, 3.0, 6.0])
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia), forces=(jaxrb.Gravity(),))
w_exact = jax.vmap(lambda w: asymmetric_top(ts, inertia, w))(states.omega)
two = simulate_batch(scene, states, ts, rtol=1e-11, atol=1e-11, devices=jax.devices())
one = simulate_batch(scene, states, ts, rtol=1e-11, atol=1e-11, devices=jax.devices()[:1])
assert two.states.omega.shape == (5, 3, 3) and two.result._value.shape == (5,)
assert float(jnp.max(jnp.abs(two.states.omega - w_exact))) < 1e-9
assert float(jnp.max(jaxrb.quat_geodesic_angle(two.states.quat, one.states.quat))) < 1e-9
np.testing.assert_array_equal(np.asarray(two.states.pos), np.asarray(one.states.pos))
assert bool(jnp.all(two.result == jaxrb.RESULTS.successful))
# a jointed scene (the mapped right-hand side) stays on one CPU device unless asked
from jaxrb._batched import _default_devices
assert len(_default_devices(scene, 5)) == 1  # too few bodies to split by default
top = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([0.5, 0.5, 0.2])), forces=(jaxrb.Gravity(),),
                  joint=jaxrb.Pivot((0.0, 0.0, -0.5)))
assert len(_default_devices(scene, 100)) == 2 and len(_default_devices(top, 100)) == 1
spin = states.omega.at[:, 2].add(20.0)
a = simulate_batch(top, jaxrb.make_state(omega=spin), ts[:2], rtol=1e-11, atol=1e-11,
                   devices=jax.devices())
b = simulate_batch(top, jaxrb.make_state(omega=spin), ts[:2], rtol=1e-11, atol=1e-11,
                   devices=jax.devices()[:1])
assert float(jnp.max(jnp.abs(a.states.omega - b.states.omega))) < 1e-8
print("ok")
"""


def test_simulate_batch_splits_the_batch_over_devices():
    """Two host devices (two CPU cores): the batch is padded and split; each part runs its own
    loop and agrees with the one-device run and the exact solution. A separate process,
    since the device count is fixed when JAX starts."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", _SHARDED], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")


def test_simulate_batch_float32(batch):
    scene = jaxrb.Scene(jaxrb.RigidBody(jnp.float32(1.0), INERTIA.astype(jnp.float32)))
    s32 = jax.tree.map(lambda x: x.astype(jnp.float32), batch)
    traj = simulate_batch(scene, s32, jnp.array([0.0, 5.0], jnp.float32), rtol=1e-6, atol=1e-6)
    assert traj.states.omega.dtype == jnp.float32
    w_exact = jax.vmap(lambda w: asymmetric_top(5.0, INERTIA, w))(batch.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega[:, -1].astype(jnp.float64) - w_exact))) < 1e-4


def test_simulate_batch_max_steps_flagged(batch):
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    ts = jnp.array([0.0, 5.0, 10.0])
    traj = simulate_batch(scene, batch, ts, max_steps=3, throw=False)
    assert bool(jnp.all(traj.result == jaxrb.RESULTS.max_steps_reached))
    with pytest.raises(Exception, match="max"):
        simulate_batch(scene, batch, ts, max_steps=3, throw=True)


def test_simulate_batch_bad_input():
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    with pytest.raises(ValueError, match="states0.pos"):
        simulate_batch(scene, jaxrb.make_state(omega=jnp.ones(3)), jnp.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="non-decreasing"):
        simulate_batch(scene, jaxrb.make_state(omega=jnp.ones((2, 3))), jnp.array([1.0, 0.0]))
    floor_scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA), floor=jaxrb.Floor(0.5))
    with pytest.raises(ValueError, match="floor"):
        simulate_batch(floor_scene, jaxrb.make_state(omega=jnp.ones((2, 3))), jnp.array([0.0, 1.0]))


@pytest.mark.parametrize("inertia", [(1.0, 2.0, 3.0), (3.0, 1.0, 2.0), (2.0, 3.0, 1.5)])
def test_exact_flow_matches_integration(inertia, batch, reference):
    inertia = jnp.array(inertia)
    ts = jnp.array([0.0, 2.5, 10.0])
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    if inertia[0] == 1.0:
        ref = reference[1]
    else:
        ref = jax.vmap(
            lambda s: (
                jaxrb.simulate(scene, s, ts, solver=dfx.Dopri8(), rtol=1e-13, atol=1e-13).states
            )
        )(batch)
    ex = torque_free_flow(inertia, batch, ts)
    assert ex.quat.shape == (6, 3, 4)
    np.testing.assert_allclose(ex.omega, ref.omega, atol=1e-10)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(ex.quat, ref.quat))) < 1e-9
    np.testing.assert_allclose(ex.pos, ref.pos, atol=1e-12)


def test_exact_flow_long_time_invariants(batch):
    """At t = 1e4 (thousands of rotations) the world angular momentum and energy are exact."""
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    t = jnp.array([0.0, 1e4])
    ex = torque_free_flow(INERTIA, batch, t)
    L = jax.vmap(jax.vmap(lambda s: jaxrb.angular_momentum(scene, s)))(ex)
    E = jax.vmap(jax.vmap(lambda s: jaxrb.energy(scene, s)))(ex)
    np.testing.assert_allclose(L[:, 1], L[:, 0], rtol=0, atol=1e-10 * float(jnp.max(jnp.abs(L))))
    np.testing.assert_allclose(E[:, 1], E[:, 0], rtol=1e-12)
    np.testing.assert_allclose(jnp.linalg.norm(ex.quat, axis=-1), 1.0, atol=1e-14)


@persistent
def _flow_quat(omega0):
    """The exact torque-free attitude at t = 3 s from omega0 (rad/s, body frame)."""
    return torque_free_flow(INERTIA, jaxrb.make_state(omega=omega0), 3.0).quat


@persistent
def _flow_quat_gradient(omega0, c):
    return jax.grad(lambda w: jnp.sum(_flow_quat(w) * c))(omega0)


def test_exact_flow_grad(batch):
    """Reverse-mode derivative of q(t) in omega0 matches central finite differences."""
    w0 = batch.omega[0]
    eps = 1e-6
    fd = jnp.stack(
        [(_flow_quat(w0 + eps * e) - _flow_quat(w0 - eps * e)) / (2 * eps) for e in jnp.eye(3)],
        -1,
    )
    c = jnp.array([0.3, -0.2, 0.5, 0.1])
    gr = _flow_quat_gradient(w0, c)
    np.testing.assert_allclose(gr, c @ fd, atol=1e-7)


def test_splitting_order_and_conservation():
    """Lie-group splitting: second order, |q| = 1 and the world angular momentum to round-off."""
    from jaxrb._splitting import simulate_splitting

    state = jaxrb.make_state(omega=jnp.array([1.0, 0.0, 1.5]), vel=jnp.array([1.0, 0.0, 0.0]))
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
    ts = jnp.linspace(0.0, 5.0, 3)
    exact = torque_free_flow(INERTIA, state, ts)
    errs = []
    for dt in (0.02, 0.01):
        traj = simulate_splitting(scene, state, ts, dt=dt)
        errs.append(float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, exact.quat))))
        assert float(traj.quat_norm_drift) < 1e-13
        L = jax.vmap(lambda s: jaxrb.angular_momentum(scene, s))(traj.states)
        np.testing.assert_allclose(L, jnp.broadcast_to(L[0], L.shape), atol=1e-13)
        np.testing.assert_allclose(traj.states.pos, exact.pos, atol=1e-12)
    assert 3.5 < errs[0] / errs[1] < 4.5  # order 2
    with pytest.raises(ValueError, match="equally spaced"):
        simulate_splitting(scene, state, jnp.array([0.0, 1.0, 3.0]), dt=0.1)
