"""Restitution from bounces and drag from a flight: noise-free recovery and noisy coverage."""

import diffrax as dfx
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxrb
import jaxrb.fit as jf


def _coverage_ok(z):
    """z = (estimate - truth) / reported std over K independent noise draws.

    If the reported std is right, z ~ N(0, 1) (t with >= 5 dof here; close enough), so
    sum(z^2) ~ chi2(K): require it inside the two-sided 99.8 % interval, and the mean
    inside +- 3.09 / sqrt(K) (no bias). Seeds are fixed, so the test is deterministic; the
    bounds say a correct estimator would fail with probability < 0.4 % for a fresh seed.
    """
    z = np.asarray(z)
    k = z.size
    lo, hi = scipy.stats.chi2.ppf([0.001, 0.999], k)
    return lo < np.sum(z**2) < hi and abs(np.mean(z)) < 3.09 / np.sqrt(k), (
        np.sum(z**2) / k,
        np.mean(z),
    )


E_TRUE, H0_TRUE = 0.7, 1.2


def test_restitution_from_three_bounces():
    times = np.asarray(jaxrb.analytic.ball_impact_times(H0_TRUE, E_TRUE, 3))
    res = jf.fit_restitution(impact_times=times, restitution0=0.5)
    assert res.converged
    assert abs(res.values["restitution"] / E_TRUE - 1) <= 1e-6
    assert abs(res.values["h0"] / H0_TRUE - 1) <= 1e-6
    heights = np.asarray(jaxrb.analytic.ball_apex_heights(H0_TRUE, E_TRUE, 3))
    res = jf.fit_restitution(apex_heights=heights, restitution0=0.5)
    assert abs(res.values["restitution"] / E_TRUE - 1) <= 1e-6


def test_restitution_coverage():
    rng = np.random.default_rng(1)
    times = np.asarray(jaxrb.analytic.ball_impact_times(H0_TRUE, E_TRUE, 6))
    z = []
    for _ in range(40):
        res = jf.fit_restitution(
            impact_times=times + 2e-3 * rng.standard_normal(6), restitution0=0.5
        )
        z.append((res.values["restitution"] - E_TRUE) / res.std["restitution"])
    ok, stats = _coverage_ok(z)
    assert ok, stats


SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
K_TRUE, MASS = 0.05, 0.2
TS = np.linspace(0.0, 1.0, 11)


@pytest.fixture(scope="module")
def flight():
    scene = jaxrb.Scene(
        jaxrb.RigidBody(MASS, jnp.ones(3)), forces=(jaxrb.Gravity(), jaxrb.QuadraticDrag(K_TRUE))
    )
    state0 = jaxrb.make_state(pos=jnp.array([0.0, 0.0, 1.0]), vel=jnp.array([8.0, 1.0, 6.0]))
    return np.asarray(jaxrb.simulate(scene, state0, jnp.asarray(TS), **SIM).states.pos)


def test_drag_noise_free_and_coverage(flight):
    res = jf.fit_drag(TS, flight, mass=MASS, drag0=0.7 * K_TRUE, **SIM)
    assert res.converged
    assert abs(res.values["drag"] / K_TRUE - 1) <= 1e-6
    np.testing.assert_allclose(res.values["vel0"], [8.0, 1.0, 6.0], atol=1e-8)
    rng = np.random.default_rng(2)
    z = []
    for _ in range(20):
        noisy = jf.fit_drag(
            TS,
            flight + 1e-3 * rng.standard_normal(flight.shape),
            mass=MASS,
            drag0=0.7 * K_TRUE,
            **SIM,
        )
        z.append((noisy.values["drag"] - K_TRUE) / noisy.std["drag"])
    ok, stats = _coverage_ok(z)
    assert ok, stats


