"""Persistent contact against references computed without jaxrb: a rocking block (Housner's
planar rocking equation), a die pivoting on an edge (the pivot equation), a coin rolling on
its rim (the rolling-disc equations derived with sympy's Kane's method), and the reported
penetration / energy-gain cases."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent
from scipy.integrate import solve_ivp

import jaxrb

G = 9.81
PRECISE = dict(rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------ a box on an edge


def _box(half, mass, e, mu, state0, ts, rest_speed=1e-6, forward_mode=False):
    """`_box_run` with every argument passed the same way (positionally), so that a call
    naming a default reuses the trace of one that leaves it out."""
    return _box_run(half, mass, e, mu, state0, ts, rest_speed, forward_mode)


@persistent(static_argnames=("rest_speed", "forward_mode"))
def _box_run(half, mass, e, mu, state0, ts, rest_speed, forward_mode):
    body = jaxrb.RigidBody(mass, shape=jaxrb.Box(half))
    scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))
    options = jaxrb.contact.ContactOptions(rest_speed=rest_speed, max_impacts=16)
    adjoint = dfx.ForwardMode() if forward_mode else None
    return jaxrb.simulate(
        scene, state0, ts, throw=False, contact=options, adjoint=adjoint, **PRECISE
    )


def _on_edge(half, tilt):
    """A box turned by `tilt` (rad) about -y, resting on its +x bottom edge."""
    q = jaxrb.axis_angle_to_quat(jnp.array([0.0, -1.0, 0.0]), tilt)
    lowest = -float(jaxrb.Box(half).floor_distance(jnp.zeros(3), q, 0.0))
    return jaxrb.make_state(pos=(0.0, 0.0, lowest), quat=q)


def _tilt(quat):
    """The box's rotation about -y (rad) from its attitude."""
    R = np.asarray(jaxrb.quat_to_matrix(quat))
    return np.arctan2(-R[..., 0, 2], R[..., 2, 2])


def _rocking_reference(alpha, p2, theta0, n):
    """Housner's planar rocking block: theta'' = -s p^2 sin(alpha - s theta) about the edge
    s = sign(theta), released from rest at theta0 > 0; at each impact (theta = 0) the angular
    velocity is multiplied by 1 - 1.5 sin^2(alpha) (the angular momentum about the new edge
    is conserved). Returns the impact times and the amplitudes of the half-cycles after
    them, with the apex times."""
    ratio = 1 - 1.5 * np.sin(alpha) ** 2
    t, theta, omega, s = 0.0, theta0, 0.0, 1.0
    times, apex_times, amplitudes = [], [], []
    for _ in range(n):

        def f(_, y, s=s):
            return [y[1], -s * p2 * np.sin(alpha - s * y[0])]

        def hit(_, y):
            return y[0]

        def apex(_, y):
            return y[1]

        hit.terminal, hit.direction = True, -s
        apex.direction = s
        sol = solve_ivp(f, [t, t + 10.0], [theta, omega], events=(hit, apex), **_REF)
        if sol.t_events[1].size and times:
            apex_times.append(sol.t_events[1][0])
            amplitudes.append(abs(sol.y_events[1][0][0]))
        t, omega = sol.t_events[0][0], sol.y_events[0][0][1] * ratio
        theta, s = 0.0, np.sign(omega)
        times.append(t)
    return np.array(times), np.array(apex_times), np.array(amplitudes)


_REF = dict(rtol=1e-13, atol=1e-14, method="DOP853")


def test_rocking_block_against_housner():
    """A slender block (e = 0, no slip) released tilted by alpha / 2 on an edge: impact
    times and the amplitudes between them against the planar rocking equation, 1e-6."""
    b, d, h, m = 0.05, 0.1, 0.25, 2.0
    R, alpha = np.hypot(b, h), np.arctan2(b, h)
    p2 = m * G * R / (4 / 3 * m * R**2)
    theta0 = 0.5 * alpha
    times, apex_times, amplitudes = _rocking_reference(alpha, p2, theta0, 4)
    ts = jnp.asarray(np.concatenate([[0.0], apex_times, [times[-1] + 0.01]]))
    half = jnp.array([b, d, h])
    traj = _box(half, m, 0.0, 2.0, _on_edge(half, theta0), ts)
    assert traj.result == jaxrb.RESULTS.successful
    got = np.asarray(traj.impacts.time[:4])
    np.testing.assert_allclose(got, times, rtol=1e-6)
    np.testing.assert_allclose(np.abs(_tilt(traj.states.quat[1:-1])), amplitudes, rtol=1e-6)
    assert int(traj.contact.zeno_merges) == 0
    assert int(traj.contact.inconsistent) == 0


