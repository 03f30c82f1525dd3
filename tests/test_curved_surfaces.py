"""A ball on curved surfaces against closed forms (float64).

Bowl: the inside of a sphere of radius Rb, centre O = (0, 0, Rb). A ball of radius r and
I = 2 m r^2 / 5 rolling without slipping in a vertical plane through O has kinetic energy
(7/10) m (Rb - r)^2 theta'^2 (theta the angle of its centre from the bottom, seen from O), so
(7/5) (Rb - r) theta'' = -g sin theta: a pendulum of length L = 7 (Rb - r) / 5. Released
from rest at theta0: theta(t) = 2 arcsin(k sn(K(k) - t sqrt(g / L), k)), k = sin(theta0 / 2);
at small amplitude the period is 2 pi sqrt(7 (Rb - r) / (5 g)).

Cone: z = tan(d) rho. A ball rolling without slipping on a horizontal circle of centre
radius rho at the rate Omega, with spin sigma about the contact normal, satisfies (from
m c'' = m g + N n + F and I w' = -r n x F, with w = (n x c') / r + sigma n)

    (7/5) rho Omega^2 = tan(d) (g - (2/5) r sigma Omega),

and its centre stays at the height (r + rho sin d) / cos d.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent
from scipy.special import ellipj, ellipk

import jaxrb

G, R_BALL, R_BOWL = 9.81, 0.02, 0.5
L_EQUIV = 7 * (R_BOWL - R_BALL) / 5
T_SMALL = 2 * np.pi * np.sqrt(L_EQUIV / G)  # the small-amplitude period
TS = jnp.linspace(0.0, 2 * T_SMALL, 41)  # T_SMALL / 4 is the 6th save


def bowl_scene(radius, restitution, friction):
    body = jaxrb.RigidBody(0.05, shape=jaxrb.Sphere(R_BALL))
    bowl = jaxrb.Bowl(restitution, friction, radius=radius)
    return jaxrb.Scene(body, (jaxrb.Gravity(),), floor=bowl)


@persistent
def _in_bowl(radius, restitution, friction, pos):
    def one(radius, e, mu, pos):
        scene = bowl_scene(radius, e, mu)
        return jaxrb.simulate(
            scene, jaxrb.make_state(pos=pos), TS, rtol=1e-11, atol=1e-11, max_impacts=8, throw=False
        )

    return jax.vmap(one)(radius, restitution, friction, pos)


def on_bowl(theta0):
    """The centre of a ball touching the bowl at angle theta0 from the bottom (x-z plane)."""
    return np.array([0, 0, R_BOWL]) + (R_BOWL - R_BALL) * np.array(
        [np.sin(theta0), 0.0, -np.cos(theta0)]
    )


X_DROP, Z_DROP = 0.2, 0.3  # a ball dropped from rest above the bowl's side


@pytest.fixture(scope="module")
def bowl_runs():
    pos = np.stack([on_bowl(0.2), on_bowl(0.002), [X_DROP, 0.0, Z_DROP], on_bowl(0.2)])
    radius = np.array([R_BOWL, R_BOWL, R_BOWL, -R_BOWL])  # the last: an invalid bowl
    return _in_bowl(
        jnp.asarray(radius),
        jnp.array([0.0, 0.0, 0.5, 0.0]),
        jnp.array([0.8, 0.8, 0.0, 0.8]),
        jnp.asarray(pos),
    )


def bowl_angle(pos):
    return np.arctan2(pos[:, 0], R_BOWL - pos[:, 2])


def test_ball_rolling_in_a_bowl_follows_the_exact_pendulum_motion(bowl_runs):
    traj = jax.tree.map(lambda x: np.asarray(x[0]), bowl_runs)
    assert traj.result == jaxrb.RESULTS.successful
    assert traj.impacts.count == 0 and np.all(traj.contact.kind == 1)  # rolling on a point
    assert not np.any(traj.contact.sliding)
    k, t = np.sin(0.2 / 2), np.asarray(TS)
    sn, _, _, _ = ellipj(ellipk(k**2) - t * np.sqrt(G / L_EQUIV), k**2)
    np.testing.assert_allclose(bowl_angle(traj.states.pos), 2 * np.arcsin(k * sn), atol=1e-9)
    centre = traj.states.pos - np.array([0, 0, R_BOWL])
    np.testing.assert_allclose(np.linalg.norm(centre, axis=1), R_BOWL - R_BALL, atol=1e-10)
    # rolling: the contact point is still, v + w x (-r n) = 0
    w = np.einsum("tij,tj->ti", jax.vmap(jaxrb.quat_to_matrix)(traj.states.quat), traj.states.omega)
    n = -centre / np.linalg.norm(centre, axis=1, keepdims=True)
    slip = traj.states.vel + np.cross(w, -R_BALL * n)
    assert np.max(np.abs(slip)) < 1e-9


def test_small_oscillation_in_a_bowl_has_the_rolling_period(bowl_runs):
    traj = jax.tree.map(lambda x: np.asarray(x[1]), bowl_runs)
    assert traj.result == jaxrb.RESULTS.successful
    theta = bowl_angle(traj.states.pos)
    theta0 = 0.002
    # released at theta0 from rest: at T/4 it passes the bottom, at T/2 the other side, at T
    # it is back; a period off by a relative eps moves the bottom passage by eps pi/2 theta0
    # (the amplitude correction theta0^2 / 16 = 2.5e-7 is within the bound)
    assert abs(theta[5]) / theta0 < 1e-6
    np.testing.assert_allclose(theta[[10, 20, 40]], [-theta0, theta0, theta0], rtol=1e-9)


def test_ball_dropped_into_a_bowl_bounces_where_and_how_the_closed_form_says(bowl_runs):
    traj = jax.tree.map(lambda x: np.asarray(x[2]), bowl_runs)
    assert traj.result == jaxrb.RESULTS.successful
    e, m = 0.5, 0.05
    # falling straight down, the centre meets the sphere of radius Rb - r about O
    z_hit = R_BOWL - np.sqrt((R_BOWL - R_BALL) ** 2 - X_DROP**2)
    t_hit = np.sqrt(2 * (Z_DROP - z_hit) / G)
    np.testing.assert_allclose(traj.impacts.time[0], t_hit, rtol=1e-9)
    # frictionless: the impulse is m (1 + e) |v . n| along the normal n = (O - c) / |O - c|
    c = np.array([X_DROP, 0.0, z_hit])
    n = (np.array([0, 0, R_BOWL]) - c) / (R_BOWL - R_BALL)
    v = np.array([0.0, 0.0, -G * t_hit])
    np.testing.assert_allclose(traj.impacts.impulse[0], -m * (1 + e) * (v @ n) * n, atol=1e-9)
    # it stays inside the bowl and never gains energy
    centre = traj.states.pos - np.array([0, 0, R_BOWL])
    assert np.all(np.linalg.norm(centre, axis=1) <= R_BOWL - R_BALL + 1e-9)
    assert traj.contact.max_penetration <= 1e-9 and traj.contact.max_energy_rise <= 1e-9
    scene = bowl_scene(R_BOWL, e, 0.0)
    energy = np.asarray(jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states))
    assert np.all(np.diff(energy) <= 1e-9 * energy[0])


def test_an_invalid_bowl_is_flagged_per_member_under_vmap(bowl_runs):
    codes = np.asarray(bowl_runs.result._value)
    assert codes[3] == jaxrb.RESULTS.invalid_surface._value
    assert np.all(codes[:3] == jaxrb.RESULTS.successful._value)


D_CONE, R_CONE_BALL = 0.3, 0.01


@persistent
def _on_cone(tip_radius, state0, ts):
    def one(tip_radius, state0, ts):
        body = jaxrb.RigidBody(0.05, shape=jaxrb.Sphere(R_CONE_BALL))
        cone = jaxrb.Cone(0.0, 0.8, inclination=D_CONE, tip_radius=tip_radius)
        scene = jaxrb.Scene(body, (jaxrb.Gravity(),), floor=cone)
        traj = jaxrb.simulate(scene, state0, ts, rtol=1e-11, atol=1e-11, max_impacts=8, throw=False)
        return traj, jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states)

    return jax.vmap(one)(tip_radius, state0, ts)


def steady_circle(sigma, rho=0.3, d=D_CONE, r=R_CONE_BALL):
    """The initial state, rate Omega and height of the steady circle (module docstring)."""
    a, b, c = 1.4 * rho, 0.4 * r * sigma * np.tan(d), -G * np.tan(d)
    omega_c = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    e_rho, e_phi, e_z = np.eye(3)
    n = -np.sin(d) * e_rho + np.cos(d) * e_z
    w = -(rho * omega_c / r) * (np.cos(d) * e_rho + np.sin(d) * e_z) + sigma * n
    height = (r + rho * np.sin(d)) / np.cos(d)
    state0 = jaxrb.make_state(pos=rho * e_rho + height * e_z, vel=rho * omega_c * e_phi, omega=w)
    return state0, omega_c, height


@pytest.fixture(scope="module")
def cone_runs():
    """Three steady circles (sigma = 0, 30, -50 rad/s; two turns each) on a sharp cone, and a
    ball released from rest on the side of a cone with a rounded tip (radius 5 cm)."""
    circles = [steady_circle(sigma) for sigma in (0.0, 30.0, -50.0)]
    # the swing: at rest, centre 15 cm from the axis, on the cone's surface
    rho0 = 0.15
    z0 = (R_CONE_BALL + rho0 * np.sin(D_CONE)) / np.cos(D_CONE)
    states = [c[0] for c in circles] + [jaxrb.make_state(pos=(rho0, 0.0, z0))]
    state0 = jax.tree.map(lambda *x: jnp.stack(x), *states)
    ts = [np.linspace(0.0, 2.0, 41) * 2 * np.pi / c[1] for c in circles] + [
        np.linspace(0.0, 3.0, 41)
    ]
    traj, energy = _on_cone(jnp.array([0.0, 0.0, 0.0, 0.05]), state0, jnp.asarray(np.stack(ts)))
    return traj, energy, circles, np.stack(ts)


def test_ball_rolling_round_a_cone_keeps_the_steady_circle(cone_runs):
    traj, _, circles, ts = cone_runs
    assert np.all(np.asarray(traj.result._value)[:3] == jaxrb.RESULTS.successful._value)
    assert np.all(np.asarray(traj.contact.kind)[:3] == 1) and not np.any(traj.contact.sliding[:3])
    pos = np.asarray(traj.states.pos)[:3]
    omega_c = np.array([c[1] for c in circles])
    height = np.array([c[2] for c in circles])
    np.testing.assert_allclose(np.hypot(pos[..., 0], pos[..., 1]), 0.3, atol=1e-10)
    np.testing.assert_allclose(pos[..., 2] - height[:, None], 0.0, atol=1e-10)
    phase = np.unwrap(np.arctan2(pos[..., 1], pos[..., 0]), axis=1)
    np.testing.assert_allclose(phase - omega_c[:, None] * ts[:3], 0.0, atol=1e-9)
    # sigma = 0: the rolling-only circle, Omega^2 = 5 g tan d / (7 rho)
    np.testing.assert_allclose(omega_c[0] ** 2, 5 * G * np.tan(D_CONE) / (7 * 0.3), rtol=1e-12)


def test_ball_rolls_through_a_rounded_cone_tip_and_up_the_other_side(cone_runs):
    """Rolling without slipping keeps the energy: released from rest, the ball rolls down
    through the rounded bottom (where the contact passes from the cone to the tip's cap and
    back, its frame turning continuously) and up the other side to its starting height.

    Where the contact passes between cone and cap the surface's curvature jumps (from 0 to
    1 / tip_radius along the slope): each crossing is an event (cause "junction"), and each
    segment keeps to one part's geometry, so no step straddles the jump."""
    traj, energy, _, _ = cone_runs
    k = 3
    assert int(np.asarray(traj.result._value)[k]) == jaxrb.RESULTS.successful._value
    assert int(traj.impacts.count[k]) == 0 and int(traj.contact.inconsistent[k]) == 0
    assert np.all(np.asarray(traj.contact.kind[k]) == 1) and not np.any(traj.contact.sliding[k])
    pos = np.asarray(traj.states.pos[k])
    np.testing.assert_allclose(energy[k], energy[k][0], rtol=1e-10)
    causes = np.asarray(traj.contact.event_cause[k])[: int(traj.contact.events[k]) + 1]
    assert np.sum(causes == jaxrb.contact.CAUSES.index("junction")) >= 4  # 2 per pass
    gap = np.asarray(jax.vmap(jaxrb.Cone(0.0, inclination=D_CONE, tip_radius=0.05).gap)(pos))
    np.testing.assert_allclose(gap - R_CONE_BALL, 0.0, atol=1e-10)
    np.testing.assert_allclose(pos[:, 1], 0.0, atol=1e-12)  # it stays in its vertical plane
    assert pos[:, 0].min() < -0.149  # it reached the other side, 15 cm out (to the saves)


