"""The tippe top: a ball of radius R whose mass centre G lies a = alpha R below its centre C
(a `Sphere` with offset a e3; inertia diag(I1, I1, I3) about G), spun about the vertical on a
floor with Coulomb friction.

Oracles, derived without jaxrb:

- Jellett's integral L . r (L the angular momentum about G, r from G to the contact point,
  r = a e3 - R z) is conserved while the top slides and while it rolls: dL/dt = r x F
  (gravity acts at G) is normal to r, and L . dr/dt = L . (w x a e3) = 0 for a symmetric
  body, since L lies in the plane of w and e3.
- The upright spinning top is destabilised by sliding friction exactly when
  1 - alpha < I1 / I3 < 1 + alpha (Bou-Rabee, Marsden & Romero 2004, SIAM J. Appl. Dyn.
  Syst. 3, 352): with enough spin it turns over, raising G, and for I1 / I3 well below
  1 - alpha it keeps spinning upright.

Under Coulomb friction the slip can stop: the top spun fast enough to slide turns over until
the slip vanishes and then rolls on, tilted (here past 140 degrees); the continuous friction
laws of the cited analyses never stick and carry it on to 180 degrees.
"""

import jax
import jax.numpy as jnp
import numpy as np
from programs import persistent

import jaxrb

R, ALPHA, M = 0.02, 0.3, 0.015
A = ALPHA * R
I3 = 0.4 * M * R**2
SPIN, TILT, MU = 150.0, 0.1, 0.2  # rad/s about the vertical, rad, friction coefficient
RATIOS = (1.1, 0.5)  # I1 / I3: inside (1 - alpha, 1 + alpha), and well below it
TS = jnp.linspace(0.0, 2.0, 201)


def tippe_top(ratio):
    inertia = jnp.stack([ratio * I3, ratio * I3, jnp.asarray(I3)])
    body = jaxrb.RigidBody(M, inertia, shape=jaxrb.Sphere(R, offset=(0.0, 0.0, A)))
    return jaxrb.Scene(body, (jaxrb.Gravity(),), floor=jaxrb.Floor(0.0, MU))


def spun_upright():
    """Tilted by TILT about x, the ball touching the floor, spinning at SPIN about the
    vertical with its centre C at rest (so the contact point starts without slip)."""
    q = jaxrb.axis_angle_to_quat(jnp.array([1.0, 0.0, 0.0]), TILT)
    centre_offset = jaxrb.quat_rotate(q, jnp.array([0.0, 0.0, A]))  # G to C, world
    w = jnp.array([0.0, 0.0, SPIN])
    return jaxrb.make_state(
        pos=jnp.array([0.0, 0.0, R]) - centre_offset,
        quat=q,
        vel=-jnp.cross(w, centre_offset),
        omega=jaxrb.quat_rotate(jaxrb.quat_conjugate(q), w),
    )


@persistent
def _spin(ratios):
    def one(ratio):
        return jaxrb.simulate(
            tippe_top(ratio), spun_upright(), TS, rtol=1e-10, atol=1e-10, max_impacts=8, throw=False
        )

    return jax.vmap(one)(ratios)


def test_tippe_top_turns_over_inside_the_range_and_conserves_jelletts_integral():
    traj = _spin(jnp.asarray(RATIOS))
    assert np.all(np.asarray(traj.result._value) == jaxrb.RESULTS.successful._value)
    assert np.all(np.asarray(traj.impacts.count) == 0)
    Rm = np.asarray(jax.vmap(jaxrb.quat_to_matrix)(traj.states.quat))  # (2, T, 3, 3)
    tilt = np.degrees(np.arccos(np.clip(Rm[..., 2, 2], -1.0, 1.0)))
    sliding = np.asarray(traj.contact.sliding)
    z = np.asarray(traj.states.pos[..., 2])
    for k, ratio in enumerate(RATIOS):
        scene = tippe_top(ratio)
        inertia = np.asarray(scene.body.inertia_matrix)
        # Jellett's integral, sliding and rolling alike
        L = np.einsum("tij,jk,tk->ti", Rm[k], inertia, np.asarray(traj.states.omega[k]))
        r = Rm[k, :, :, 2] * A - np.array([0.0, 0.0, R])
        jellett = np.sum(L * r, axis=1)
        np.testing.assert_allclose(jellett, jellett[0], rtol=1e-8)
        state_k = jax.tree.map(lambda x, k=k: x[k], traj.states)
        gaps = jax.vmap(scene.body.shape.floor_distance)(state_k.pos, state_k.quat)
        assert float(jnp.max(jnp.abs(gaps))) < 1e-9  # the ball stays on the floor
        energy = np.asarray(jaxrb.energy(scene, state_k))
        assert np.all(np.diff(energy) < 1e-10 * energy[0])  # friction only takes energy
    # inside the range: it slides, turns over and raises its mass centre
    assert sliding[0].sum() >= 50
    assert tilt[0, -1] > 140.0
    assert z[0, -1] - z[0, 0] > 1.5 * A
    # well below it: it stays upright (its tilt falls), and its mass centre never rises
    assert np.max(tilt[1]) < 10.0 and tilt[1, -1] < tilt[1, 0]
    assert np.max(z[1]) < z[1, 0] + 1e-9
