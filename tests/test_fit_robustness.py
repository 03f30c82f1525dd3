"""Fitting survives its own trial steps: a trial point where the model cannot be evaluated
(an invalid inertia, a failed simulation, non-finite residuals or Jacobian) is rejected and a
shorter step tried, never an abort; a fit reports honestly whether it converged.

The inertia starts share one compiled solver: the data and the starts differ only in values.
"""

import warnings

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import traces

import jaxrb
import jaxrb.fit as jf
import jaxrb.fit._inertia_id as inertia_id
from jaxrb.fit._least_squares import _solve

# Fixed-step Tsit5 for the data and the model (as in test_fit_inertia.py): the recovery then
# tests the optimiser, not the integrator's truncation error, and it compiles quickly.
SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
J_TRUE = np.array([[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]])
TS = np.linspace(0.0, 2.0, 21)
OMEGA0 = np.array([1.0, 0.5, 0.8])


@pytest.fixture(scope="module")
def omega_data():
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.asarray(J_TRUE)))
    state0 = jaxrb.make_state(omega=jnp.asarray(OMEGA0))
    return np.asarray(jaxrb.simulate(scene, state0, jnp.asarray(TS), **SIM).states.omega)


def _diagonal_starts(count, seed=0):
    """Diagonal tensors with each principal moment of J_TRUE's diagonal off by up to +-30 %
    (uniform), drawn until `count` are valid (the triangle inequality can fail)."""
    rng = np.random.default_rng(seed)
    starts = []
    while len(starts) < count:
        guess = np.diag(np.diag(J_TRUE) * (1 + 0.3 * rng.uniform(-1, 1, 3)))
        if bool(jaxrb.inertia.is_valid_inertia(jnp.asarray(guess))):
            starts.append(guess)
    return starts


def test_random_diagonal_starts(omega_data):
    """20 starts, noise-free torque-free data: each fit converges to the truth (up to the
    scale it fixes) or says it did not; none raises. All 20 converge (measured: 10 to 40
    steps). Then noisy data from a start that used to exhaust the default budget."""
    before = traces(_solve)
    outcomes = []
    for guess in _diagonal_starts(20):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", jf.ConvergenceWarning)
            res = jf.fit_inertia(TS, inertia0=guess, omega=omega_data, **SIM)
        outcomes.append((res.converged, res.reason, res.num_steps, res.num_invalid))
        if res.converged:
            J = res.values["inertia"]
            J_scaled = J_TRUE * np.trace(J) / np.trace(J_TRUE)
            rel = np.max(np.abs(J - J_scaled)) / np.max(np.abs(J_scaled))
            assert rel <= 1e-6, (np.diag(guess), rel)
            np.testing.assert_allclose(res.values["omega0"], OMEGA0, rtol=0, atol=1e-8)
        else:
            assert res.reason in ("max_steps", "no_progress"), res.reason
            assert any("did not converge" in w for w in res.warnings)
        assert res.num_steps <= 100 and res.num_rejected <= res.num_steps
    assert sum(c for c, *_ in outcomes) == 20, outcomes

    rng = np.random.default_rng(1)
    guess = np.diag(J_TRUE) * np.array([1.3, 0.75, 1.2])
    for _ in range(6):
        noisy = omega_data + 1e-3 * rng.standard_normal(omega_data.shape)
        res = jf.fit_inertia(TS, inertia0=guess, omega=noisy, **SIM)
        assert res.converged, (res.reason, res.num_steps)
        assert res.num_steps < 100
    if before is not None:  # one compiled solver for all 26 fits
        assert traces(_solve) - before <= 1


def test_invalid_inertia_trial_gives_nan_not_an_abort(monkeypatch, omega_data):
    """The residuals at a parameter vector whose tensor is singular (one Cholesky factor
    e^40 times the others) are NaN under jit, where `simulate` used to raise."""
    captured = {}

    def capture(fn, z0, *args, **kwargs):
        captured.update(fn=fn, z0=np.asarray(z0))

    monkeypatch.setattr(inertia_id, "least_squares_fit", capture)
    jf.fit_inertia(TS, inertia0=np.diag(J_TRUE), omega=omega_data, **SIM)
    fn, z = captured["fn"], captured["z0"].copy()
    z[0] = 40.0
    inertia, _, _ = fn.split(jnp.asarray(z))
    assert not bool(jaxrb.inertia.is_valid_inertia(inertia))
    r = eqx.filter_jit(lambda f, zz: f(zz, None))(fn, jnp.asarray(z))
    assert r.shape == (omega_data.size,) and bool(jnp.all(jnp.isnan(r)))


