"""Dice and coins on the floor: random throws (no penetration, energy never rises, a die at
rest on a face), vmap against the loop, sliding on a face, bad input, float32."""

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb

A_DIE = 0.008
R_BALL = 0.1
TOL = dict(rtol=1e-10, atol=1e-10)
G = 9.81


def _ball_scene(e, mu=0.0):
    body = jaxrb.RigidBody(1.0, shape=jaxrb.Sphere(R_BALL))
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))


# ------------------------------------------------------------------ dice and coins


def _tumbler(shape, e, mu):
    body = jaxrb.RigidBody(0.004, shape=shape)
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))


def _throw(omega=(5.0, -8.0, 3.0), vel=(0.3, 0.0, 0.0), z=0.1):
    q = jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, 0.5]), 0.7)
    return jaxrb.make_state(pos=(0.0, 0.0, z), quat=q, vel=vel, omega=omega)


@persistent
def _die_run(scene, state0, ts):
    return jaxrb.simulate(scene, state0, ts, throw=False, max_impacts=24)


def test_elastic_die_conserves_energy_over_20_impacts():
    scene = _tumbler(jaxrb.Box((A_DIE, A_DIE, A_DIE)), 1.0, 0.0)
    ts = jnp.linspace(0.0, 3.0, 301)
    traj = _die_run(scene, _throw(), ts)
    count = int(traj.impacts.count)
    assert count >= 20, count
    energy = np.asarray(jaxrb.energy(scene, traj.states))
    assert np.max(np.abs(energy - energy[0])) / energy[0] < 1e-10
    assert np.max(np.abs(np.asarray(traj.impacts.energy_lost[:count]))) < 1e-15
    dist = jax.vmap(scene.body.shape.floor_distance)(traj.states.pos, traj.states.quat)
    assert float(jnp.min(dist)) > -1e-9  # no penetration


@persistent(static_argnames="coin")
def _settle_batch(omegas, quats, vels, coin):
    shape = jaxrb.Cylinder(0.012, 0.001) if coin else jaxrb.Box((A_DIE, A_DIE, A_DIE))
    scene = _tumbler(shape, 0.5, 0.3)
    ts = jnp.linspace(0.0, 1.5, 151)

    def run(omega, quat, vel):
        state0 = jaxrb.make_state(pos=(0.0, 0.0, 0.1), quat=quat, vel=vel, omega=omega)
        # a coin on its edge rocks from one rim to the other: ~2 impacts per rock, ~50 rocks/s
        return jaxrb.simulate(scene, state0, ts, throw=False, max_impacts=160)

    return scene, jax.vmap(run)(omegas, quats, vels)


