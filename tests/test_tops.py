"""Exact torque-free tops (jaxrb.analytic) vs high-accuracy numerical integration and invariants."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxrb import quat_geodesic_angle, quat_rotate
from jaxrb.analytic import (
    asymmetric_top,
    asymmetric_top_params,
    ellipk_m1,
    flip_half_period,
    spherical_top,
    symmetric_top,
)


def _quat_mul_np(p, q):
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return np.array(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ]
    )


def _integrate(inertia, omega0, q0, ts, attitude=True):
    """scipy DOP853 (rtol = atol = 1e-13) of J w_dot = -w x J w and q_dot = 1/2 q (x) (0, w)."""
    inertia = np.asarray(inertia, dtype=float)

    def rhs(t, y):
        w = y[:3]
        dw = -np.cross(w, inertia * w) / inertia
        if not attitude:
            return dw
        dq = 0.5 * _quat_mul_np(y[3:], np.concatenate([[0.0], w]))
        return np.concatenate([dw, dq])

    y0 = np.asarray(omega0, dtype=float)
    if attitude:
        y0 = np.concatenate([y0, np.asarray(q0, dtype=float)])
    sol = solve_ivp(rhs, (ts[0], ts[-1]), y0, method="DOP853", rtol=1e-13, atol=1e-13, t_eval=ts)
    assert sol.success
    return sol.y.T


_asym = jax.jit(asymmetric_top)
I123 = jnp.array([1.0, 2.0, 3.0])

# both regimes, all sign patterns that matter
OMEGA0S = [
    (1.0, 0.1, 2.0),  # about axis 3
    (-1.0, 0.5, -2.0),
    (0.3, -1.0, -2.0),
    (2.0, 1.0, 0.3),  # about axis 1
    (-2.0, -1.0, 0.3),
    (-1.5, 0.7, -0.4),
]


@pytest.mark.parametrize("omega0", OMEGA0S)
def test_asymmetric_vs_integration(omega0):
    ts = np.linspace(0.0, 50.0, 101)
    ref = _integrate(I123, omega0, None, ts, attitude=False)
    w = np.asarray(_asym(jnp.asarray(ts), I123, jnp.array(omega0)))
    assert np.max(np.abs(w - ref)) / np.linalg.norm(omega0) < 1e-9


@pytest.mark.parametrize("inertia", [(3.0, 1.0, 2.0), (2.0, 3.0, 1.0), (1.0, 3.0, 2.0)])
def test_asymmetric_any_axis_order(inertia):
    ts = np.linspace(0.0, 20.0, 41)
    for omega0 in [(1.0, 0.1, 2.0), (2.0, -1.0, 0.3)]:
        ref = _integrate(inertia, omega0, None, ts, attitude=False)
        w = np.asarray(_asym(jnp.asarray(ts), jnp.array(inertia), jnp.array(omega0)))
        assert np.max(np.abs(w - ref)) / np.linalg.norm(omega0) < 1e-9


@jax.jit
def _residual_and_invariants(inertia, omega0, ts):
    f = lambda t: asymmetric_top(t, inertia, omega0)  # noqa: E731
    w = jax.vmap(f)(ts)
    wdot = jax.vmap(jax.jacfwd(f))(ts)
    res = inertia * wdot + jnp.cross(w, inertia * w)
    E = jnp.sum(inertia * w * w, axis=-1)
    L2 = jnp.sum((inertia * w) ** 2, axis=-1)
    return w, res, E, L2


@jax.jit
def _newton_w2_root(inertia, omega0, t):
    """Root of omega_2(t) of the exact formula by Newton (derivative by the custom JVP)."""
    f2 = lambda t: asymmetric_top(t, inertia, omega0)[1]  # noqa: E731
    newton = lambda t: jax.lax.fori_loop(0, 30, lambda _, t: t - f2(t) / jax.grad(f2)(t), t)  # noqa: E731
    return jax.vmap(newton)(t)


def _separatrix_omega0(m1_target, about3):
    """omega0 = (w1, 1, w3) on I = (1, 2, 3) with 1 - m = m1_target (solved in closed form)."""
    # regime 3: m1 = d31 D / (d32 Q) with D = 3 w3^2 - w1^2, Q = 2 + 6 w3^2 (w2 = 1), w1 fixed.
    # regime 1: m1 = -d31 D / (d21 P) with P = 2 w1^2 + 2, w3 fixed.
    if about3:
        w1 = 0.5
        # 2 (3 w3^2 - w1^2) = m1 (2 + 6 w3^2)  ->  w3^2 (6 - 6 m1) = 2 m1 + 2 w1^2
        w3 = np.sqrt((2 * m1_target + 2 * w1**2) / (6 - 6 * m1_target))
    else:
        w3 = 0.5
        # -2 (3 w3^2 - w1^2) = m1 (2 w1^2 + 2) -> w1^2 (2 - 2 m1) = 2 m1 + 6 w3^2
        w1 = np.sqrt((2 * m1_target + 6 * w3**2) / (2 - 2 * m1_target))
    return jnp.array([w1, 1.0, w3])


@pytest.mark.parametrize("m1_target", [1e-6, 1e-10])
@pytest.mark.parametrize("about3", [True, False])
def test_near_separatrix(m1_target, about3):
    omega0 = _separatrix_omega0(m1_target, about3)
    p = asymmetric_top_params(I123, omega0)
    assert bool(p.about_axis3) == about3
    assert abs(float(p.m1) / m1_target - 1) < 1e-6
    half = float(flip_half_period(I123, omega0))
    assert half == pytest.approx(2 * float(ellipk_m1(p.m1)) / abs(float(p.frequency)), rel=1e-15)
    ts = jnp.linspace(0.0, 3.2 * half, 4001)
    w, res, E, L2 = _residual_and_invariants(I123, omega0, ts)
    scale = float(jnp.linalg.norm(omega0))
    assert float(jnp.max(jnp.abs(res))) / scale**2 < 1e-10
    E0 = float(jnp.sum(I123 * omega0**2))
    L20 = float(jnp.sum((I123 * omega0) ** 2))
    assert float(jnp.max(jnp.abs(E / E0 - 1))) < 1e-10
    assert float(jnp.max(jnp.abs(L2 / L20 - 1))) < 1e-10
    # spacing of the sign changes of omega_2 = the flip half-period
    w2 = np.asarray(w[:, 1])
    idx = np.nonzero(np.sign(w2[1:]) != np.sign(w2[:-1]))[0]
    assert len(idx) >= 3
    roots = np.asarray(_newton_w2_root(I123, omega0, ts[idx]))
    spacing = np.diff(roots)
    assert np.max(np.abs(spacing / half - 1)) < 1e-9


def test_asymmetric_residual_generic():
    ts = jnp.linspace(0.0, 50.0, 201)
    for omega0 in OMEGA0S:
        omega0 = jnp.array(omega0)
        _, res, E, L2 = _residual_and_invariants(I123, omega0, ts)
        assert float(jnp.max(jnp.abs(res))) / float(jnp.sum(omega0**2)) < 1e-12
        E0 = float(jnp.sum(I123 * omega0**2))
        assert float(jnp.max(jnp.abs(E / E0 - 1))) < 1e-13


def test_asymmetric_jit_eager_vmap_grad():
    ts = jnp.linspace(0.0, 10.0, 7)
    w0s = jnp.array(OMEGA0S)
    eager = jnp.stack([asymmetric_top(ts, I123, w) for w in w0s[:1]])
    jitted = jnp.stack([_asym(ts, I123, w) for w in w0s[:1]])
    batched = jax.jit(jax.vmap(asymmetric_top, in_axes=(None, None, 0)))(ts, I123, w0s)
    np.testing.assert_allclose(jitted, eager, rtol=0, atol=1e-14)
    np.testing.assert_allclose(batched[:1], eager, rtol=0, atol=1e-14)
    assert batched.shape == (len(OMEGA0S), 7, 3)
    # t of any shape
    assert asymmetric_top(jnp.zeros((2, 3)), I123, w0s[0]).shape == (2, 3, 3)
    np.testing.assert_allclose(asymmetric_top(0.0, I123, w0s[1]), w0s[1], atol=1e-15)

    # gradient w.r.t. omega0 and inertia vs central differences (float64)
    @jax.jit
    def loss(inertia, w0):
        return jnp.sum(jnp.sin(asymmetric_top(ts, inertia, w0)))

    g_i, g_w = jax.jit(jax.grad(loss, argnums=(0, 1)))(I123, w0s[0])
    h = 1e-6
    for k in range(3):
        e = jnp.zeros(3).at[k].set(h)
        fd_w = (loss(I123, w0s[0] + e) - loss(I123, w0s[0] - e)) / (2 * h)
        fd_i = (loss(I123 + e, w0s[0]) - loss(I123 - e, w0s[0])) / (2 * h)
        assert float(g_w[k]) == pytest.approx(float(fd_w), rel=1e-6, abs=1e-7)
        assert float(g_i[k]) == pytest.approx(float(fd_i), rel=1e-6, abs=1e-7)


def test_asymmetric_bad_input():
    with pytest.raises(ValueError, match="inertia"):
        asymmetric_top(0.0, jnp.array([1.0, 2.0, 2.0]), jnp.ones(3))
    with pytest.raises(ValueError, match="inertia"):
        asymmetric_top(0.0, jnp.array([1.0, -2.0, 3.0]), jnp.ones(3))
    with pytest.raises(ValueError, match="omega0"):
        asymmetric_top(0.0, I123, jnp.ones(4))


QS = [
    jnp.array([1.0, 0.0, 0.0, 0.0]),
    jnp.array([0.7, -0.2, 0.5, 0.3]) / jnp.linalg.norm(jnp.array([0.7, -0.2, 0.5, 0.3])),
]


@pytest.mark.parametrize(
    "J1, J3, omega0",
    [
        (2.0, 1.0, (0.4, -0.3, 2.0)),  # prolate
        (1.0, 2.0, (0.4, -0.3, 2.0)),  # oblate
        (1.0, 1.7, (-1.0, 0.5, -0.7)),
    ],
)
@pytest.mark.parametrize("q0", QS)
def test_symmetric_top_vs_integration(J1, J3, omega0, q0):
    ts = np.linspace(0.0, 20.0, 81)
    ref = _integrate((J1, J1, J3), omega0, q0, ts)
    sol = jax.jit(symmetric_top)(jnp.asarray(ts), J1, J3, jnp.array(omega0), q0)
    np.testing.assert_allclose(sol.omega, ref[:, :3], rtol=0, atol=1e-10)
    assert float(jnp.max(quat_geodesic_angle(sol.quat, jnp.asarray(ref[:, 3:])))) < 1e-9
    w0 = jnp.array(omega0)
    # |omega| constant, K constant in the world frame
    np.testing.assert_allclose(jnp.linalg.norm(sol.omega, axis=-1), jnp.linalg.norm(w0), rtol=1e-14)
    K_world = quat_rotate(sol.quat, sol.angular_momentum)
    np.testing.assert_allclose(K_world, jnp.broadcast_to(K_world[0], K_world.shape), atol=1e-12)
    np.testing.assert_allclose(
        jnp.linalg.norm(sol.angular_momentum, axis=-1), sol.angular_momentum_norm, rtol=1e-14
    )
    # docs/theory.md, section 5.2: gamma, alpha from arccos;
    # sin(beta) = (J3 - J1) w3 w_tau / (|K| |w|)
    w_tau = float(jnp.linalg.norm(w0[:2]))
    Kn = float(sol.angular_momentum_norm[0])
    wn = float(sol.omega_norm[0])
    assert float(sol.gamma[0]) == pytest.approx(np.arccos(J3 * omega0[2] / Kn), abs=1e-12)
    assert float(sol.alpha[0]) == pytest.approx(np.arccos(omega0[2] / wn), abs=1e-12)
    assert np.sin(float(sol.beta[0])) == pytest.approx(
        (J3 - J1) * omega0[2] * w_tau / (Kn * wn), abs=1e-12
    )
    # the angle between K and omega stays beta
    cosb = jnp.sum(sol.angular_momentum * sol.omega, axis=-1) / (Kn * wn)
    np.testing.assert_allclose(cosb, np.cos(float(sol.beta[0])), atol=1e-12)


def test_symmetric_top_precession_sense():
    # oblate and prolate tops: omega turns about e3 in opposite senses in the body
    w0 = jnp.array([1.0, 0.0, 1.0])
    pro = symmetric_top(0.1, 2.0, 1.0, w0)
    obl = symmetric_top(0.1, 1.0, 2.0, w0)
    assert float(pro.body_rate) > 0 > float(obl.body_rate)
    assert float(pro.omega[1]) < 0 < float(obl.omega[1])


@pytest.mark.parametrize("q0", QS)
def test_spherical_top(q0):
    ts = np.linspace(0.0, 10.0, 41)
    omega0 = (0.3, -1.2, 0.8)
    ref = _integrate((1.5, 1.5, 1.5), omega0, q0, ts)
    omega, q = jax.jit(spherical_top)(jnp.asarray(ts), jnp.array(omega0), q0)
    np.testing.assert_allclose(omega, ref[:, :3], atol=1e-12)
    assert float(jnp.max(quat_geodesic_angle(q, jnp.asarray(ref[:, 3:])))) < 1e-9
    # gradient finite at omega0 = 0 (AD-safe exp map)
    g = jax.jit(jax.grad(lambda w: jnp.sum(spherical_top(1.0, w)[1])))(jnp.zeros(3))
    assert bool(jnp.all(jnp.isfinite(g)))


def test_symmetric_vmap_and_jit_equal_eager():
    ts = jnp.linspace(0.0, 5.0, 5)
    w0s = jnp.array([[0.4, -0.3, 2.0], [1.0, 0.5, -0.7], [0.0, 0.0, 1.0]])
    f = jax.vmap(symmetric_top, in_axes=(None, None, None, 0))
    batched = jax.jit(f)(ts, 1.0, 2.0, w0s)
    for i in range(3):
        eager = symmetric_top(ts, 1.0, 2.0, w0s[i])
        np.testing.assert_allclose(batched.quat[i], eager.quat, atol=1e-15)
        np.testing.assert_allclose(batched.omega[i], eager.omega, atol=1e-15)
    assert batched.quat.shape == (3, 5, 4)
