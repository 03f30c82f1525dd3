"""Rolling and spin resistance of a ball against the closed forms (float64).

A uniform ball (I = 2 m r^2 / 5) rolling on a plane tilted by theta, down the slope d, with
rolling resistance mu_r (a couple mu_r r N against its rolling, N = m g cos theta) obeys
m a = m g sin theta - F and I a / r = F r - mu_r r N, so

    a = (5/7) g (sin theta - mu_r cos theta);

its spin about the normal, resisted by mu_s r N, falls at (5/2) mu_s g cos theta / r. On a
level floor a ball rolling at v0 stops after 7 v0 / (5 mu_r g), having gone
7 v0^2 / (10 mu_r g).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb

G, R, M = 9.81, 0.02, 0.05
TS = jnp.linspace(0.0, 0.5, 26)


def ball_scene(theta, mu_r, mu_s):
    normal = jnp.stack([jnp.sin(theta), 0.0, jnp.cos(theta)])
    floor = jaxrb.Floor(0.0, 0.5, normal=normal, rolling_resistance=mu_r, spin_resistance=mu_s)
    return jaxrb.Scene(jaxrb.RigidBody(M, shape=jaxrb.Sphere(R)), (jaxrb.Gravity(),), floor=floor)


@persistent
def _rolling(theta, mu_r, mu_s, v0, spin):
    def one(theta, mu_r, mu_s, v0, spin):
        scene = ball_scene(theta, mu_r, mu_s)
        n = scene.floor.normal
        d = jnp.stack([jnp.cos(theta), 0.0, -jnp.sin(theta)])  # down the slope
        state0 = jaxrb.make_state(pos=R * n, vel=v0 * d, omega=v0 / R * jnp.cross(n, d) + spin * n)
        return jaxrb.simulate(scene, state0, TS, rtol=1e-11, atol=1e-11, throw=False)

    return jax.vmap(one)(theta, mu_r, mu_s, v0, spin)


# (theta, mu_r, mu_s, v0, spin about the normal)
CASES = np.array(
    [
        [0.0, 0.05, 0.01, 1.0, 40.0],  # level: slows while rolling, its spin runs down
        [0.3, 0.02, 0.0, 0.2, 0.0],  # an incline: rolls down, slowed
        [0.0, 0.1, 0.02, 0.2, 2.0],  # level: comes to rest at 0.29 s, its spin at 0.16 s
        [0.0, -0.1, 0.0, 0.2, 0.0],  # invalid: a negative coefficient
    ]
)


@pytest.fixture(scope="module")
def runs():
    return _rolling(*(jnp.asarray(CASES[:, k]) for k in range(5)))


def member(runs, k):
    return jax.tree.map(lambda x: np.asarray(x[k]), runs)


def world_omega(traj):
    rot = np.asarray(jax.vmap(jaxrb.quat_to_matrix)(jnp.asarray(traj.states.quat)))
    return np.einsum("tij,tj->ti", rot, traj.states.omega)


@pytest.mark.parametrize("k", [0, 1])
def test_rolling_ball_slows_and_its_spin_runs_down_as_the_closed_forms_say(runs, k):
    theta, mu_r, mu_s, v0, spin = CASES[k]
    traj, t = member(runs, k), np.asarray(TS)
    assert traj.result == jaxrb.RESULTS.successful and traj.contact.events == 0
    n = np.array([np.sin(theta), 0.0, np.cos(theta)])
    d = np.array([np.cos(theta), 0.0, -np.sin(theta)])
    a = 5 / 7 * G * (np.sin(theta) - mu_r * np.cos(theta))
    np.testing.assert_allclose((traj.states.pos - R * n) @ d, v0 * t + a * t**2 / 2, atol=1e-10)
    np.testing.assert_allclose(traj.states.vel @ d, v0 + a * t, atol=1e-10)
    spin_rate = 5 / 2 * mu_s * G * np.cos(theta) / R
    np.testing.assert_allclose(world_omega(traj) @ n, spin - spin_rate * t, atol=1e-9)


def test_ball_comes_to_rest_where_the_closed_form_says_and_stays(runs):
    _, mu_r, mu_s, v0, spin = CASES[2]
    traj, t = member(runs, 2), np.asarray(TS)
    assert traj.result == jaxrb.RESULTS.successful
    t_stop, s_stop = 7 * v0 / (5 * mu_r * G), 7 * v0**2 / (10 * mu_r * G)
    rolling = t < t_stop - 1e-3
    a = 5 / 7 * mu_r * G
    np.testing.assert_allclose(
        traj.states.pos[rolling, 0], v0 * t[rolling] - a * t[rolling] ** 2 / 2, atol=1e-10
    )
    # below the blend speed (1e-6 m/s) the couple fades: the ball stops within a blend
    # speed's worth of the closed form, and stays
    at_rest = t > t_stop + 0.01
    np.testing.assert_allclose(traj.states.pos[at_rest, 0], s_stop, atol=1e-8)
    assert np.max(np.abs(traj.states.vel[at_rest])) < 1e-6
    spin_stop = spin * R / (5 / 2 * mu_s * G)
    assert np.max(np.abs(world_omega(traj)[t > spin_stop + 0.01, 2])) * R < 1e-6
    scene = ball_scene(0.0, mu_r, mu_s)
    energy = np.asarray(jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states))
    assert np.all(np.diff(energy) <= 1e-12)


def test_negative_resistance_is_flagged_and_other_shapes_refuse_it(runs):
    assert np.asarray(runs.result._value)[3] == jaxrb.RESULTS.invalid_resistance._value
    with pytest.raises(ValueError, match="rolling_resistance"):
        jaxrb.Floor(0.5, 0.3, rolling_resistance=-1.0)
    box = jaxrb.RigidBody(0.1, shape=jaxrb.Box((0.01, 0.01, 0.01)))
    floor = jaxrb.Floor(0.5, 0.3, rolling_resistance=0.1)
    scene = jaxrb.Scene(box, (jaxrb.Gravity(),), floor=floor)
    with pytest.raises(ValueError, match="act on a ball"):
        jaxrb.simulate(scene, jaxrb.make_state(pos=(0, 0, 0.1)), jnp.linspace(0, 0.1, 3))