@pytest.mark.parametrize("coin", [False, True], ids=["die", "coin"])
def test_tumbling_die_and_coin(coin, getkey):
    """Random throws: never below the floor (1e-9 m), energy never rises (at an event, or
    between saves beyond the solver's tolerance), energy lost at each impact >= 0. A die
    ends at rest on a face, by the dynamics alone; a coin (no rolling resistance) may still
    roll on its rim at the end."""
    n = 8
    omegas = jax.random.normal(getkey(), (n, 3)) * 15.0
    quats = jaxrb.quat_normalize(jax.random.normal(getkey(), (n, 4)))
    vels = jax.random.normal(getkey(), (n, 3)) * 0.5
    scene, batch = _settle_batch(omegas, quats, vels, coin)
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    log = batch.contact
    # at an event the energy rises only by lifting the body out of a penetration within the
    # contact tolerance (the projection): m g contact_tol = 3.9e-11 J; the energy ~4e-3 J
    lift = float(scene.body.mass) * G * jaxrb.contact.ContactOptions().resolved(jnp.float64).contact
    assert np.all(np.asarray(log.max_energy_rise) <= lift)
    assert np.all(np.asarray(log.max_penetration) < 1e-9)
    dist = jax.vmap(jax.vmap(scene.body.shape.floor_distance))(batch.states.pos, batch.states.quat)
    assert float(jnp.min(dist)) > -1e-9
    energy = np.asarray(jax.vmap(lambda s: jaxrb.energy(scene, s))(batch.states))
    assert np.max(np.diff(energy, axis=1)) < 1e-9 * np.max(energy)
    rec = batch.impacts
    lost = np.where(np.asarray(rec.valid), np.asarray(rec.energy_lost), 0.0)
    assert np.all(lost >= -1e-15)
    assert np.all(lost.sum(axis=1) <= energy[:, 0] - energy[:, -1] + 1e-12)
    if coin:
        return
    # at rest on a face: sticking face mode, nothing moves, the face flat on the floor
    assert np.all(np.asarray(log.kind[:, -1]) == jaxrb.contact.KIND_NAMES.index("face"))
    assert not np.any(np.asarray(log.sliding[:, -1]))
    assert np.max(np.abs(np.asarray(batch.states.vel[:, -1]))) < 1e-9
    assert np.max(np.abs(np.asarray(batch.states.omega[:, -1]))) < 1e-6
    normals = np.concatenate([np.eye(3), -np.eye(3)])
    R_end = np.asarray(jaxrb.quat_to_matrix(batch.states.quat[:, -1]))
    down = -np.einsum("fj,bij->bf", normals, R_end[:, 2:3, :])  # (n, faces): -n_world . z
    face = np.argmax(down, axis=1)
    np.testing.assert_allclose(down[np.arange(n), face], 1.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(batch.states.pos[:, -1, 2]), A_DIE, atol=1e-9)


@persistent
def _die_batch(scene, omegas, heights, ts):
    """`_die_run` of each (spin, height) under `jax.vmap`."""
    return jax.vmap(lambda w, z: _die_run(scene, _throw(omega=w, z=z), ts))(omegas, heights)


def test_die_batch_vmap_equals_per_member(getkey):
    """64 dice thrown with different spins bounce different numbers of times under vmap."""
    scene = _tumbler(jaxrb.Box((A_DIE, A_DIE, A_DIE)), 0.6, 0.3)
    omegas = jax.random.normal(getkey(), (64, 3)) * 10.0
    heights = jax.random.uniform(getkey(), (64,), minval=0.02, maxval=0.06)
    ts = jnp.linspace(0.0, 0.15, 4)

    def run(omega, z):
        return _die_run(scene, _throw(omega=omega, z=z), ts)

    batch = _die_batch(scene, omegas, heights, ts)
    counts = np.asarray(batch.impacts.count)
    assert len(set(counts.tolist())) > 1  # members bounce different numbers of times

    # Equal up to the problem's conditioning: batched arithmetic differs from unbatched by
    # roundoff (1e-16, seen before the first impact), and a tumbling die amplifies any 1e-16
    # change through the adaptive step sequence and each bounce (measured: a 1e-15 relative
    # change of the initial spin moves the state at t = 0.15 s by up to 1e-7 relative). So
    # each member is compared with its own run and with that run's responses to such changes.
    for i in range(len(counts)):
        _assert_member_is_its_own_run(run, batch, i, omegas[i], heights[i])


def _rel(a, b):
    """Largest relative difference of two pytrees of arrays (1e-3 absolute floor)."""
    return max(
        float(np.max(np.abs(np.asarray(x) - np.asarray(y)) / (1e-3 + np.abs(np.asarray(x)))))
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    )


# relative changes of a run's initial spin and height, a few to a hundred units of roundoff
NUDGES = (1e-15, -1e-15, 2e-15, -2e-15, 5e-15, -5e-15, 1e-14, -1e-14, 2e-14, -2e-14)