class _Walled(eqx.Module):
    """Residuals tanh(z - 1.2) (twice, weighted): the Gauss-Newton step from far away
    overshoots past z = 1.5, where the residuals are NaN, or (`nan_jacobian`) zero, a lower
    cost than anywhere else, with a NaN Jacobian."""

    nan_jacobian: bool = eqx.field(static=True)

    def __call__(self, z, args):
        x = z[0]
        r = jnp.stack([jnp.tanh(x - 1.2), 0.5 * jnp.tanh(x - 1.2)])
        beyond = x > 1.5
        if self.nan_jacobian:
            return jnp.where(beyond, jnp.sqrt(jnp.maximum(1.5 - x, 0.0)), r)
        return jnp.where(beyond, jnp.nan, r)


@pytest.mark.parametrize("nan_jacobian", [False, True])
def test_trial_points_beyond_a_wall_are_rejected(nan_jacobian):
    """From z0 = -3 the first steps land past z = 1.5 (where the model, or its Jacobian, is
    NaN): rejected, damped, retried; the fit converges to z = 1.2."""
    fn = _Walled(nan_jacobian)
    res = jf.least_squares_fit(fn, jnp.array([-3.0]), lambda z: (z,), ("z",), ("z",))
    assert res.converged, res.message
    assert res.num_invalid >= 1 and res.num_rejected >= res.num_invalid
    assert res.values["z"][0] == pytest.approx(1.2, abs=1e-9)


def test_non_convergence_is_reported_not_raised():
    class Residuals(eqx.Module):
        def __call__(self, z, args):
            return jnp.stack([jnp.exp(z[0]) - 2.0, 0.5 * z[0], jnp.sin(3 * z[0])])

    fn = Residuals()
    with pytest.warns(jf.ConvergenceWarning, match="budget of max_steps"):
        res = jf.least_squares_fit(
            fn, jnp.array([4.0]), lambda z: (z,), ("z",), ("z",), max_steps=2
        )
    assert not res.converged and res.reason == "max_steps" and res.num_steps == 2
    assert "max_steps" in res.message and "did not converge" in res.warnings[-1]

    class NaNAtStart(eqx.Module):
        def __call__(self, z, args):
            return jnp.where(z[0] < 0, jnp.nan, z - 1.0) * jnp.ones(3)

    with pytest.warns(jf.ConvergenceWarning, match="initial guess"):
        res = jf.least_squares_fit(NaNAtStart(), jnp.array([-1.0]), lambda z: (z,), ("z",), ("z",))
    assert not res.converged and res.reason == "invalid_start" and res.num_steps == 0
    assert np.isnan(res.std["z"]).all() and np.isnan(res.condition_number)
    assert "converged: False" in res.report()


def test_tolerance_and_budget_checks():
    fn = _Walled(False)
    for kwargs, match in (
        (dict(rtol=-1.0), "rtol"),
        (dict(atol=np.nan), "atol"),
        (dict(max_steps=-1), "max_steps"),
    ):
        with pytest.raises(ValueError, match=match):
            jf.least_squares_fit(fn, jnp.array([0.0]), lambda z: (z,), ("z",), ("z",), **kwargs)
    omega = np.tile(OMEGA0, (TS.size, 1))
    with pytest.raises(ValueError, match="sim_rtol"):
        jf.fit_inertia(TS, inertia0=np.diag(J_TRUE), omega=omega, sim_rtol=-1e-8)
    with pytest.raises(ValueError, match="both be 0"):
        jf.fit_drag(TS, np.zeros((TS.size, 3)), mass=1.0, drag0=0.1, sim_rtol=0, sim_atol=0)


@pytest.mark.parametrize("jacobian", ["batched", "columns"])
def test_the_jacobian_either_way_is_jax_jacfwd_s(jacobian):
    """The fit's Jacobian (batched over the parameters, or a column at a time) equals
    `jax.jacfwd` of the residuals at the result, and its residuals the model's there
    (float64)."""

    class Decay(eqx.Module):  # a * exp(-k t) + c sampled at 8 times, data with a wiggle
        t: jax.Array

        def __call__(self, z, args):
            a, k, c = z
            data = 2.0 * jnp.exp(-0.7 * self.t) + 0.3 + 0.01 * jnp.sin(5 * self.t)
            return a * jnp.exp(-k * self.t) + c - data

    fn = Decay(jnp.linspace(0.0, 3.0, 8))
    res = jf.least_squares_fit(
        fn, jnp.array([1.0, 0.3, 0.0]), lambda z: (z,), ("z",), ("a", "k", "c"), jacobian=jacobian
    )
    assert res.converged, res.message
    z = jnp.asarray(res.values["z"])
    expected = jax.jacfwd(lambda z: fn(z, None))(z)
    np.testing.assert_allclose(res.jacobian, expected, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(res.residuals, fn(z, None), rtol=1e-13, atol=1e-15)
    with pytest.raises(ValueError, match="jacobian must be 'batched' or 'columns', got 'rows'"):
        jf.least_squares_fit(fn, jnp.zeros(3), lambda z: (z,), ("z",), ("z",), jacobian="rows")
