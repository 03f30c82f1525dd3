"""Pivot (heavy top) and Hinge (fixed-axis pendulum) against exact oracles (float64)."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb import analytic

TIGHT = dict(solver=dfx.Dopri8(), rtol=1e-13, atol=1e-13)
P = analytic.SAMPLE_PENDULUM  # m = 7.5 kg, r = 0.25 m, k_O = 0.295 m


def pendulum_scene(joint_cls):
    """The classical sample pendulum: mass centre at (r, 0, 0), pivot O at the world origin.

    The body starts horizontal; turning about body y by theta lowers the mass centre, so
    theta is measured downward as in the sample problem.
    """
    J_c = P.mass * (P.k_O**2 - P.r**2)  # about the mass centre, so that J_O = m k_O^2
    body = jaxrb.RigidBody(P.mass, jnp.array([J_c, J_c, J_c]))
    point = jnp.array([-P.r, 0.0, 0.0])
    joint = (
        jaxrb.Hinge(point, axis=(0.0, 1.0, 0.0)) if joint_cls is jaxrb.Hinge else jaxrb.Pivot(point)
    )
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=joint)


@pytest.fixture(scope="module")
def swing():
    scene = pendulum_scene(jaxrb.Hinge)
    state0 = jaxrb.make_state(pos=(P.r, 0.0, 0.0))
    ts = jnp.linspace(0.0, 0.69, 200)  # the half swing to theta = pi takes about 0.6985 s
    return scene, ts, jaxrb.simulate(scene, state0, ts, **TIGHT)


def test_pendulum_bearing_force_matches_formula(swing):
    scene, ts, traj = swing
    states = traj.states
    theta = jnp.arctan2(-states.pos[:, 2], states.pos[:, 0])
    assert float(theta[0]) == 0.0 and float(jnp.rad2deg(theta[-1])) > 175.0
    force = jax.vmap(lambda t, s: jaxrb.joint_reaction(scene, t, s))(ts, states)
    towards_O = -states.pos / P.r
    increasing_theta = jnp.stack([-jnp.sin(theta), jnp.zeros_like(theta), -jnp.cos(theta)], -1)
    On = jnp.sum(force * towards_O, -1)
    Ot = -jnp.sum(force * increasing_theta, -1)  # the formula's Ot points against theta
    On_exact, Ot_exact, mag_exact = analytic.pendulum_bearing_force(theta, P.mass, P.r, P.k_O)
    mg = P.mass * 9.81
    np.testing.assert_allclose(On, On_exact, rtol=1e-6, atol=1e-6 * mg)
    np.testing.assert_allclose(Ot, Ot_exact, rtol=1e-6, atol=1e-6 * mg)
    np.testing.assert_allclose(jnp.linalg.norm(force, axis=-1), mag_exact, rtol=1e-6)
    # the force has no component along the hinge axis in this planar problem
    assert jnp.max(jnp.abs(force[:, 1])) <= 1e-9 * mg


def test_pendulum_motion_matches_energy_and_exact_rate(swing):
    scene, ts, traj = swing
    theta = jnp.arctan2(-traj.states.pos[:, 2], traj.states.pos[:, 0])
    w2 = jnp.sum(traj.states.omega**2, -1)
    np.testing.assert_allclose(
        w2, analytic.pendulum_angular_velocity_squared(theta, P.r, P.k_O), rtol=1e-9, atol=1e-9
    )
    E = jaxrb.energy(scene, traj.states)
    assert jnp.max(jnp.abs(E - E[0])) <= 1e-10 * P.mass * 9.81 * P.r


def test_hinge_and_pivot_agree():
    """A free-turning pivot held in the plane by symmetry moves like the hinge."""
    state0 = jaxrb.make_state(pos=(P.r, 0.0, 0.0), omega=(0.0, 0.5, 0.0))
    ts = jnp.linspace(0.0, 2.0, 41)
    hinge = jaxrb.simulate(pendulum_scene(jaxrb.Hinge), state0, ts, **TIGHT)
    pivot = jaxrb.simulate(pendulum_scene(jaxrb.Pivot), state0, ts, **TIGHT)
    for a, b in zip(jax.tree.leaves(hinge.states), jax.tree.leaves(pivot.states), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-10)


def test_heavy_symmetric_top_invariants():
    """Energy, vertical angular momentum about O and the spin component J3 w3 are conserved."""
    J1, J3, m, arm = 0.02, 0.03, 1.5, 0.1
    body = jaxrb.RigidBody(m, jnp.array([J1, J1, J3]))
    scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=jaxrb.Pivot((0.0, 0.0, -arm)))
    q0 = jaxrb.axis_angle_to_quat(jnp.array([1.0, 0.0, 0.0]), 0.4)
    anchor = jnp.zeros(3)
    state0 = jaxrb.make_state(
        pos=jaxrb.quat_rotate(q0, jnp.array([0.0, 0.0, arm])), quat=q0, omega=(0.5, 0.0, 40.0)
    )
    ts = jnp.linspace(0.0, 5.0, 101)
    traj = jaxrb.simulate(scene, state0, ts, **TIGHT)
    s = traj.states
    # the pivot stays put
    np.testing.assert_allclose(
        s.pos - jaxrb.quat_rotate(s.quat, jnp.array([0.0, 0.0, arm])), 0.0, atol=1e-12
    )
    E = jaxrb.energy(scene, s)
    L = jaxrb.angular_momentum(scene, s, point=anchor)
    spin = J3 * s.omega[:, 2]
    assert jnp.max(jnp.abs(E / E[0] - 1)) <= 1e-10
    assert jnp.max(jnp.abs(L[:, 2] - L[0, 2])) <= 1e-10 * jnp.linalg.norm(L[0])
    assert jnp.max(jnp.abs(spin - spin[0])) <= 1e-10 * abs(spin[0])
    # and the top really precesses and nutates (the test is not vacuous)
    assert jnp.ptp(s.pos[:, 0]) > 1e-3


def test_joint_reaction_of_resting_pendulum_carries_weight():
    scene = pendulum_scene(jaxrb.Pivot)
    # hanging straight down from O at rest: mass centre at (0, 0, -r)
    q = jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, 0.0]), jnp.pi / 2)
    state = jaxrb.make_state(pos=(0.0, 0.0, -P.r), quat=q)
    force = jaxrb.joint_reaction(scene, 0.0, state)
    np.testing.assert_allclose(force, jnp.array([0.0, 0.0, P.mass * 9.81]), atol=1e-12)


def test_joint_reaction_without_joint_is_an_error():
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.ones(3)))
    with pytest.raises(ValueError, match="joint"):
        jaxrb.joint_reaction(scene, 0.0, jaxrb.make_state())