def _assert_member_is_its_own_run(run, batch, i, omega, z):
    """Member i of `batch` equals `run(omega, z)` up to roundoff's effect on that run, with
    the same impacts at the same times (1e-9 s). Roundoff's effect is estimated as the
    largest of the run's responses to the `NUDGES` of its spin and of its height: one such
    response is no estimate of it, as they vary by up to two orders of magnitude from one
    nudge to the next (measured on one of these throws: 1.4e-12 median, 1.3e-10 largest)."""
    count = int(batch.impacts.count[i])
    one = run(omega, z)
    assert int(one.impacts.count) == count
    spread = max(
        [_rel(one.states, run(omega * (1 + d), z).states) for d in NUDGES]
        + [_rel(one.states, run(omega, z * (1 + d)).states) for d in NUDGES]
    )
    member = jax.tree.map(lambda x: x[i], batch.states)
    assert _rel(one.states, member) <= 10 * spread + 1e-12
    np.testing.assert_allclose(
        np.asarray(one.impacts.time[:count]),
        np.asarray(batch.impacts.time[i, :count]),
        rtol=0,
        atol=1e-9,
    )


@pytest.mark.parametrize("lanes", [3, 1])
def test_throws_in_refilled_lanes_equal_per_throw_runs(getkey, lanes):
    """`simulate_throws`: 7 throws in 3 lanes (finished lanes take the next throw), or in one
    (one throw after another, the CPU's default) give each throw the trajectory of its own
    `simulate` run, up to the problem's conditioning (as in the vmap test above); a throw
    with bad input is flagged and the others are computed."""
    scene = _tumbler(jaxrb.Box((A_DIE, A_DIE, A_DIE)), 0.6, 0.3)
    n = 7
    omegas = jax.random.normal(getkey(), (n, 3)) * 10.0
    heights = jax.random.uniform(getkey(), (n,), minval=0.02, maxval=0.06)
    omegas = omegas.at[4, 1].set(jnp.nan)  # bad input
    ts = jnp.linspace(0.0, 0.15, 4)
    states0 = jax.vmap(lambda w, z: _throw(omega=w, z=z))(omegas, heights)
    out = jaxrb.simulate_throws(scene, states0, ts, lanes=lanes, max_impacts=24)
    assert out.states.pos.shape == (n, 4, 3)
    ok = np.asarray(out.result == jaxrb.RESULTS.successful)
    assert ok.tolist() == [True] * 4 + [False] + [True] * 2
    counts = np.asarray(out.impacts.count)
    assert len(set(counts[ok].tolist())) > 1  # the throws take different numbers of passes

    def run(omega, z):
        return _die_run(scene, _throw(omega=omega, z=z), ts)

    for i in np.flatnonzero(ok):
        _assert_member_is_its_own_run(run, out, int(i), omegas[i], heights[i])


# Runs `simulate_throws` on the throws pickled at argv[1] and saves its results to argv[2].
_THROWS_ON_TWO_DEVICES = """
import pickle
import sys

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import jaxrb

assert len(jax.local_devices()) == 2
with open(sys.argv[1], "rb") as f:
    scene, states0, ts = pickle.load(f)
out = jaxrb.simulate_throws(scene, states0, ts, max_impacts=16)
assert len(out.states.pos.sharding.device_set) == 2  # computed on both devices
assert np.asarray(out.result == jaxrb.RESULTS.successful).all()
np.savez(sys.argv[2], pos=out.states.pos, vel=out.states.vel, count=out.impacts.count)
print("ok")
"""


def test_throws_split_over_host_devices(tmp_path):
    """Two host devices (two CPU cores): `simulate_throws`' one lane splits the throws over
    both (three throws, padded to four), and each throw's trajectory is its own `simulate`
    run's (here, in the suite's one-device process), to roundoff. A separate process, since
    the device count is fixed when JAX starts."""
    import os
    import pickle
    import subprocess
    import sys

    ball = jaxrb.RigidBody(0.05, shape=jaxrb.Sphere(0.02))
    scene = jaxrb.Scene(ball, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(0.6, 0.3))
    heights = jnp.array([0.05, 0.1, 0.15])  # three throws: padded to four over two devices
    states0 = jax.vmap(
        lambda z: jaxrb.make_state(
            pos=jnp.stack([0.0, 0.0, z]), vel=(0.4, 0.0, 0.0), omega=(0.0, 20.0, 5.0)
        )
    )(heights)
    ts = jnp.linspace(0.0, 0.4, 5)
    throws, saved = tmp_path / "throws.pkl", tmp_path / "results.npz"
    throws.write_bytes(pickle.dumps((scene, states0, ts)))
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", _THROWS_ON_TWO_DEVICES, str(throws), str(saved)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")
    two = np.load(saved)
    assert two["pos"].shape == (3, 5, 3)
    for i in range(3):
        own = jaxrb.simulate(scene, jax.tree.map(lambda x, i=i: x[i], states0), ts, max_impacts=16)
        assert int(two["count"][i]) == int(own.impacts.count) > 0
        np.testing.assert_allclose(two["pos"][i], np.asarray(own.states.pos), rtol=0, atol=1e-9)
        np.testing.assert_allclose(two["vel"][i], np.asarray(own.states.vel), rtol=0, atol=1e-8)


