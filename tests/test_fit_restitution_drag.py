"""Restitution from bounces and drag from a flight: noise-free recovery and noisy coverage.

Restitution and friction through the impact simulation: `test_fit_contact.py`.
"""

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
