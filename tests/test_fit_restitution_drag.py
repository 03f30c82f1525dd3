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


_FLOAT32_FIT = """
import warnings
import jax, numpy as np
import jaxrb, jaxrb.fit as jf
from jaxrb.fit._least_squares import check_tolerances
assert jax.numpy.result_type(float) == jax.numpy.float32  # JAX's default: no x64
np.testing.assert_allclose(check_tolerances(None, None, default=1e-11), [1e-6, 1e-6], rtol=1e-7)
np.testing.assert_allclose(check_tolerances(1e-5, None, default=1e-11), [1e-5, 1e-6], rtol=1e-7)
k, mass = 0.05, 0.2
ts = np.linspace(0.0, 1.0, 11)
scene = jaxrb.Scene(jaxrb.RigidBody(mass, shape=jaxrb.Sphere(0.05)),
                    forces=(jaxrb.Gravity(), jaxrb.QuadraticDrag(k)))
flight = jaxrb.simulate(scene, jaxrb.make_state(vel=(8.0, 1.0, 6.0)), ts, rtol=1e-6, atol=1e-6)
with warnings.catch_warnings():
    warnings.simplefilter("error")  # no ConvergenceWarning
    res = jf.fit_drag(ts, np.asarray(flight.states.pos), mass=mass, drag0=0.7 * k)
assert res.converged, res.message
assert abs(res.values["drag"] / k - 1) < 1e-5, res.values["drag"]
# an inertia fit (9 parameters) stalled between 1e-6 and 1e-5 of |z| before: rtol's floor
J = np.array([[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]])
J0 = J * np.array([[1.3, 0.7, 1.3], [0.7, 1.3, 0.7], [1.3, 0.7, 0.7]])
ts = np.linspace(0.0, 2.0, 21)
spin = jaxrb.simulate(jaxrb.Scene(jaxrb.RigidBody(1.0, J)),
                      jaxrb.make_state(omega=(1.0, 0.5, 0.8)), ts, rtol=1e-7, atol=1e-7)
with warnings.catch_warnings():
    warnings.simplefilter("error")
    res = jf.fit_inertia(ts, inertia0=J0, omega=np.asarray(spin.states.omega))
assert res.converged, res.message
fitted = res.values["inertia"]
scaled = J * np.trace(fitted) / np.trace(J)  # torque-free: the tensor up to scale
assert np.max(np.abs(fitted - scaled)) / np.max(np.abs(scaled)) < 1e-5
print("ok")
"""


def test_fits_in_float32_with_the_defaults():
    """In float32 (JAX's default) the drag and inertia fits' defaults are met: the
    simulation's tolerances default to 1e-6 and the least-squares rtol is raised to 100
    machine epsilons (at 1e-10 both fits found their values to 2e-6 but reported no
    convergence). A separate process: the suite runs in float64."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run(
        [sys.executable, "-c", _FLOAT32_FIT], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")