def test_batch_with_a_floor_compiles_once(caplog):
    """`simulate` of a batch of states with a floor is one compiled entry point: a second
    call with the same shapes compiles nothing (the members' map used to be lowered and
    compiled again at every call, about 28 s for 16 dice on a 2-core CPU), and gives the
    same result."""
    scene = _ball_scene(0.5, 0.2)
    states0 = jaxrb.make_state(
        pos=jnp.array([[0.0, 0.0, 0.15], [0.0, 0.0, 0.25]]), vel=jnp.array([[0.5, 0, 0]] * 2)
    )
    ts = jnp.linspace(0.0, 0.5, 3)
    first = jaxrb.simulate(scene, states0, ts, max_impacts=16)
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        second = jaxrb.simulate(scene, states0, ts, max_impacts=16)
    compiled = [r.getMessage() for r in caplog.records if "Compiling" in r.getMessage()]
    assert compiled == []
    assert first.impacts.count.tolist() == second.impacts.count.tolist()
    assert min(first.impacts.count.tolist()) > 0
    np.testing.assert_array_equal(np.asarray(first.states.pos), np.asarray(second.states.pos))


def test_default_lanes_follow_the_backend(monkeypatch):
    """`simulate_throws`' default lane count: one lane where JAX's default backend is the CPU
    (the cheapest per throw there, benchmarks/README.md), else min(N, 64)."""
    from jaxrb.contact import _lanes

    monkeypatch.setattr(_lanes.jax, "default_backend", lambda: "cpu")
    assert [jaxrb.contact.default_lanes(n) for n in (1, 7, 1000)] == [1, 1, 1]
    monkeypatch.setattr(_lanes.jax, "default_backend", lambda: "gpu")
    assert [jaxrb.contact.default_lanes(n) for n in (1, 7, 1000)] == [1, 7, 64]


# ------------------------------------------------------------------ sliding contact


@persistent
def _slide_run(scene, state0, ts):
    return jaxrb.simulate(scene, state0, ts, throw=False, rtol=1e-12, atol=1e-12)


def test_sphere_slides_then_rolls():
    """A uniform ball set down sliding (v0, no spin): friction mu m g decelerates it and spins
    it up until rolling at t* = 2 v0 / (7 mu g), then it rolls at 5/7 v0 for ever."""
    v0, mu = 1.2, 0.2
    t_star = 2 * v0 / (7 * mu * G)
    x_star = v0 * t_star - 0.5 * mu * G * t_star**2
    ts = jnp.asarray([0.0, 0.3 * t_star, 0.9 * t_star, 1.1 * t_star, 2.0, 5.0])
    state0 = jaxrb.make_state(pos=(0.0, 0.0, R_BALL), vel=(v0, 0.0, 0.0))
    traj = _slide_run(_ball_scene(0.5, mu), state0, ts)
    assert traj.result == jaxrb.RESULTS.successful
    t = np.asarray(ts)
    x = np.where(t < t_star, v0 * t - 0.5 * mu * G * t**2, x_star + 5 / 7 * v0 * (t - t_star))
    vx = np.where(t < t_star, v0 - mu * G * t, 5 / 7 * v0)
    wy = np.where(t < t_star, 2.5 * mu * G * t / R_BALL, 5 / 7 * v0 / R_BALL)
    np.testing.assert_allclose(np.asarray(traj.states.pos[:, 0]), x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(traj.states.vel[:, 0]), vx, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(traj.states.omega[:, 1]), wy, rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.asarray(traj.states.pos[:, 2]), R_BALL, rtol=0, atol=1e-12)


