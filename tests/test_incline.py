"""A tilted floor: balls and blocks on an incline against the closed forms (float64).

The plane through the origin with normal n = (sin theta, 0, cos theta) rises towards -x;
down the slope is d = (cos theta, 0, -sin theta), and gravity's component along it is
g sin theta. Starting at rest on the plane:

- a block sticks when tan theta <= mu, and otherwise slides with a = g (sin theta - mu cos
  theta);
- a uniform ball rolls when tan theta <= 7 mu / 2, with a = 5 g sin theta / 7 and w = v / R,
  and otherwise slides with a = g (sin theta - mu cos theta) while friction spins it up at
  dw/dt = 5 mu g cos theta / (2 R);
- a ball dropped from rest at a distance h0 above a frictionless incline bounces with
  restitution e: the first impact at t1 = sqrt(2 h0 / (g cos theta)), the k-th after it
  2 e^k v1 / (g cos theta) later, v1 = g cos theta t1.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb

G, R, A = 9.81, 0.02, 0.01  # gravity, ball radius, block half-edge
TS = jnp.linspace(0.0, 0.5, 26)


def incline(theta, restitution, mu):
    normal = jnp.stack([jnp.sin(theta), 0.0, jnp.cos(theta)])
    return jaxrb.Floor(restitution, mu, normal=normal)


@persistent
def _balls(theta, restitution, mu, lift):
    def one(theta, e, mu, lift):
        floor = incline(theta, e, mu)
        body = jaxrb.RigidBody(0.05, shape=jaxrb.Sphere(R))
        scene = jaxrb.Scene(body, (jaxrb.Gravity(),), floor=floor)
        state0 = jaxrb.make_state(pos=(R + lift) * floor.normal)
        return jaxrb.simulate(
            scene, state0, TS, rtol=1e-11, atol=1e-11, max_impacts=16, throw=False
        )

    return jax.vmap(one)(theta, restitution, mu, lift)


@persistent
def _blocks(theta, mu):
    def one(theta, mu):
        floor = incline(theta, 0.3, mu)
        body = jaxrb.RigidBody(0.05, shape=jaxrb.Box(jnp.full(3, A)))
        scene = jaxrb.Scene(body, (jaxrb.Gravity(),), floor=floor)
        quat = jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, 0.0]), theta)  # face on the plane
        state0 = jaxrb.make_state(pos=A * floor.normal, quat=quat)
        return jaxrb.simulate(
            scene, state0, TS, rtol=1e-11, atol=1e-11, max_impacts=16, throw=False
        )

    return jax.vmap(one)(theta, mu)


def downslope(theta):
    return np.array([np.cos(theta), 0.0, -np.sin(theta)])


def test_ball_rolls_or_slides_down_the_incline_as_the_closed_forms_say():
    theta = np.radians([20.0, 30.0])
    mu = np.array([0.5, 0.1])  # tan 20 deg < 7/2 0.5 (rolls); tan 30 deg > 7/2 0.1 (slides)
    traj = _balls(jnp.asarray(theta), jnp.zeros(2), jnp.asarray(mu), jnp.zeros(2))
    assert np.all(np.asarray(traj.result._value) == jaxrb.RESULTS.successful._value)
    t = np.asarray(TS)
    assert np.all(np.asarray(traj.impacts.count) == 0)
    for k, rolls in enumerate((True, False)):
        n = np.array([np.sin(theta[k]), 0.0, np.cos(theta[k])])
        d = downslope(theta[k])
        if rolls:
            acc, spin = 5 * G * np.sin(theta[k]) / 7, 5 * G * np.sin(theta[k]) / (7 * R)
        else:
            acc = G * (np.sin(theta[k]) - mu[k] * np.cos(theta[k]))
            spin = 5 * mu[k] * G * np.cos(theta[k]) / (2 * R)
        pos = np.asarray(traj.states.pos[k])
        np.testing.assert_allclose(pos, R * n + 0.5 * acc * t[:, None] ** 2 * d, atol=1e-9)
        # the ball turns about the axis n x d (world), at spin * t
        w_world = np.einsum(
            "tij,tj->ti",
            np.asarray(jax.vmap(jaxrb.quat_to_matrix)(traj.states.quat[k])),
            np.asarray(traj.states.omega[k]),
        )
        np.testing.assert_allclose(w_world, spin * t[:, None] * np.cross(n, d), atol=1e-8)
        sliding = np.asarray(traj.contact.sliding[k])
        assert not np.any(sliding) if rolls else np.all(sliding[1:])


def test_ball_bounces_on_a_frictionless_incline_at_the_closed_form_times():
    theta, e, lift = np.radians(25.0), 0.8, 0.02
    traj = _balls(
        jnp.asarray([theta, 0.0]), jnp.asarray([e, e]), jnp.zeros(2), jnp.asarray([lift, lift])
    )
    assert np.all(np.asarray(traj.result._value) == jaxrb.RESULTS.successful._value)
    for k, g_normal in enumerate((G * np.cos(theta), G)):  # the incline; the level floor
        t1 = np.sqrt(2 * lift / g_normal)
        v1 = g_normal * t1
        times = t1 + np.concatenate([[0.0], np.cumsum(2 * v1 * e ** np.arange(1, 12) / g_normal)])
        times = times[times < float(TS[-1])]
        assert len(times) >= 5 and int(traj.impacts.count[k]) == len(times)
        np.testing.assert_allclose(np.asarray(traj.impacts.time[k, : len(times)]), times, atol=1e-9)
    # on the incline the ball also runs down the slope, with g sin theta, unhindered
    t = np.asarray(TS)
    along = np.asarray(traj.states.pos[0]) @ downslope(theta)
    np.testing.assert_allclose(along, 0.5 * G * np.sin(theta) * t**2, atol=1e-9)


@pytest.mark.parametrize("steep", [False, True])
def test_block_sticks_or_slides_on_the_incline(steep):
    theta = np.radians([10.0, 30.0])
    mu = np.array([0.5, 0.3])  # tan 10 deg < 0.5 (sticks); tan 30 deg > 0.3 (slides)
    traj = _blocks(jnp.asarray(theta), jnp.asarray(mu))
    assert np.all(np.asarray(traj.result._value) == jaxrb.RESULTS.successful._value)
    k = int(steep)
    t = np.asarray(TS)
    n = np.array([np.sin(theta[k]), 0.0, np.cos(theta[k])])
    acc = G * (np.sin(theta[k]) - mu[k] * np.cos(theta[k])) if steep else 0.0
    pos = np.asarray(traj.states.pos[k])
    np.testing.assert_allclose(
        pos, A * n + 0.5 * acc * t[:, None] ** 2 * downslope(theta[k]), atol=1e-9
    )
    assert int(traj.impacts.count[k]) == 0
    assert np.all(np.asarray(traj.contact.kind[k]) == jaxrb.contact.KIND_NAMES.index("face"))
    np.testing.assert_allclose(np.asarray(traj.states.omega[k]), 0.0, atol=1e-9)
    assert np.all(np.asarray(traj.contact.sliding[k])[1:] == steep)


def test_floor_normal_is_checked_and_a_scene_file_takes_it():
    from jaxrb._scene_file import SceneFileError, loads_scene

    with pytest.raises(ValueError, match="Floor.normal must be a finite non-zero direction"):
        jaxrb.Floor(0.5, normal=(0.0, 0.0, 0.0))
    floor = jaxrb.Floor(0.5, normal=(0.0, 3.0, 4.0))
    np.testing.assert_allclose(np.asarray(floor.normal), [0.0, 0.6, 0.8], rtol=1e-15)
    n, t1, t2 = floor.frame()
    np.testing.assert_allclose(np.asarray(jnp.stack([n @ t1, n @ t2, t1 @ t2])), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(jnp.cross(t1, t2)), np.asarray(n), atol=1e-15)
    head = (
        "[simulation]\nt_end = 1.0\n"
        + '[body]\nmass = 1.0\n[body.shape]\ntype = "sphere"\nradius = 0.1\n[initial]\n'
    )
    spec = loads_scene(
        head + "pos = [0, 0, 0.5]\n[floor]\nrestitution = 0.5\nnormal = [0.1, 0, 1]\n"
    )
    np.testing.assert_allclose(np.asarray(spec.scene.floor.normal[0]), 0.1 / np.sqrt(1.01))
    with pytest.raises(SceneFileError, match=r"\[floor\].normal: must be a non-zero direction"):
        loads_scene(head + "pos = [0, 0, 0.5]\n[floor]\nrestitution = 0.5\nnormal = [0, 0, 0]\n")
    with pytest.raises(SceneFileError, match="tilted plane"):
        # a ball centred at (-1, 0, 0.5) is 0.35 m under the plane x + z = 0
        loads_scene(head + "pos = [-1, 0, 0.5]\n[floor]\nrestitution = 0.5\nnormal = [1, 0, 1]\n")