def test_curved_surfaces_meet_only_a_ball_and_check_their_dimensions():
    box = jaxrb.RigidBody(0.1, shape=jaxrb.Box((0.01, 0.01, 0.01)))
    scene = jaxrb.Scene(box, (jaxrb.Gravity(),), floor=jaxrb.Bowl(0.5, 0.3, radius=1.0))
    with pytest.raises(ValueError, match="Bowl meets only a Sphere"):
        jaxrb.simulate(scene, jaxrb.make_state(pos=(0, 0, 0.5)), jnp.linspace(0, 0.1, 3))
    with pytest.raises(ValueError, match="radius"):
        jaxrb.Bowl(0.5, 0.3, radius=0.0)
    with pytest.raises(ValueError, match="inclination"):
        jaxrb.Cone(0.5, 0.3, inclination=2.0)
    with pytest.raises(TypeError, match="floor must be"):
        jaxrb.Scene(box, (jaxrb.Gravity(),), floor="bowl")


BALL = '[body]\nmass = 0.05\n[body.shape]\ntype = "sphere"\nradius = 0.02\n'
END = "[simulation]\nt_end = 1.0\n"
B_BOX = '[body]\nmass = 0.05\n[body.shape]\ntype = "box"\nhalf_extents = [0.01, 0.01, 0.01]\n'