def _sliding_die(mu, drag, damping):
    """A die on the floor with drag (zero coefficients: the same compiled run, no drag)."""
    body = jaxrb.RigidBody(0.004, shape=jaxrb.Box((A_DIE, A_DIE, A_DIE)))
    forces = (jaxrb.Gravity(), jaxrb.LinearDrag(drag), jaxrb.DampingMoment(damping))
    return jaxrb.Scene(body, forces=forces, floor=jaxrb.Floor(0.5, mu))


def _face_slide_reference(mu, v0, wz0, rho, k):
    """A face sliding and spinning on the floor under the ellipsoidal limit surface: the
    friction force and moment (f, tau / rho) = -mu m g s / |s| with the slip twist
    s = (v, rho w) (rho: the face's friction radius, the mean distance of its points from
    its centre; k: the radius of gyration about the vertical). Integrated with scipy to the
    stop; returns (stop time, dense solution of (x, y, vx, vy, yaw, w))."""
    from scipy.integrate import solve_ivp

    def rhs(_, y):
        v, w = y[2:4], y[5]
        size = np.sqrt(v @ v + (rho * w) ** 2)
        return [*v, *(-mu * G * v / size), w, -mu * G * rho**2 * w / (k**2 * size)]

    def stopped(_, y):
        return np.sqrt(y[2] ** 2 + y[3] ** 2 + (rho * y[5]) ** 2) - 1e-10

    stopped.terminal = True
    y0 = [0.0, 0.0, *v0, 0.0, wz0]
    sol = solve_ivp(rhs, (0.0, 10.0), y0, events=stopped, dense_output=True, rtol=1e-12, atol=1e-14)
    return float(sol.t_events[0][0]), sol


def test_die_slides_to_rest_on_its_face():
    """A die lying on a face, sliding and spinning, against the limit-surface equations
    integrated by scipy: the position at half the stop time, the stop time, and the final
    position and yaw at rest."""
    mu, vx, vy, wz = 0.3, 0.4, -0.25, 30.0
    scene = _sliding_die(mu, drag=0.0, damping=0.0)
    rho = A_DIE * (np.sqrt(2) + np.arcsinh(1.0)) / 3  # mean distance over a square face
    k = A_DIE * np.sqrt(2 / 3)  # cube: I_zz = (2/3) m a^2 about the vertical
    T, ref = _face_slide_reference(mu, (vx, vy), wz, rho, k)
    ts = jnp.asarray([0.0, 0.5 * T, T + 0.01, 1.0])
    state0 = jaxrb.make_state(pos=(0.0, 0.0, A_DIE), vel=(vx, vy, 0.0), omega=(0.0, 0.0, wz))
    traj = _slide_run(scene, state0, ts)
    assert traj.result == jaxrb.RESULTS.successful
    # the slide ends at one event (slip below slip_stop / 2 = 5e-6 m/s: ~2e-6 s early)
    assert int(traj.contact.events) == 1
    assert float(traj.contact.event_time[1]) == pytest.approx(T, abs=1e-5)
    np.testing.assert_allclose(np.asarray(traj.states.pos[1, :2]), ref.sol(0.5 * T)[:2], atol=1e-9)
    end = ref.sol(T)
    for k_save in (2, 3):  # at rest: sticking, velocities at roundoff level (the stuck
        # face's constrained equations integrate accelerations of roundoff size)
        assert not bool(traj.contact.sliding[k_save])
        np.testing.assert_allclose(
            np.asarray(traj.states.pos[k_save]), [end[0], end[1], A_DIE], rtol=0, atol=1e-9
        )
        np.testing.assert_allclose(np.asarray(traj.states.vel[k_save]), 0.0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(traj.states.omega[k_save]), 0.0, atol=1e-12)
        q = traj.states.quat[k_save]
        yaw = 2 * np.arctan2(float(q[3]), float(q[0]))
        np.testing.assert_allclose(yaw, end[4], rtol=0, atol=1e-8)