def test_bad_input(flight):
    with pytest.raises(ValueError, match="pos has 10 samples but ts has 11"):
        jf.fit_drag(TS, flight[:-1], mass=MASS, drag0=0.1)
    bad = flight.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="pos contains NaN"):
        jf.fit_drag(TS, bad, mass=MASS, drag0=0.1)
    with pytest.raises(ValueError, match="too few samples"):
        jf.fit_drag(TS[:2], flight[:2], mass=MASS, drag0=0.1)
    with pytest.raises(ValueError, match="drag0"):
        jf.fit_drag(TS, flight, mass=MASS, drag0=-1.0)
    with pytest.raises(ValueError, match="model"):
        jf.fit_drag(TS, flight, mass=MASS, drag0=0.1, model="cubic")
    with pytest.raises(ValueError, match="too few samples"):
        jf.fit_restitution(impact_times=[0.5, 1.0])
    with pytest.raises(ValueError, match="impact_times contains NaN"):
        jf.fit_restitution(impact_times=[0.5, np.nan, 1.2])
    with pytest.raises(ValueError, match="strictly increasing"):
        jf.fit_restitution(impact_times=[0.5, 0.4, 1.2])
    with pytest.raises(ValueError, match="needs"):
        jf.fit_restitution()


# ------------------------------------------------------------ through the impact simulation

E_BALL, MU_BALL, R_BALL = 0.6, 0.1, 0.05


def _spinning_ball_scene(e, mu):
    body = jaxrb.RigidBody(0.2, shape=jaxrb.Sphere(R_BALL))
    return jaxrb.Scene(
        body, forces=(jaxrb.Gravity(), jaxrb.QuadraticDrag(1e-3)), floor=jaxrb.Floor(e, mu)
    )


BALL_STATE0 = jaxrb.make_state(pos=(0.0, 0.0, 0.5), vel=(1.5, 0.3, 0.0), omega=(5.0, -40.0, 0.0))
BALL_TS = np.linspace(0.0, 0.8, 25)  # two bounces, before the ball starts to roll


@pytest.fixture(scope="module")
def tracked_ball():
    traj = jaxrb.simulate(
        _spinning_ball_scene(E_BALL, MU_BALL),
        BALL_STATE0,
        jnp.asarray(BALL_TS),
        rtol=1e-12,
        atol=1e-12,
    )
    assert int(traj.impacts.count) >= 2  # the data contain bounces
    return np.asarray(traj.states.pos), np.asarray(traj.states.omega)


def test_contact_fit_from_tracked_trajectory(tracked_ball):
    """Restitution and friction of a spinning ball's bounces, from positions and gyro data,
    through the simulation with impacts, from starts 30 % off. The backspin makes the first
    contact slide (it would stick for mu > 0.21), so friction shapes the data."""
    pos, omega = tracked_ball
    res = jf.fit_contact(
        _spinning_ball_scene(0.5, 0.5),
        BALL_STATE0,
        BALL_TS,
        pos,
        omega=omega,
        omega_weight=0.01,
        restitution0=0.42,
        friction0=0.13,
    )
    assert res.converged, res.message
    assert abs(res.values["restitution"] / E_BALL - 1) <= 1e-6
    assert abs(res.values["friction"] / MU_BALL - 1) <= 1e-6
    assert np.all(np.isfinite(res.std["restitution"])) and not res.warnings


def test_contact_fit_bad_input(tracked_ball):
    pos, _ = tracked_ball
    scene = _spinning_ball_scene(0.5, 0.5)
    with pytest.raises(ValueError, match="pos"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, pos[:-1])
    with pytest.raises(ValueError, match="pos"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, np.where(pos > 0.4, np.nan, pos))
    with pytest.raises(ValueError, match="restitution0"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, pos, restitution0=1.2)
    with pytest.raises(ValueError, match="Floor"):
        no_floor = jaxrb.Scene(jaxrb.RigidBody(0.2, shape=jaxrb.Sphere(R_BALL)))
        jf.fit_contact(no_floor, BALL_STATE0, BALL_TS, pos)
