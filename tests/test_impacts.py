"""Impacts with the floor: bouncing ball against closed forms, gradients across impacts,
the impact map's energy law, tumbling dice and coins, vmap batches and bad input."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb._impacts import impact_map
from jaxrb.analytic import ball_apex_heights, ball_height, ball_impact_times, ball_rest_time

G = 9.81
R_BALL = 0.1
TOL = dict(rtol=1e-10, atol=1e-10)


def _ball_scene(e, mu=0.0):
    body = jaxrb.RigidBody(1.0, shape=jaxrb.Sphere(R_BALL))
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))


@functools.partial(jax.jit, static_argnames="throw")
def _ball_run(h0, v0, e, ts, throw=False):
    state0 = jaxrb.make_state(
        pos=jnp.stack([0.0 * h0, 0.0 * h0, h0 + R_BALL]), vel=jnp.stack([0.0 * v0, 0.0 * v0, v0])
    )
    return jaxrb.simulate(_ball_scene(e), state0, ts, throw=throw, **TOL)


def test_ball_impact_times_apex_and_rest():
    h0, e, n = 1.0, 0.7, 12
    t_imp = np.asarray(ball_impact_times(h0, e, n))
    apex_t = t_imp + e ** np.arange(1, n + 1) * np.sqrt(2 * G * h0) / G  # apex after each bounce
    ts = jnp.asarray(np.concatenate([[0.0], apex_t, [5.0]]))
    traj = _ball_run(h0, 0.0, e, ts)
    assert traj.result == jaxrb.RESULTS.successful
    rec = traj.impacts
    count = int(rec.count)
    assert count > n
    assert np.max(np.abs(np.asarray(rec.time[:n]) - t_imp)) < 1e-9
    apex = np.asarray(traj.states.pos[1 : n + 1, 2]) - R_BALL
    np.testing.assert_allclose(apex, np.asarray(ball_apex_heights(h0, e, n)), rtol=1e-9, atol=1e-11)
    assert abs(float(rec.rest_time) - float(ball_rest_time(h0, e))) < 1e-8
    # at rest on the floor at the end, nothing moves
    np.testing.assert_allclose(np.asarray(traj.states.pos[-1]), [0, 0, R_BALL], atol=1e-12)
    np.testing.assert_allclose(np.asarray(traj.states.vel[-1]), 0.0, atol=1e-12)
    # energy lost at each impact: (1 - e^2) of the incoming kinetic energy
    un = np.asarray(rec.normal_speed[:count])
    lost = np.asarray(rec.energy_lost[:count])
    np.testing.assert_allclose(
        lost[: count - 1], 0.5 * (1 - e**2) * un[: count - 1] ** 2, rtol=1e-12
    )
    assert np.all(lost >= 0)
    np.testing.assert_allclose(np.asarray(rec.impulse[:n, 2]), (1 + e) * un[:n], rtol=1e-12)


def test_ball_height_matches_closed_form():
    h0, e, v0 = 0.8, 0.6, 1.5
    ts = jnp.linspace(0.0, 3.0, 14)
    traj = _ball_run(h0, v0, e, ts)
    height = np.asarray(traj.states.pos[:, 2]) - R_BALL
    exact = np.asarray(ball_height(ts, h0, e, v0=v0))
    # after the (merged) Zeno series the bounce heights are below rest_speed^2/(2g) ~ 5e-6 m
    assert np.max(np.abs(height - exact)) < 1e-8
    assert np.min(height) > -1e-10


def _height_at(params, T):
    h0, v0, e = params
    ts = jnp.linspace(0.0, 1.0, 14) * T  # same shape as the other ball tests: one compile
    return _ball_run(h0, v0, e, ts).states.pos[-1, 2] - R_BALL


_height_grad = jax.jit(jax.grad(_height_at))  # one compilation for every T


def test_ball_gradients_across_impacts():
    h0, v0, e = 1.0, 0.5, 0.7
    t_imp = np.asarray(ball_impact_times(h0, e, 3, v0=v0))
    params = jnp.array([h0, v0, e])
    for T in (0.5 * (t_imp[0] + t_imp[1]), 0.5 * (t_imp[1] + t_imp[2])):  # after 1 and 2 impacts
        grad = np.asarray(_height_grad(params, T))
        exact = np.asarray(jax.grad(lambda p, T=T: ball_height(T, p[0], p[2], v0=p[1]))(params))
        np.testing.assert_allclose(grad, exact, rtol=1e-7, atol=1e-9)
        eps = 1e-4  # central differences: truncation ~eps^2, solver noise ~1e-12 / eps
        fd = [
            (
                float(_height_at(params.at[i].add(eps), T))
                - float(_height_at(params.at[i].add(-eps), T))
            )
            / (2 * eps)
            for i in range(3)
        ]
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-7)


def _spin_ball_final(params):
    """A ball thrown with backspin bounces once on a floor with friction, in quadratic drag."""
    mu, drag, moment, h0 = params
    body = jaxrb.RigidBody(1.0, inertia=moment * jnp.ones(3), shape=jaxrb.Sphere(R_BALL))
    scene = jaxrb.Scene(
        body, forces=(jaxrb.Gravity(), jaxrb.QuadraticDrag(drag)), floor=jaxrb.Floor(0.7, mu)
    )
    state0 = jaxrb.make_state(
        pos=jnp.stack([0.0 * h0, 0.0 * h0, h0 + R_BALL]),
        vel=(2.0, 0.0, 0.0),
        omega=(0.0, -30.0, 0.0),
    )
    traj = jaxrb.simulate(scene, state0, jnp.array([0.0, 0.55]), throw=False, **TOL)
    s = traj.states
    return jnp.stack([s.pos[-1, 0], s.pos[-1, 2], s.vel[-1, 0], s.omega[-1, 1]]), traj.impacts.count


_spin_ball_jacobian = jax.jit(jax.jacrev(lambda p: _spin_ball_final(p)[0]))
_spin_ball = jax.jit(_spin_ball_final)


@pytest.mark.parametrize("mu", [0.2, 0.6], ids=["sliding", "sticking"])
def test_gradients_across_impact_wrt_friction_drag_inertia(mu):
    """d(final state)/d(friction, drag coefficient, moment of inertia, height) vs central
    differences, through one impact that slides (mu = 0.2) or sticks (mu = 0.6)."""
    params = jnp.array([mu, 0.02, 0.004, 0.5])
    _, count = _spin_ball(params)
    assert int(count) == 1
    jac = np.asarray(_spin_ball_jacobian(params))
    for i in range(4):
        # solver noise in the post-impact state ~1e-9 (tolerance 1e-10, times impulse/inertia
        # factors), so central differences need eps ~1e-4 relative: noise / eps ~ 1e-5
        eps = 1e-4 * float(params[i])
        up = np.asarray(_spin_ball(params.at[i].add(eps))[0])
        down = np.asarray(_spin_ball(params.at[i].add(-eps))[0])
        np.testing.assert_allclose(jac[:, i], (up - down) / (2 * eps), rtol=1e-5, atol=1e-5)
    # in the sliding impact the friction coefficient moves the outgoing velocity; when the
    # contact sticks, friction no longer matters but the moment of inertia does
    if mu == 0.2:
        assert abs(jac[2, 0]) > 0.1
    else:
        assert abs(jac[2, 0]) < 1e-6 and abs(jac[2, 2]) > 1.0


# ------------------------------------------------------------------ impact map


def _random_case(key):
    k = jax.random.split(key, 6)
    m = jax.random.uniform(k[0], (), minval=0.5, maxval=2.0)
    moments = jax.random.uniform(k[1], (3,), minval=0.5, maxval=1.0)
    moments = moments.at[2].set(jnp.minimum(moments[2], moments[0] + moments[1] - 0.1))
    q = jaxrb.quat_normalize(jax.random.normal(k[2], (4,)))
    state = jaxrb.State(
        jnp.zeros(3), q, jax.random.normal(k[3], (3,)), jax.random.normal(k[4], (3,))
    )
    r = jax.random.normal(k[5], (3,)) * 0.5
    return m, moments, state, r


@jax.jit
def _map_case(key, e, mu):
    m, moments, state, r = _random_case(key)
    body = jaxrb.RigidBody(m, moments)
    after, j, lost = impact_map(body, state, r, e, mu)
    R = jaxrb.quat_to_matrix(state.quat)
    un_before = (state.vel + jnp.cross(R @ state.omega, r))[2]
    u_after = after.vel + jnp.cross(R @ after.omega, r)

    def kinetic(s):
        return 0.5 * m * s.vel @ s.vel + 0.5 * s.omega @ (moments * s.omega)

    return un_before, u_after, j, lost, kinetic(state) - kinetic(after)


def test_impact_map_energy_and_laws(getkey):
    keys = jax.random.split(getkey(), 200)
    es = jax.random.uniform(getkey(), (200,))
    mus = jax.random.uniform(getkey(), (200,), maxval=1.5)
    un, u_after, j, lost, dT = jax.vmap(_map_case)(keys, es, mus)
    un, u_after, j, lost, dT = map(np.asarray, (un, u_after, j, lost, dT))
    np.testing.assert_allclose(lost, dT, atol=1e-12)
    assert np.all(lost >= -1e-12)  # energy never increases for e <= 1
    hit = un < 0
    assert np.all(j[hit, 2] > 0) and np.all(j[~hit] == 0)
    assert np.all(u_after[hit, 2] >= -1e-12)  # no contact point left approaching
    assert np.all(
        np.linalg.norm(j[:, :2], axis=1) <= np.asarray(mus) * j[:, 2] + 1e-12
    )  # friction cone
    # frictionless: u'_n = -e u_n exactly and e = 1 conserves energy
    un, u_after, j, lost, dT = map(np.asarray, jax.vmap(_map_case)(keys, es, jnp.zeros(200)))
    hit = un < 0
    np.testing.assert_allclose(
        u_after[hit, 2], -np.asarray(es)[hit] * un[hit], rtol=1e-12, atol=1e-13
    )
    _, _, _, lost1, _ = jax.vmap(_map_case)(keys, jnp.ones(200), jnp.zeros(200))
    assert np.max(np.abs(np.asarray(lost1))) < 1e-13


# ------------------------------------------------------------------ dice and coins

A_DIE = 0.008


def _tumbler(shape, e, mu):
    body = jaxrb.RigidBody(0.004, shape=shape)
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))


def _throw(omega=(5.0, -8.0, 3.0), vel=(0.3, 0.0, 0.0), z=0.1):
    q = jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, 0.5]), 0.7)
    return jaxrb.make_state(pos=(0.0, 0.0, z), quat=q, vel=vel, omega=omega)


@jax.jit
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


def _face_down(quat, normals):
    """cos of the angle between the most downward face normal and -z."""
    nw = normals @ jaxrb.quat_to_matrix(quat).T
    return float(jnp.max(-nw[:, 2]))


@functools.partial(jax.jit, static_argnames="coin")
def _settle_batch(omegas, quats, vels, coin):
    shape = jaxrb.Cylinder(0.012, 0.001) if coin else jaxrb.Box((A_DIE, A_DIE, A_DIE))
    scene = _tumbler(shape, 0.5, 0.3)
    ts = jnp.linspace(0.0, 1.5, 31)

    def run(omega, quat, vel):
        state0 = jaxrb.make_state(pos=(0.0, 0.0, 0.1), quat=quat, vel=vel, omega=omega)
        return jaxrb.simulate(scene, state0, ts, throw=False, max_impacts=48)

    return scene, jax.vmap(run)(omegas, quats, vels)


@pytest.mark.parametrize("coin", [False, True], ids=["die", "coin"])
def test_tumbling_die_and_coin_settle_on_a_face(coin, getkey):
    """Random throws: each ends at rest lying flat on a face (a coin on a side, not its rim),
    never penetrating the floor, with non-negative energy lost at every impact."""
    n = 8
    omegas = jax.random.normal(getkey(), (n, 3)) * 15.0
    quats = jaxrb.quat_normalize(jax.random.normal(getkey(), (n, 4)))
    vels = jax.random.normal(getkey(), (n, 3)) * 0.5
    scene, batch = _settle_batch(omegas, quats, vels, coin)
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    rec = batch.impacts
    assert np.all(np.isfinite(np.asarray(rec.rest_time)))
    assert np.all(np.asarray(rec.rest_time) < 1.5)
    # at rest: nothing moves, a face lies flat on the floor, the mass centre above it
    np.testing.assert_array_equal(np.asarray(batch.states.vel[:, -1]), 0.0)
    np.testing.assert_array_equal(np.asarray(batch.states.omega[:, -1]), 0.0)
    normals, offsets, _ = scene.body.shape.rest_faces()
    R_end = jaxrb.quat_to_matrix(batch.states.quat[:, -1])
    down = -np.asarray(jnp.einsum("fj,bij->bfi", normals, R_end))[..., 2]  # (n, faces)
    face = np.argmax(down, axis=1)
    np.testing.assert_allclose(down[np.arange(n), face], 1.0, atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(batch.states.pos[:, -1, 2]), np.asarray(offsets)[face], atol=1e-12
    )
    # never below the floor (beyond the event locator's tolerance)
    dist = jax.vmap(jax.vmap(scene.body.shape.floor_distance))(batch.states.pos, batch.states.quat)
    assert float(jnp.min(dist)) > -1e-9
    # energy lost at each impact >= 0, and no more than the whole loss (friction adds to it)
    lost = np.where(np.asarray(rec.valid), np.asarray(rec.energy_lost), 0.0)
    assert np.all(lost >= -1e-15)
    energy = np.asarray(jax.vmap(lambda s: jaxrb.energy(scene, s))(batch.states))
    assert np.all(lost.sum(axis=1) <= energy[:, 0] - energy[:, -1] + 1e-12)


def test_die_batch_vmap_equals_per_member(getkey):
    """1000 dice thrown with different spins bounce different numbers of times under vmap."""
    scene = _tumbler(jaxrb.Box((A_DIE, A_DIE, A_DIE)), 0.6, 0.3)
    omegas = jax.random.normal(getkey(), (1000, 3)) * 10.0
    heights = jax.random.uniform(getkey(), (1000,), minval=0.02, maxval=0.06)
    ts = jnp.linspace(0.0, 0.15, 4)

    def run(omega, z):
        return _die_run(scene, _throw(omega=omega, z=z), ts)

    batch = jax.vmap(run)(omegas, heights)
    counts = np.asarray(batch.impacts.count)
    assert len(set(counts.tolist())) > 1  # members bounce different numbers of times

    # Equal up to the problem's conditioning: batched arithmetic differs from unbatched by
    # roundoff (1e-16, seen before the first impact), and a tumbling die amplifies any 1e-16
    # change through the adaptive step sequence and each bounce (measured: a 1e-15 relative
    # change of the initial spin moves the state at t = 0.15 s by up to 1e-7 relative). So
    # each member is compared with its own run and with that run's response to such a change.
    def rel(a, b):
        return max(
            float(np.max(np.abs(np.asarray(x) - np.asarray(y)) / (1e-3 + np.abs(np.asarray(x)))))
            for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
        )

    for i in (0, 1, int(np.argmax(counts)), int(np.argmin(counts))):
        one = run(omegas[i], heights[i])
        assert int(one.impacts.count) == counts[i]
        nudged = run(omegas[i] * (1 + 1e-15), heights[i])
        member = jax.tree.map(lambda x, i=i: x[i], batch.states)
        assert rel(one.states, member) <= 10 * rel(one.states, nudged.states) + 1e-12
        np.testing.assert_allclose(
            np.asarray(one.impacts.time[: counts[i]]),
            np.asarray(batch.impacts.time[i, : counts[i]]),
            rtol=0,
            atol=1e-9,
        )


# ------------------------------------------------------------------ sliding contact


@jax.jit
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


def test_die_slides_to_rest_on_its_face():
    """A die lying on a face, sliding and spinning: the slip s = (v_x, v_y, rho w_z) (rho the
    radius of gyration about the vertical) shrinks at the rate mu g along a fixed direction,
    so it stops at T = |s0| / (mu g), having moved v0 T / 2 and turned w_z0 T / 2."""
    mu, vx, vy, wz = 0.3, 0.4, -0.25, 30.0
    scene = _sliding_die(mu, drag=0.0, damping=0.0)
    rho = A_DIE * np.sqrt(2 / 3)  # cube: I_zz = (2/3) m a^2 about the vertical
    T = np.linalg.norm([vx, vy, rho * wz]) / (mu * G)
    ts = jnp.asarray([0.0, 0.5 * T, T + 0.01, 1.0])
    state0 = jaxrb.make_state(pos=(0.0, 0.0, A_DIE), vel=(vx, vy, 0.0), omega=(0.0, 0.0, wz))
    traj = _slide_run(scene, state0, ts)
    assert traj.result == jaxrb.RESULTS.successful
    frac = 1 - (1 - 0.5) ** 2  # distance fraction covered by t = T/2 at constant deceleration
    np.testing.assert_allclose(
        np.asarray(traj.states.pos[1, :2]), frac * np.array([vx, vy]) * T / 2, atol=1e-10
    )
    for k in (2, 3):  # at rest, exactly
        np.testing.assert_allclose(
            np.asarray(traj.states.pos[k]), [vx * T / 2, vy * T / 2, A_DIE], rtol=0, atol=1e-10
        )
        np.testing.assert_array_equal(np.asarray(traj.states.vel[k]), 0.0)
        np.testing.assert_array_equal(np.asarray(traj.states.omega[k]), 0.0)
        yaw = 2 * np.arctan2(float(traj.states.quat[k, 3]), float(traj.states.quat[k, 0]))
        np.testing.assert_allclose(yaw, wz * T / 2, rtol=0, atol=1e-8)


def test_sliding_dice_with_drag_batch_equals_per_member(getkey):
    """Drag turns the slip direction while a die slides on its face; sliding must still end
    cleanly (no creeping onto the Coulomb discontinuity) for every member under vmap."""
    scene = _sliding_die(0.3, drag=0.012, damping=1e-7)
    ts = jnp.linspace(0.0, 1.0, 5)

    def run(v, wz):
        state0 = jaxrb.make_state(
            pos=(0.0, 0.0, A_DIE), vel=jnp.stack([v[0], v[1], 0.0]), omega=jnp.stack([0, 0, wz])
        )
        return _slide_run(scene, state0, ts)

    vs = jax.random.normal(getkey(), (6, 2)) * 0.5
    wzs = jax.random.normal(getkey(), (6,)) * 40.0
    batch = jax.vmap(run)(vs, wzs)
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    np.testing.assert_array_equal(np.asarray(batch.states.vel[:, -1]), 0.0)
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


def test_bad_input_flagged_under_vmap():
    """Traced restitution / friction / start height: one result code per member."""
    ts = jnp.linspace(0.0, 1.0, 14)

    @jax.vmap
    def run(e, mu, h):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(1.0, shape=jaxrb.Sphere(R_BALL)),
            forces=(jaxrb.Gravity(),),
            floor=jaxrb.Floor(e, mu),
        )
        return jaxrb.simulate(
            scene, jaxrb.make_state(pos=jnp.stack([0.0 * h, 0.0 * h, h])), ts, throw=False, **TOL
        ).result

    res = run(
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
    assert int(traj.impacts.count) > 3 and np.isfinite(float(traj.impacts.rest_time))
    np.testing.assert_array_equal(np.asarray(traj.states.vel[-1]), 0.0)
    assert float(traj.states.pos[-1, 2]) == pytest.approx(A_DIE, abs=1e-6)