def test_die_pivots_on_an_edge_and_falls_onto_a_face():
    """A cube released at rest on an edge, 10 degrees past its balance: it pivots about the
    edge (no slip, mu = 2) by phi'' = (m g r / I_edge) sin(phi), r = a sqrt(2),
    I_edge = 8/3 m a^2, and lands on a face when phi = 45 degrees: that time, and the
    angular velocity then (the landing edge's approach speed / 2a), to 1e-6."""
    a, m = 0.008, 0.004
    phi0 = np.radians(10.0)
    k = m * G * a * np.sqrt(2) / (8 / 3 * m * a**2)

    def f(_, y):
        return [y[1], k * np.sin(y[0])]

    def lands(_, y):
        return y[0] - np.pi / 4

    lands.terminal = True
    ref = solve_ivp(f, [0.0, 5.0], [phi0, 0.0], events=lands, **_REF)
    t_land = ref.t_events[0][0]
    w_land = ref.y_events[0][0][1]
    assert w_land == pytest.approx(np.sqrt(2 * k * (np.cos(phi0) - np.cos(np.pi / 4))), rel=1e-10)
    half = jnp.array([a, a, a])
    # tilted about -y by 45 - 10 degrees: the diagonal through the +x bottom edge is 10
    # degrees from the vertical, on the side that falls back onto the bottom face
    ts = jnp.linspace(0.0, 1.0, 6) * 0.999 * t_land
    traj = _box(half, m, 0.0, 2.0, _on_edge(half, np.pi / 4 - phi0), ts)
    assert traj.result == jaxrb.RESULTS.successful
    assert int(traj.impacts.count) == 0
    assert np.all(np.asarray(traj.contact.kind[1:]) == jaxrb.contact.KIND_NAMES.index("pair"))
    assert not np.any(np.asarray(traj.contact.sliding[1:]))
    phi = np.pi / 4 - np.abs(_tilt(traj.states.quat))
    ref_phi = [solve_ivp(f, [0.0, float(t)], [phi0, 0.0], **_REF).y[0, -1] for t in ts[1:]]
    np.testing.assert_allclose(phi[1:], ref_phi, rtol=1e-6)
    ts_land = jnp.linspace(0.0, 1.0, 6) * (t_land + 1e-3)
    landed = _box(half, m, 0.0, 2.0, _on_edge(half, np.pi / 4 - phi0), ts_land)
    assert float(landed.impacts.time[0]) == pytest.approx(t_land, rel=1e-6)
    speed = float(landed.impacts.normal_speed[0])  # the far edge: 2a from the pivot
    assert speed / (2 * a) == pytest.approx(w_land, rel=1e-6)


def _second_impact_time(b, forward_mode=False):
    """Rocking block of half-width b: the time of its second impact (s)."""
    d, h, m = 0.1, 0.25, 2.0
    half = jnp.stack([b, d + 0 * b, h + 0 * b])
    q = jaxrb.axis_angle_to_quat(jnp.array([0.0, -1.0, 0.0]), 0.1)
    lowest = -jaxrb.Box(half).floor_distance(jnp.zeros(3), q, 0.0)
    state0 = jaxrb.make_state(pos=jnp.stack([0.0 * b, 0.0 * b, lowest]), quat=q)
    ts = jnp.linspace(0.0, 1.2, 4)
    return _box(half, m, 0.0, 2.0, state0, ts, forward_mode=forward_mode).impacts.time[1]


_second_impact_time_grad = persistent(jax.jacfwd(lambda b: _second_impact_time(b, True)))