@persistent
def _translating_slides(scene, speeds, ts):
    """Dice on a face set sliding without spin at `speeds` (m/s, along (1, 0.3, 0)), under
    `jax.vmap`, at rtol = atol = 1e-6."""

    def run(speed):
        vel = speed * jnp.array([1.0, 0.3, 0.0])
        state0 = jaxrb.make_state(pos=(0.0, 0.0, A_DIE), vel=vel)
        return jaxrb.simulate(scene, state0, ts, throw=False, rtol=1e-6, atol=1e-6)

    return jax.vmap(run)(speeds)


def test_every_slide_stops_where_uniform_deceleration_says():
    """A die sliding on its face without spin decelerates at mu g and stops at
    T = |v0| / (mu g), |v0|^2 / (2 mu g) further on. The stop is a dip of the slip speed
    through zero, its condition negative for only slip_stop / (mu g) = 3.4e-6 s: the slip
    step limit makes a step end there for every speed (without it, at rtol 1e-6, 6 of
    these 24 dice were stepped over and slid on round zero for 7500-10500 steps)."""
    mu = 0.3
    scene = _sliding_die(mu, drag=0.0, damping=0.0)
    speeds = jnp.linspace(0.05, 1.0, 24)
    ts = jnp.asarray([0.0, 0.5, 1.0])
    traj = _translating_slides(scene, speeds, ts)
    speed = np.asarray(speeds) * np.hypot(1.0, 0.3)
    T = speed / (mu * G)
    assert np.all(np.asarray(traj.result._value) == 0)
    assert np.all(np.asarray(traj.contact.events) == 1)
    stops = jaxrb.contact.CAUSES.index("slip stops")
    assert np.all(np.asarray(traj.contact.event_cause[:, 1]) == stops)
    # it fires when the slip has fallen to slip_stop / 2 = 5e-6 m/s: 1.7e-6 s early
    early = 0.5 * 1e-5 / (mu * G)
    np.testing.assert_allclose(np.asarray(traj.contact.event_time[:, 1]), T - early, atol=1e-9)
    direction = np.array([1.0, 0.3]) / np.hypot(1.0, 0.3)
    end = (speed**2 / (2 * mu * G))[:, None] * direction
    np.testing.assert_allclose(np.asarray(traj.states.pos[:, -1, :2]), end, atol=1e-9)
    assert not np.any(np.asarray(traj.contact.sliding[:, -1]))
    assert np.all(np.asarray(traj.num_steps) < 100)


def _sliding_start(v, wz):
    """A die on its face moving at (v, 0) m/s and spinning at wz rad/s about the vertical."""
    return jaxrb.make_state(
        pos=(0.0, 0.0, A_DIE), vel=jnp.stack([v[0], v[1], 0.0]), omega=jnp.stack([0, 0, wz])
    )


@persistent
def _slide_batch(scene, vs, wzs, ts):
    """`_slide_run` of each (velocity, spin) under `jax.vmap`."""
    return jax.vmap(lambda v, wz: _slide_run(scene, _sliding_start(v, wz), ts))(vs, wzs)


def test_sliding_dice_with_drag_batch_equals_per_member(getkey):
    """Drag turns the slip direction while a die slides on its face; sliding must still end
    cleanly (no creeping onto the Coulomb discontinuity) for every member under vmap."""
    scene = _sliding_die(0.3, drag=0.012, damping=1e-7)
    ts = jnp.linspace(0.0, 1.0, 5)

    def run(v, wz):
        return _slide_run(scene, _sliding_start(v, wz), ts)

    vs = jax.random.normal(getkey(), (6, 2)) * 0.5
    wzs = jax.random.normal(getkey(), (6,)) * 40.0
    batch = _slide_batch(scene, vs, wzs, ts)
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    # every die sticks at the end, its velocity at the level of the constraint stabilisation
    # acting on the projection's ~1e-12 m residual (a creeping slip would be ~slip_stop, 1e-5)
    assert np.all(np.asarray(batch.contact.kind[:, -1]) == jaxrb.contact.KIND_NAMES.index("face"))
    assert not np.any(np.asarray(batch.contact.sliding[:, -1]))
    assert np.max(np.abs(np.asarray(batch.states.vel[:, -1]))) < 1e-10
    for i in range(2):
        one = run(vs[i], wzs[i])
        np.testing.assert_allclose(
            np.asarray(one.states.pos), np.asarray(batch.states.pos[i]), rtol=0, atol=1e-12
        )


