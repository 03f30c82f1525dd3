"""Inertia identification: full tensor with products from motion, scale, warnings, bad input."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
import jaxrb.fit as jf
from jaxrb.fit._parameterisation import perturb_quat

# Fixed-step Tsit5 both for the data and the model: recovery then tests the optimiser and the
# parameterisation, not the integrator's truncation error; and it compiles quickly.
SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
J_TRUE = np.array([[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]])
# 30 % off, entry by entry (a valid tensor: checked by fit_inertia)
J_START = J_TRUE * np.array([[1.3, 0.7, 1.3], [0.7, 1.3, 0.7], [1.3, 0.7, 0.7]])
TS = np.linspace(0.0, 2.0, 21)
OMEGA0 = np.array([1.0, 0.5, 0.8])


def _observe(forces=(), quat0=(1.0, 0.0, 0.0, 0.0)):
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.asarray(J_TRUE)), forces=forces)
    state0 = jaxrb.make_state(quat=jnp.asarray(quat0), omega=jnp.asarray(OMEGA0))
    traj = jaxrb.simulate(scene, state0, jnp.asarray(TS), **SIM)
    return np.asarray(traj.states.omega), np.asarray(traj.states.quat)


def test_torque_free_full_tensor_up_to_scale():
    omega, _ = _observe()
    res = jf.fit_inertia(TS, inertia0=J_START, omega=omega, **SIM)
    assert res.converged
    J = res.values["inertia"]
    assert np.trace(J) == pytest.approx(np.trace(J_START), rel=1e-12)  # the fixed scale
    J_scaled = J_TRUE * np.trace(J) / np.trace(J_TRUE)
    rel = np.max(np.abs(J - J_scaled)) / np.max(np.abs(J_scaled))
    assert rel <= 1e-6, rel
    np.testing.assert_allclose(res.values["omega0"], OMEGA0, rtol=0, atol=1e-8)
    assert any("scale" in w for w in res.warnings)
    assert res.condition_number < 1e6
    assert "converged: True" in res.report()


def test_known_torque_gives_absolute_scale_from_attitude_and_rate():
    torque = jaxrb.Wrench(torque=(0.3, -0.2, 0.5), frame="body")
    q0 = np.asarray(jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, 0.5]), 0.7))
    omega, quat = _observe((torque,), q0)
    q_start = np.asarray(perturb_quat(jnp.asarray(q0), jnp.array([0.02, -0.01, 0.03])))
    res = jf.fit_inertia(
        TS,
        inertia0=J_START,
        omega=omega,
        quat=quat,
        forces=(torque,),
        quat0=q_start,
        omega0=OMEGA0 * 1.1,
        **SIM,
    )
    assert res.converged and not res.warnings
    rel = np.max(np.abs(res.values["inertia"] - J_TRUE)) / np.max(np.abs(J_TRUE))
    assert rel <= 1e-6, rel
    assert (
        float(jaxrb.quat_geodesic_angle(jnp.asarray(res.values["quat0"]), jnp.asarray(q0))) < 1e-8
    )


def test_unidentifiable_combination_is_reported():
    """Only the product a * b enters the model: the driver must say so and not hide it."""
    x = jnp.linspace(0.0, 1.0, 8)

    class Residuals(eqx.Module):
        y: jax.Array

        def __call__(self, z, args):
            return z[0] * z[1] * x + z[2] - self.y

    fn = Residuals(2.0 * x + 0.5)
    with pytest.warns(jf.IdentifiabilityWarning, match="condition number") as record:
        res = jf.least_squares_fit(
            fn, jnp.array([1.5, 1.0, 0.0]), lambda z: (z,), ("z",), ("a", "b", "c")
        )
    message = str(record[0].message)
    assert "a" in message.split("combination of")[1] and "b" in message.split("combination of")[1]
    assert res.condition_number > 1e8
    assert res.values["z"][0] * res.values["z"][1] == pytest.approx(2.0, rel=1e-10)


def test_log_cholesky_parameterisation_is_always_physical(getkey):
    z = jax.random.normal(getkey(), (200, 6)) * 2.0
    J = jax.vmap(jf.log_cholesky_to_inertia)(z)
    assert bool(jnp.all(jax.vmap(jaxrb.inertia.is_valid_inertia)(J)))
    # the inverse map (moderate values: cond(S) ~ e^(4 max|d|) limits the round trip's accuracy)
    z = 0.5 * z
    back = jax.vmap(jf.inertia_to_log_cholesky)(jax.vmap(jf.log_cholesky_to_inertia)(z))
    np.testing.assert_allclose(back, z, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(
        jf.log_cholesky_to_inertia(jf.inertia_to_log_cholesky(J_TRUE)), J_TRUE, atol=1e-14
    )


def test_bad_input():
    omega = np.tile(OMEGA0, (TS.size, 1))
    with pytest.raises(ValueError, match="omega has 20 samples but ts has 21"):
        jf.fit_inertia(TS, inertia0=J_START, omega=omega[:-1])
    bad = omega.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"omega contains NaN or inf \(first at sample 5\)"):
        jf.fit_inertia(TS, inertia0=J_START, omega=bad)
    with pytest.raises(ValueError, match="too few samples"):
        jf.fit_inertia(TS[:2], inertia0=J_START, omega=omega[:2])
    with pytest.raises(ValueError, match="strictly increasing"):
        jf.fit_inertia(TS[::-1], inertia0=J_START, omega=omega)
    with pytest.raises(ValueError, match="needs observed"):
        jf.fit_inertia(TS, inertia0=J_START)
    with pytest.raises(ValueError, match="triangle"):
        jf.fit_inertia(TS, inertia0=[1.0, 1.0, 3.0], omega=omega)
    with pytest.raises(ValueError, match="unit quaternions"):
        jf.fit_inertia(
            TS, inertia0=J_START, quat=np.tile([2.0, 0, 0, 0], (TS.size, 1)), omega0=OMEGA0
        )


def test_a_fit_that_cannot_start_says_why():
    """A simulation that fails at the initial guess (here: out of steps) is named in the
    fit's message and warning, not only "the model cannot be evaluated"."""
    omega, _ = _observe()
    with pytest.warns(jf.ConvergenceWarning, match="maximum number of solver steps"):
        res = jf.fit_inertia(TS, inertia0=J_START, omega=omega, sim_max_steps=2)
    assert not res.converged and res.reason == "invalid_start"
    assert "cannot be evaluated at the initial guess" in res.message
    assert "the simulation at the initial guess: The maximum number of solver steps" in (
        res.message
    )