def test_rocking_block_gradient_of_second_impact_time():
    """d(second impact time)/d(half-width) through two impacts and the rocking between them,
    against central differences (1e-5). Forward mode (quicker to compile than reverse mode;
    reverse mode through impacts and mode changes: test_contact_impacts)."""
    b = 0.05
    t2 = float(_second_impact_time(jnp.asarray(b)))
    assert 0.3 < t2 < 1.2
    grad = float(_second_impact_time_grad(jnp.asarray(b)))
    eps = 1e-5
    fd = (
        float(_second_impact_time(jnp.asarray(b + eps)))
        - float(_second_impact_time(jnp.asarray(b - eps)))
    ) / (2 * eps)
    assert grad == pytest.approx(fd, rel=1e-5)


# ------------------------------------------------------------------ a coin on its rim

COIN_R, COIN_H, COIN_M = 0.012, 0.001, 0.0075


def _coin_scene(mu, damping):
    body = jaxrb.RigidBody(COIN_M, shape=jaxrb.Cylinder(COIN_R, COIN_H))
    forces = (jaxrb.Gravity(), jaxrb.DampingMoment(damping))
    return jaxrb.Scene(body, forces=forces, floor=jaxrb.Floor(0.5, mu))


@persistent
def _coin_run(mu, damping, state0, ts):
    """One compilation for every coin test (a rolling coin has many stick/slip events)."""
    options = jaxrb.contact.ContactOptions(max_impacts=64, max_events=1500)
    scene = _coin_scene(mu, damping)
    return jaxrb.simulate(scene, state0, ts, throw=False, contact=options, **PRECISE)


COIN_TS = jnp.linspace(0.0, 5.0, 501)  # the coin tests' save times (one compilation)


def _rolling_coin_start(rhs_extras, y0):
    _, extras = rhs_extras
    pos0, axes0, w0, v0 = extras(y0)
    R0 = axes0.T  # columns: the body axes in world components
    return jaxrb.make_state(
        pos=pos0, quat=jaxrb.matrix_to_quat(jnp.asarray(R0)), vel=v0, omega=R0.T @ w0
    )


def test_coin_rolls_on_its_rim_as_the_rolling_disc_equations_say():
    """A coin set rolling on its rim without slipping (mu = 2) against the rolling-disc
    equations (Kane's method in sympy): mass centre and lean over 1 s, 1e-6 relative."""
    pytest.importorskip("sympy", reason="the rolling-disc reference needs sympy ([test] extra)")
    from rolling_disc_reference import rolling_disc_rhs

    rhs, extras = rolling_disc_rhs(COIN_M, COIN_R, COIN_H, G)
    y0 = np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.5, -20.0, 1.0])  # lean 0.3 rad, spinning
    ts = np.asarray(COIN_TS) / 5.0  # 1 s
    ref = solve_ivp(rhs, (0.0, ts[-1]), y0, dense_output=True, **_REF)
    state0 = _rolling_coin_start((rhs, extras), y0)
    traj = _coin_run(2.0, 0.0, state0, jnp.asarray(ts))
    assert traj.result == jaxrb.RESULTS.successful
    assert int(traj.impacts.count) == 0
    assert not np.any(np.asarray(traj.contact.sliding))
    ref_pos = np.array([extras(ref.sol(t))[0] for t in ts])
    ref_lean = np.array([ref.sol(t)[1] for t in ts])
    R = np.asarray(jaxrb.quat_to_matrix(traj.states.quat))
    lean = np.arccos(np.clip(R[:, 2, 2], -1, 1))  # body z (the disc's axis) from vertical
    lean = np.pi / 2 - lean  # the disc's plane from vertical, as the reference's q2
    travel = np.max(np.abs(ref_pos - ref_pos[0]))
    np.testing.assert_allclose(np.asarray(traj.states.pos), ref_pos, rtol=0, atol=1e-6 * travel)
    np.testing.assert_allclose(np.abs(lean), np.abs(ref_lean), rtol=1e-6)
    assert np.ptp(ref_lean) > 0.3  # the lean changes: a real test of the dynamics