# ------------------------------------------------------------------ bad input


def test_bad_input_clear_errors():
    with pytest.raises(ValueError, match="restitution"):
        jaxrb.Floor(1.5)
    with pytest.raises(ValueError, match="restitution"):
        jaxrb.Floor(-0.1)
    with pytest.raises(ValueError, match="friction"):
        jaxrb.Floor(0.5, friction=-0.2)
    scene = _ball_scene(0.5)
    with pytest.raises(ValueError, match="below the floor"):
        jaxrb.simulate(scene, jaxrb.make_state(pos=(0.0, 0.0, 0.05)), jnp.linspace(0.0, 1.0, 3))
    with pytest.raises(ValueError, match="shape"):
        jaxrb.simulate(
            jaxrb.Scene(jaxrb.RigidBody(1.0, (1.0, 1.0, 1.0)), floor=jaxrb.Floor(0.5)),
            jaxrb.make_state(pos=(0.0, 0.0, 1.0)),
            jnp.linspace(0.0, 1.0, 3),
        )


@persistent
def _ball_results(e, mu, h):
    """The result codes of balls dropped from heights h on floors (e, mu), one per member."""
    return jax.vmap(_ball_result)(e, mu, h)


def _ball_result(e, mu, h):
    scene = jaxrb.Scene(
        jaxrb.RigidBody(1.0, shape=jaxrb.Sphere(R_BALL)),
        forces=(jaxrb.Gravity(),),
        floor=jaxrb.Floor(e, mu),
    )
    ts = jnp.linspace(0.0, 1.0, 14)
    state0 = jaxrb.make_state(pos=jnp.stack([0.0 * h, 0.0 * h, h]))
    return jaxrb.simulate(scene, state0, ts, throw=False, **TOL).result


def test_bad_input_flagged_under_vmap():
    """Traced restitution / friction / start height: one result code per member."""
    res = _ball_results(
        jnp.array([0.5, 1.5, 0.5, 0.5]),
        jnp.array([0.0, 0.0, -1.0, 0.0]),
        jnp.array([1.0, 1.0, 1.0, 0.05]),
    )
    R = jaxrb.RESULTS
    expected = [R.successful, R.invalid_restitution, R.invalid_friction, R.starts_below_floor]
    for got, want in zip(res._value, expected, strict=True):
        assert got == want._value


def test_float32_die_settles():
    """A float32 scene (with float64 enabled elsewhere) bounces and comes to rest on a face."""
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    body = jaxrb.RigidBody(f32(0.004), shape=jaxrb.Box(f32([A_DIE, A_DIE, A_DIE])))
    scene = jax.tree.map(f32, _tumbler(body.shape, 0.5, 0.3))
    state0 = jax.tree.map(f32, _throw())
    traj = jaxrb.simulate(
        scene, state0, jnp.linspace(0.0, 1.0, 5, dtype=jnp.float32), rtol=1e-5, atol=1e-5
    )
    assert traj.states.pos.dtype == jnp.float32
    assert int(traj.impacts.count) > 3
    assert int(traj.contact.kind[-1]) == jaxrb.contact.KIND_NAMES.index("face")
    assert not bool(traj.contact.sliding[-1])
    assert float(jnp.max(jnp.abs(traj.states.vel[-1]))) < 1e-5
    assert float(traj.states.pos[-1, 2]) == pytest.approx(A_DIE, abs=1e-6)
