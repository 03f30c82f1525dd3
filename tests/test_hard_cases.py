"""Hard cases (short versions; the long ones are in benchmarks/): Dzhanibekov flips near the
separatrix, fast spin, extreme inertia ratios, long-run drift, Euler angles near gimbal lock."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

import jaxrb
from jaxrb._batched import simulate_batch
from jaxrb._exact_flow import _qx, _qz, torque_free_flow
from jaxrb.analytic import asymmetric_top, asymmetric_top_params, flip_half_period


def _dopri8(scene, states, ts, tol=1e-12):
    return jax.vmap(
        lambda s: (
            jaxrb.simulate(
                scene, s, ts, solver=dfx.Dopri8(), rtol=tol, atol=tol, max_steps=200_000
            ).states
        )
    )(states)


def test_dzhanibekov_near_separatrix():
    """Spin close to the intermediate axis: flips of omega_2, m1 = 1 - m ~ 1e-8."""
    inertia = jnp.array([1.0, 2.0, 3.0])
    omega0 = jnp.array([[1e-4, 1.0, 1e-4], [-2e-4, 1.0, 1e-4]])
    m1 = jax.vmap(lambda w: asymmetric_top_params(inertia, w).m1)(omega0)
    assert float(jnp.max(m1)) < 1e-6
    half = jax.vmap(lambda w: flip_half_period(inertia, w))(omega0)
    ts = jnp.stack([jnp.zeros(2), 0.5 * half, 1.5 * half], -1)  # before and after the first flip
    states = jaxrb.make_state(omega=omega0)
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    ref = jax.vmap(
        lambda s, t: jaxrb.simulate(scene, s, t, solver=dfx.Dopri8(), rtol=1e-13, atol=1e-13).states
    )(states, ts)
    ex = jax.vmap(lambda s, t: torque_free_flow(inertia, s, t, n_fourier=256))(states, ts)
    assert bool(jnp.all(ex.omega[:, 1, 1] * ex.omega[:, 2, 1] < 0))  # omega_2 flipped
    np.testing.assert_allclose(ex.omega, ref.omega, atol=1e-8)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(ex.quat, ref.quat))) < 1e-7


def test_fast_spin():
    """|omega| ~ 1e3 rad/s over ~10 turns: relative errors stay at the tolerance level."""
    inertia = jnp.array([1.0, 2.0, 3.0])
    rng = np.random.default_rng(3)
    w = rng.normal(size=(6, 3))
    omega0 = 1e3 * w / np.linalg.norm(w, axis=-1, keepdims=True)
    states = jaxrb.make_state(omega=omega0)
    ts = jnp.array([0.0, 0.03, 0.06])
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    traj = simulate_batch(scene, states, ts, rtol=1e-11, atol=1e-11)
    ex = torque_free_flow(inertia, states, ts)
    w_exact = jax.vmap(lambda w: asymmetric_top(ts, inertia, w))(states.omega)
    np.testing.assert_allclose(ex.omega, w_exact, atol=1e-9 * 1e3)
    np.testing.assert_allclose(traj.states.omega, w_exact, atol=1e-8 * 1e3)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, ex.quat))) < 1e-8


def test_extreme_inertia_ratio():
    """A needle-like body (moment ratio 1e3): exact flow and integration agree."""
    inertia = jnp.array([1e-3, 1.0, 1.0005])
    omega0 = jnp.array([[0.3, 1.0, 0.7], [1.0, 0.2, -0.5]])
    states = jaxrb.make_state(omega=omega0)
    ts = jnp.array([0.0, 1.0, 4.0])
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    ref = _dopri8(scene, states, ts, tol=1e-13)
    ex = torque_free_flow(inertia, states, ts, n_fourier=128)
    np.testing.assert_allclose(ex.omega, ref.omega, atol=1e-9)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(ex.quat, ref.quat))) < 1e-9


def test_long_run_drift_short_version():
    """100 rotation periods: integrated invariants drift at the tolerance level, exact flow not."""
    inertia = jnp.array([1.0, 2.0, 3.0])
    omega0 = jnp.array([1.0, 0.0, 1.5])
    state = jaxrb.make_state(omega=omega0)
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    period = float(flip_half_period(inertia, omega0)) * 2
    ts = jnp.linspace(0.0, 100 * period, 11)
    traj = jaxrb.simulate(scene, state, ts, rtol=1e-8, atol=1e-8)
    E = jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states)
    L = jax.vmap(lambda s: jaxrb.angular_momentum(scene, s))(traj.states)
    e_drift = float(jnp.max(jnp.abs(E / E[0] - 1)))
    l_drift = float(jnp.max(jnp.linalg.norm(L - L[0], axis=-1)) / jnp.linalg.norm(L[0]))
    assert 0 < e_drift < 1e-5 and 0 < l_drift < 1e-4
    assert float(traj.quat_norm_drift) < 1e-5
    ex = torque_free_flow(inertia, state, ts)
    E_ex = jax.vmap(lambda s: jaxrb.energy(scene, s))(ex)
    L_ex = jax.vmap(lambda s: jaxrb.angular_momentum(scene, s))(ex)
    assert float(jnp.max(jnp.abs(E_ex / E_ex[0] - 1))) < 1e-13
    assert float(jnp.max(jnp.linalg.norm(L_ex - L_ex[0], axis=-1))) < 1e-12
    assert e_drift > 100 * float(jnp.max(jnp.abs(E_ex / E_ex[0] - 1)))


def test_euler_angles_near_gimbal_lock_cost_more_steps():
    """3-1-3 Euler-angle kinematics with theta ~ 1e-3 (near its singularity theta = 0) need
    several times more adaptive steps than the quaternion form for the same accuracy."""
    inertia = jnp.array([1.0, 2.0, 3.0])
    omega0 = jnp.array([0.05, 0.0, 2.0])
    theta0 = 1e-3
    q0 = _qx(jnp.array(theta0))
    T, tol = 20.0, 1e-8
    exact = torque_free_flow(inertia, jaxrb.make_state(quat=q0, omega=omega0), T).quat

    def rhs(t, y, args):
        th, phi, w = y[1], y[2], y[3:]
        a = w[0] * jnp.sin(phi) + w[1] * jnp.cos(phi)
        d = jnp.stack(
            [
                a / jnp.sin(th),
                w[0] * jnp.cos(phi) - w[1] * jnp.sin(phi),
                w[2] - a * jnp.cos(th) / jnp.sin(th),
            ]
        )
        return jnp.concatenate([d, -jnp.cross(w, inertia * w) / inertia])

    y0 = jnp.concatenate([jnp.array([0.0, theta0, 0.0]), omega0])
    sol = dfx.diffeqsolve(
        dfx.ODETerm(rhs),
        dfx.Dopri5(),
        0.0,
        T,
        None,
        y0,
        stepsize_controller=dfx.PIDController(rtol=tol, atol=tol),
        max_steps=100_000,
    )
    psi, th, phi = sol.ys[-1, :3]
    q_euler = jaxrb.quat_multiply(jaxrb.quat_multiply(_qz(psi), _qx(th)), _qz(phi))
    traj = jaxrb.simulate(
        jaxrb.Scene(jaxrb.RigidBody(1.0, inertia)),
        jaxrb.make_state(quat=q0, omega=omega0),
        jnp.array([0.0, T]),
        solver=dfx.Dopri5(),
        rtol=tol,
        atol=tol,
    )
    err_euler = float(jaxrb.quat_geodesic_angle(q_euler, exact))
    err_quat = float(jaxrb.quat_geodesic_angle(traj.states.quat[-1], exact))
    assert err_euler < 1e-6 and err_quat < 1e-6
    assert int(sol.stats["num_steps"]) > 5 * int(traj.num_steps)