def test_coin_spun_on_its_rim_comes_down_flat():
    """Euler's disk: a coin rolling and spinning on its rim, slowed by a damping moment,
    comes down onto its face and rests there; its energy never rises (between saves beyond
    the solver's tolerance, nor at an event), it never goes under the floor, and its
    attitude never jumps: between two saves it turns by no more than its angular velocity
    allows."""
    pytest.importorskip("sympy", reason="the rolling-disc start needs sympy ([test] extra)")
    from rolling_disc_reference import rolling_disc_rhs

    y0 = np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.5, -20.0, 1.0])
    state0 = _rolling_coin_start(rolling_disc_rhs(COIN_M, COIN_R, COIN_H, G), y0)
    traj = _coin_run(0.5, 1e-6, state0, COIN_TS)
    assert traj.result == jaxrb.RESULTS.successful
    kind = np.asarray(traj.contact.kind)
    assert np.mean(kind == jaxrb.contact.KIND_NAMES.index("point")) > 0.5  # rolled on its rim
    assert kind[-1] == jaxrb.contact.KIND_NAMES.index("face")
    s = traj.states
    np.testing.assert_allclose(np.asarray(s.vel[-1]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(s.omega[-1]), 0.0, atol=1e-7)
    np.testing.assert_allclose(float(s.pos[-1, 2]), COIN_H, atol=1e-9)  # flat on its face
    energy = np.asarray(jaxrb.energy(_coin_scene(0.5, 1e-6), s))
    assert np.max(np.diff(energy)) <= 1e-9 * energy[0]
    assert float(traj.contact.max_energy_rise) < 1e-12 * energy[0]
    assert float(traj.contact.max_penetration) < 1e-9
    shape = jaxrb.Cylinder(COIN_R, COIN_H)
    lowest = jax.vmap(lambda p, q: shape.floor_distance(p, q, 0.0))(s.pos, s.quat)
    assert float(jnp.min(lowest)) > -1e-9
    turned = np.asarray(jaxrb.quat_geodesic_angle(s.quat[1:], s.quat[:-1]))
    spin = np.linalg.norm(np.asarray(s.omega), axis=-1)
    dt = float(COIN_TS[1] - COIN_TS[0])
    # |omega| changes within a save interval: allow half as much again as its larger end
    assert np.all(turned <= 1.5 * dt * np.maximum(spin[1:], spin[:-1]) + 1e-9)


def _slipping_coin(params, start):
    """A coin set on its rim with the spin about its axis `params[1]` (rad/s, body z) instead
    of the rolling value: its rim point slips, friction (`params[0]`) stops the slip, and it
    rolls on. Returns its mass centre's (x, y) at t = 0.3 s and its contact log."""
    mu, spin = params
    state0 = jaxrb.State(start.pos, start.quat, start.vel, start.omega.at[2].set(spin))
    options = jaxrb.contact.ContactOptions(max_impacts=16, max_events=64)
    traj = jaxrb.simulate(
        _coin_scene(mu, 0.0),
        state0,
        jnp.array([0.0, 0.1, 0.3]),
        throw=False,
        contact=options,
        adjoint=dfx.ForwardMode(),
        **PRECISE,
    )
    return traj.states.pos[-1, :2], (traj.result, traj.contact)


# value and directional derivative in one compilation (central differences reuse the value)
_slipping_coin_jvp = persistent(
    lambda p, v, start: jax.jvp(lambda q: _slipping_coin(q, start), (p,), (v,), has_aux=True)
)


def test_rolling_coin_gradient_wrt_friction_and_spin():
    """d(mass centre at 0.3 s)/d(friction, initial spin) of a coin whose rim slips at first
    and then rolls (a slide -> stick mode change), forward mode, against central
    differences (1e-5)."""
    pytest.importorskip("sympy", reason="the rolling-disc start needs sympy ([test] extra)")
    from rolling_disc_reference import rolling_disc_rhs

    y0 = np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.5, -20.0, 1.0])  # rolls with spin -20 rad/s
    start = _rolling_coin_start(rolling_disc_rhs(COIN_M, COIN_R, COIN_H, G), y0)
    params = jnp.array([0.5, -23.0])
    for i, eps in enumerate([1e-4, 1e-3]):
        v = jnp.eye(2)[i]
        _, tangent, (result, log) = _slipping_coin_jvp(params, v, start)
        assert result == jaxrb.RESULTS.successful
        # it slid at first, stopped slipping at an event and rolled on its rim from then on
        sliding, kind = np.asarray(log.sliding), np.asarray(log.kind)
        assert sliding[0] and not np.any(sliding[1:])
        assert np.all(kind == jaxrb.contact.KIND_NAMES.index("point"))
        causes = [jaxrb.contact.CAUSES[int(c)] for c in log.event_cause[: int(log.events) + 1]]
        assert causes[1:] == ["slip stops"], causes  # slot 0: the start
        up = np.asarray(_slipping_coin_jvp(params + eps * v, v, start)[0])
        down = np.asarray(_slipping_coin_jvp(params - eps * v, v, start)[0])
        fd = (up - down) / (2 * eps)
        assert np.all(np.abs(fd) > 1e-4)  # both parameters move the coin
        np.testing.assert_allclose(np.asarray(tangent), fd, rtol=1e-5)