def test_scene_files_take_a_bowl_or_a_cone_for_a_ball():
    from jaxrb._scene_file import SceneFileError, loads_scene

    bowl = '[floor]\ntype = "bowl"\nradius = 0.5\nrestitution = 0.5\n'
    spec = loads_scene(BALL + "[initial]\npos = [0.1, 0, 0.2]\n" + bowl + END)
    assert isinstance(spec.scene.floor, jaxrb.Bowl) and float(spec.scene.floor.radius) == 0.5
    cone = '[floor]\ntype = "cone"\ninclination_deg = 30\nrestitution = 0.5\n'
    spec = loads_scene(BALL + "[initial]\npos = [0.3, 0, 0.3]\n" + cone + END)
    np.testing.assert_allclose(float(spec.scene.floor.inclination), np.pi / 6)
    cases = {
        # a box in a bowl
        B_BOX + "[initial]\npos = [0, 0, 0.2]\n" + bowl: r"\[floor\]: a bowl meets only a sphere",
        # outside the bowl's sphere: below its surface
        BALL + "[initial]\npos = [0.9, 0, 0.5]\n" + bowl: r"\[initial\].pos: .* beyond the bowl",
        BALL + cone.replace("30", "95"): r"inclination_deg: must be",
        BALL
        + bowl.replace("bowl", "plane"): r"\[floor\].radius: belongs to a floor of type 'bowl'",
    }
    for text, message in cases.items():
        with pytest.raises(SceneFileError, match=message):
            loads_scene(text + END)
