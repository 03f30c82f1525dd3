"""A ball on a roulette wheel's stator (`Wheel`: inclined track + smooth outer wall) against
closed forms (float64).

The track is the cone z = tan(d) rho, the wall the cylinder rho = R. A ball of radius r
and mass m pressed into the corner has its centre on the circle rho_c = R - r at the height
(r + rho_c sin d) / cos d; v is its speed along e_phi. With the track's normal
n_a = -sin d e_rho + cos d e_z, the wall's n_b = -e_rho, quadratic drag -k |v| v on the
centre and rolling resistance mu_r on the track (docs/contact.md, section 11):

- rolling on the track (no spin about n_a), sliding on the smooth wall:
  N_wall = m ((7/5) v^2 / rho_c - g tan d), N_track = m (g / cos d - (2/5) (v^2 / rho_c) sin d),
  v' = -(A + B v^2) with A = (5/7) mu_r g / cos d, B = (5/7) (k / m - (2/5) mu_r sin d / rho_c),
  so v(t) = tan(atan(q v0) - sqrt(A B) t) / q (q = sqrt(B / A)), and the ball leaves the
  wall when v^2 = (5/7) g rho_c tan d;
- sliding on a frictionless track (mu = 0, no rolling resistance, no spin):
  v' = -(k / m) v^2, v = v0 / (1 + k v0 t / m); it leaves the wall when v^2 / rho_c = g tan d
  (a point mass's condition).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb

G, D, R_WALL, R_BALL, MASS = 9.81, 0.3, 0.4, 0.01, 0.005
RHO = R_WALL - R_BALL
Z_CORNER = (R_BALL + RHO * np.sin(D)) / np.cos(D)
E_RHO, E_PHI, E_Z = np.eye(3)
V0, MU_R, DRAG = 2.0, 0.01, 1e-3  # m/s, -, kg/m


def rolling_closed_form(mu_r=MU_R, k=DRAG, v0=V0, m=MASS, rho=RHO, d=D):
    """(v(t), leaving time) of a ball rolling round against the wall."""
    A = 5 / 7 * mu_r * G / np.cos(d)
    B = 5 / 7 * (k / m - 0.4 * mu_r * np.sin(d) / rho)
    q, rate = np.sqrt(B / A), np.sqrt(A * B)
    v_leave = np.sqrt(5 / 7 * G * rho * np.tan(d))
    return (
        lambda t: np.tan(np.arctan(q * v0) - rate * t) / q,
        (np.arctan(q * v0) - np.arctan(q * v_leave)) / rate,
    )


def sliding_closed_form(k=DRAG, v0=V0):
    """(v(t), leaving time) of a ball sliding round a frictionless track against the wall."""
    v_leave = np.sqrt(G * RHO * np.tan(D))
    return lambda t: v0 / (1 + k * v0 * t / MASS), MASS / k * (1 / v_leave - 1 / v0)


@persistent
def _on_wheel(friction, rolling, wall_radius, state0, ts):
    def one(friction, rolling, wall_radius, state0, ts):
        body = jaxrb.RigidBody(MASS, shape=jaxrb.Sphere(R_BALL))
        wheel = jaxrb.Wheel(
            0.6, friction, inclination=D, wall_radius=wall_radius, rolling_resistance=rolling
        )
        scene = jaxrb.Scene(body, (jaxrb.Gravity(), jaxrb.QuadraticDrag(DRAG)), floor=wheel)
        traj = jaxrb.simulate(
            scene, state0, ts, rtol=1e-10, atol=1e-10, max_impacts=40, throw=False
        )
        return traj, jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states)

    return jax.vmap(one)(friction, rolling, wall_radius, state0, ts)


@pytest.fixture(scope="module")
def wheel_runs():
    """Four balls in one compiled program: rolling round against the wall (track friction
    0.5), sliding round a frictionless track (no rolling resistance), dropped onto the track
    near the wall moving outwards (it bounces on track and wall), and one on a wheel with an
    invalid wall."""
    corner = E_RHO * RHO + E_Z * Z_CORNER
    rolling = jaxrb.make_state(
        pos=corner, vel=V0 * E_PHI, omega=-(V0 / R_BALL) * (np.cos(D) * E_RHO + np.sin(D) * E_Z)
    )
    sliding = jaxrb.make_state(pos=corner, vel=V0 * E_PHI)
    dropped = jaxrb.make_state(pos=0.35 * E_RHO + 0.2 * E_Z, vel=0.5 * E_RHO + 1.5 * E_PHI)
    states = [rolling, sliding, dropped, rolling]
    state0 = jax.tree.map(lambda *x: jnp.stack(x), *states)
    ends = [1.3 * rolling_closed_form()[1], 1.3 * sliding_closed_form()[1], 3.0, 1.0]
    ts = jnp.asarray(np.stack([np.linspace(0.0, end, 201) for end in ends]))
    friction = jnp.array([0.5, 0.0, 0.4, 0.5])
    rolling = jnp.array([MU_R, 0.0, MU_R, MU_R])
    wall = jnp.array([R_WALL, R_WALL, R_WALL, -1.0])
    traj, energy = _on_wheel(friction, rolling, wall, state0, ts)
    return traj, np.asarray(energy), np.asarray(ts)


def _member(traj, i):
    return jax.tree.map(lambda x: x[i], traj)


def _lift_off_time(traj):
    """The time of the first event that ended a two-point contact (pair) segment."""
    log = traj.contact
    kinds = np.asarray(log.event_kind)
    causes = np.asarray(log.event_cause)
    times = np.asarray(log.event_time)
    left = np.flatnonzero((kinds[:-1] == 2) & (kinds[1:] == 1))
    assert left.size, (kinds[:8], causes[:8])
    assert jaxrb.contact.CAUSES[causes[left[0] + 1]] == "lift-off"
    return times[left[0] + 1]


@pytest.mark.parametrize(
    "member, closed_form",
    [(0, rolling_closed_form), (1, sliding_closed_form)],
    ids=["rolling", "sliding"],
)
def test_ball_leaves_the_wall_when_the_closed_form_says(wheel_runs, member, closed_form):
    traj, energy, ts = wheel_runs
    traj, ts = _member(traj, member), ts[member]
    assert traj.result == jaxrb.RESULTS.successful
    speed_of, t_leave = closed_form()
    t_sim = _lift_off_time(traj)
    # the issue asks for 1e-6 relative; the event time is resolved far better
    assert abs(t_sim - t_leave) <= 1e-8 * t_leave, (t_sim, t_leave)
    pos, vel = np.asarray(traj.states.pos), np.asarray(traj.states.vel)
    on_wall = ts < t_leave
    # in the corner: on the circle rho = R - r at the corner's height, at the closed-form speed
    np.testing.assert_allclose(np.hypot(pos[on_wall, 0], pos[on_wall, 1]), RHO, atol=1e-10)
    np.testing.assert_allclose(pos[on_wall, 2], Z_CORNER, atol=1e-10)
    speed = np.linalg.norm(vel[on_wall], axis=1)
    np.testing.assert_allclose(speed, speed_of(ts[on_wall]), rtol=1e-9)
    # afterwards it runs down the track, off the wall, touching the track only
    kind = np.asarray(traj.contact.kind)
    assert np.all(kind[on_wall] == 2) and np.all(kind[ts > t_leave] == 1)
    assert np.all(np.hypot(pos[~on_wall, 0], pos[~on_wall, 1]) <= RHO + 1e-10)
    assert pos[-1, 2] < Z_CORNER - 1e-3
    # drag and rolling resistance only take energy away
    assert np.all(np.diff(energy[member]) <= 1e-12 * energy[member][0])


def test_ball_bouncing_on_track_and_wall_never_enters_either_nor_gains_energy(wheel_runs):
    traj, energy, _ = wheel_runs
    traj, energy = _member(traj, 2), energy[2]
    log = traj.contact
    assert traj.result == jaxrb.RESULTS.successful
    pos = np.asarray(traj.states.pos)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    track_gap = pos[:, 2] * np.cos(D) - rho * np.sin(D) - R_BALL
    assert np.min(track_gap) >= -1e-9 and np.min(RHO - rho) >= -1e-9
    # it hit the wall: an impact at the wall (rho = R) whose impulse pushes it inwards
    hits = traj.impacts
    valid = np.asarray(hits.valid)
    point, impulse = np.asarray(hits.point)[valid], np.asarray(hits.impulse)[valid]
    radius = np.hypot(point[:, 0], point[:, 1])
    inwards = np.sum(point[:, :2] * impulse[:, :2], axis=1) / radius < 0
    at_wall = (np.abs(radius - R_WALL) <= 1e-6) & inwards
    assert np.any(at_wall), (radius, impulse)
    assert log.max_penetration <= 1e-9 and log.max_energy_rise <= 1e-9
    assert int(log.inconsistent) == 0
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])
    # after its bounces it rolls on the track
    assert np.asarray(log.kind)[-1] == 1 and not np.asarray(log.sliding)[-1]


def test_an_invalid_wheel_is_flagged_per_member_under_vmap(wheel_runs):
    codes = np.asarray(wheel_runs[0].result._value)
    assert codes[3] == jaxrb.RESULTS.invalid_surface._value
    assert np.all(codes[:3] == jaxrb.RESULTS.successful._value)


def test_wheel_meets_only_a_ball_and_checks_its_dimensions():
    box = jaxrb.RigidBody(0.1, shape=jaxrb.Box((0.01, 0.01, 0.01)))
    scene = jaxrb.Scene(box, (jaxrb.Gravity(),), floor=jaxrb.Wheel(0.5, 0.3))
    with pytest.raises(ValueError, match="Wheel meets only a Sphere"):
        jaxrb.simulate(scene, jaxrb.make_state(pos=(0.2, 0, 0.5)), jnp.linspace(0, 0.1, 3))
    with pytest.raises(ValueError, match="wall_radius"):
        jaxrb.Wheel(0.5, 0.3, wall_radius=0.0)
    with pytest.raises(ValueError, match="inclination"):
        jaxrb.Wheel(0.5, 0.3, inclination=-0.1)
    ball = jaxrb.RigidBody(MASS, shape=jaxrb.Sphere(R_BALL))
    smooth = jaxrb.Scene(ball, (), floor=jaxrb.Wheel(0.5, 0.0, rolling_resistance=0.01))
    with pytest.raises(ValueError, match="rolling and spin resistance need friction"):
        jaxrb.simulate(smooth, jaxrb.make_state(pos=(0.2, 0, 0.5)), jnp.linspace(0, 0.1, 3))
    outside = jaxrb.Scene(ball, (jaxrb.Gravity(),), floor=jaxrb.Wheel(0.5, 0.3, wall_radius=0.4))
    with pytest.raises(ValueError, match="starts below the floor"):
        jaxrb.simulate(outside, jaxrb.make_state(pos=(0.45, 0, 0.5)), jnp.linspace(0, 0.1, 3))


def test_wheel_frames_and_gaps_are_the_track_and_the_wall():
    wheel = jaxrb.Wheel(0.5, 0.3, inclination=D, wall_radius=R_WALL)
    centre = jnp.array([0.0, RHO, Z_CORNER])  # azimuth 90 degrees: e_rho = y, e_phi = -x
    n, t1, t2 = (np.asarray(e) for e in wheel.part_frames(centre))
    e_rho, e_phi = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    np.testing.assert_allclose(n[0], -np.sin(D) * e_rho + np.cos(D) * E_Z, atol=1e-15)
    np.testing.assert_allclose(n[1], -e_rho, atol=1e-15)
    np.testing.assert_allclose(t2, [e_phi, e_phi], atol=1e-15)
    np.testing.assert_allclose(np.cross(t1, t2), n, atol=1e-15)  # right-handed
    # the ball in the corner touches both: its centre is r from each part
    np.testing.assert_allclose(wheel.part_gaps(centre), [R_BALL, R_BALL], atol=1e-15)
    np.testing.assert_allclose(wheel.gap(centre + 0.05 * e_rho), -0.04, atol=1e-15)


def test_the_roulette_example_leaves_the_wall_where_its_file_says():
    """The shipped scene's numbers: launch state in the corner, rolling (its track friction
    holds it: the launch is below the rolling limit), and its leaving time from the closed
    form (the run itself is the roulette study's)."""
    from jaxrb._scene_examples import example_path
    from jaxrb._scene_file import load_scene

    spec = load_scene(example_path("roulette"))
    wheel, ball = spec.scene.floor, spec.scene.body
    d, r = float(wheel.inclination), float(ball.shape.radius)
    rho = float(wheel.wall_radius) - r
    np.testing.assert_allclose(wheel.part_gaps(spec.state0.pos), [r, r], atol=1e-9)
    v = np.asarray(spec.state0.vel)
    w = np.asarray(spec.state0.omega)  # body = world at the identity attitude
    contact_vel = v + np.cross(w, -r * np.asarray(wheel.part_frames(spec.state0.pos)[0][0]))
    np.testing.assert_allclose(contact_vel, 0.0, atol=1e-5)
    k = float(spec.scene.forces[1].coefficient)
    m, mu_r, mu = float(ball.mass), float(wheel.rolling_resistance), float(wheel.friction)
    # the friction rolling needs at the launch, inside the track's cone
    v0 = v[1]
    normal = m * (G / np.cos(d) - 0.4 * v0**2 / rho * np.sin(d))
    needed = np.hypot(0.4 * m * v0**2 / rho * np.cos(d), 2 / 7 * k * v0**2 - 5 / 7 * mu_r * normal)
    assert needed < mu * normal
    _, t_leave = rolling_closed_form(mu_r, k, v0, m, rho, d)
    assert abs(t_leave - 10.02) < 0.005 and spec.ts[-1] > t_leave