# ------------------------------------------------------------------ the reported cases


def test_repro_die_penetration():
    """A die thrown onto a floor with friction for 10 s: never below the floor by more than
    1e-9 m at any save or event, energy never rises at an event, at rest on a face."""
    die = jaxrb.Box(jnp.array([0.008] * 3))
    h = 0.990080435442662
    scene = jaxrb.Scene(
        jaxrb.RigidBody(0.0045, shape=die),
        (jaxrb.Gravity(),),
        floor=jaxrb.Floor(0.6839672109557128, 0.7444954432899723, h),
    )
    s0 = jaxrb.make_state(
        pos=[-0.46344395327737176, 0.8894400729158523, 1.0546392495668784],
        quat=[-0.20004650270260171, 0.4249826846566069, 0.8168934296590874, 0.33474802326277436],
        vel=[0.5879337674788814, -0.33479568806918825, 0.29993026406277723],
        omega=[-63.62237777630117, 59.05728635426463, -13.436511178308589],
    )
    tr = jaxrb.simulate(scene, s0, jnp.linspace(0, 10, 501), max_impacts=200)
    dist = jax.vmap(lambda p, q: die.floor_distance(p, q, h))(tr.states.pos, tr.states.quat)
    assert float(dist.min()) > -1e-9
    assert float(tr.contact.max_penetration) < 1e-9
    valid = np.asarray(tr.impacts.valid)
    assert np.all(np.asarray(tr.impacts.energy_lost)[valid] >= 0)
    assert float(tr.contact.max_energy_rise) < 1e-15
    assert int(tr.contact.kind[-1]) == jaxrb.contact.KIND_NAMES.index("face")


def test_repro_coin_energy():
    """A coin thrown for 10 s: no impact records a negative energy loss, the energy never
    rises at an event or between saves (beyond the solver's tolerance), no penetration."""
    coin = jaxrb.Cylinder(0.012, 0.001)
    scene = jaxrb.Scene(
        jaxrb.RigidBody(0.0075, shape=coin),
        (jaxrb.Gravity(),),
        floor=jaxrb.Floor(0.9602847184010643, 0.2436086523859945, -0.976949661285373),
    )
    s0 = jaxrb.make_state(
        pos=[-0.19418000349335984, 0.5383732435963133, -0.5539018403514786],
        quat=[-0.24204765618445448, -0.5490395083507563, -0.7429521191088347, -0.2966322624349277],
        vel=[0.6041648330765275, 0.8040986219712833, 0.23318003766312412],
        omega=[68.2902061131441, -16.215552188633747, -57.902811433330776],
    )
    tr = jaxrb.simulate(scene, s0, jnp.linspace(0, 10, 501), max_impacts=200)
    valid = np.asarray(tr.impacts.valid)
    assert np.all(np.asarray(tr.impacts.energy_lost)[valid] >= 0)
    assert float(tr.contact.max_energy_rise) < 1e-15
    energy = np.asarray(jaxrb.energy(scene, tr.states))
    # (the energy's zero is the world origin's height: scale by its size, not its sign)
    assert np.max(np.diff(energy)) < 1e-9 * abs(energy[0])
    floor = scene.floor.height
    dist = jax.vmap(lambda p, q: coin.floor_distance(p, q, floor))(tr.states.pos, tr.states.quat)
    assert float(dist.min()) > -1e-9
