"""Oracles: the fixed-axis pendulum sample problem and the bouncing ball."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special
from scipy.integrate import solve_ivp

from jaxrb import analytic
from jaxrb.analytic import SAMPLE_PENDULUM as P

# Module-level jitted functions: one compile each, reused across tests (eager dispatch of the
# elliptic functions is slow on a loaded CPU).
_theta = jax.jit(analytic.pendulum_theta)
_theta_dot = jax.jit(analytic.pendulum_theta_dot)
_times = jax.jit(analytic.ball_impact_times, static_argnums=2)
_apexes = jax.jit(analytic.ball_apex_heights, static_argnums=2)
_height = jax.jit(analytic.ball_height, static_argnames="max_bounces")
_rest = jax.jit(analytic.ball_rest_time)

# ----------------------------------------------------------------------------- pendulum


def _omega0():
    return math.sqrt(P.g * P.r / P.k_O**2)


@pytest.fixture(scope="module")
def pendulum_reference():
    """theta(t), theta_dot(t) over one full period from J_O theta_ddot = m g r cos(theta)."""
    T = 4 * scipy.special.ellipk(0.5) / _omega0()

    def rhs(t, y):
        return [y[1], P.g * P.r * math.cos(y[0]) / P.k_O**2]

    ts = np.linspace(0.0, T, 81)
    sol = solve_ivp(rhs, (0.0, T), [0.0, 0.0], method="DOP853", rtol=1e-13, atol=1e-14, t_eval=ts)
    assert sol.success
    return ts, sol.y[0], sol.y[1]


def test_sample_numbers():
    assert (P.mass, P.r, P.k_O, P.g) == (7.5, 0.25, 0.295, 9.81)
    On, Ot, mag = analytic.pendulum_bearing_force(0.0, P.mass, P.r, P.k_O)
    assert float(On) == 0.0
    assert float(Ot) == pytest.approx(7.5 * 9.81 * (1 - 0.25**2 / 0.295**2), rel=1e-15)
    assert float(mag) == pytest.approx(float(Ot), rel=1e-15)
    assert float(analytic.pendulum_period(P.r, P.k_O)) == pytest.approx(
        4 * scipy.special.ellipk(0.5) / _omega0(), rel=1e-15
    )


def test_pendulum_theta_vs_solve_ivp(pendulum_reference):
    ts, theta, theta_dot = pendulum_reference
    th, thd = _theta(jnp.asarray(ts), P.r, P.k_O), _theta_dot(jnp.asarray(ts), P.r, P.k_O)
    np.testing.assert_allclose(th, theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(thd, theta_dot, rtol=0, atol=1e-9 * np.max(np.abs(theta_dot)))
    # the swing reaches pi at half period and returns to 0
    assert float(th[40]) == pytest.approx(math.pi, abs=1e-12)
    assert abs(float(th[-1])) < 1e-12
    # the same formula with scipy's elliptic functions
    sn, cn, dn, _ = scipy.special.ellipj(_omega0() * ts, 0.5)
    np.testing.assert_allclose(th, math.pi / 2 - 2 * np.arctan(cn), rtol=0, atol=1e-13)


def test_pendulum_rates_vs_solve_ivp(pendulum_reference):
    """alpha(theta) and w^2(theta) against the integrated motion (energy from the integration)."""
    ts, theta, theta_dot = pendulum_reference
    np.testing.assert_allclose(
        analytic.pendulum_angular_velocity_squared(jnp.asarray(theta), P.r, P.k_O),
        theta_dot**2,
        rtol=0,
        atol=1e-9 * np.max(theta_dot**2),
    )
    # alpha = d theta_dot / dt, checked by the derivative of the exact theta_dot(t)
    alpha = jax.jit(jax.vmap(jax.grad(lambda t: _theta_dot(t, P.r, P.k_O))))(jnp.asarray(ts))
    np.testing.assert_allclose(
        analytic.pendulum_angular_acceleration(jnp.asarray(theta), P.r, P.k_O),
        alpha,
        rtol=0,
        atol=1e-8,
    )


def test_bearing_force_vs_newton(pendulum_reference):
    """O = m a_C - m g from the integrated motion, projected on the pendulum, theta in [0, pi]."""
    ts, theta, w = pendulum_reference
    half = ts <= ts[40]  # theta from 0 to 180 deg
    theta, w = theta[half], w[half]
    alpha = P.g * P.r * np.cos(theta) / P.k_O**2  # from J_O alpha = m g r cos(theta)
    # plane of motion: x horizontal, y up; C = r (cos theta, -sin theta) from O
    er = np.stack([np.cos(theta), -np.sin(theta)], -1)  # O -> C
    et = np.stack([-np.sin(theta), -np.cos(theta)], -1)  # d er / d theta
    a_C = P.r * (alpha[:, None] * et - (w**2)[:, None] * er)
    force = P.mass * a_C - P.mass * np.array([0.0, -P.g])  # the bearing force on the body
    On_ref = np.sum(force * -er, -1)  # towards O
    Ot_ref = -np.sum(force * et, -1)  # positive opposite to increasing theta
    On, Ot, mag = analytic.pendulum_bearing_force(jnp.asarray(theta), P.mass, P.r, P.k_O)
    jitted = jax.jit(analytic.pendulum_bearing_force)(jnp.asarray(theta), P.mass, P.r, P.k_O)
    for a, b in zip((On, Ot, mag), jitted, strict=True):  # jit == eager
        np.testing.assert_allclose(a, b, rtol=1e-15, atol=1e-12)
    scale = P.mass * P.g
    np.testing.assert_allclose(On, On_ref, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(Ot, Ot_ref, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(mag, np.linalg.norm(force, axis=-1), rtol=0, atol=1e-9 * scale)
    assert np.all(Ot_ref[theta < np.pi / 2 - 1e-3] > 0)  # the bearing holds the body back


def test_pendulum_gradients():
    @jax.jit
    def f(r, k):
        t = jnp.array([0.1, 0.3, 0.7])
        return _theta(t, r, k) + analytic.pendulum_bearing_force(0.4, 7.5, r, k)[2]

    g = jax.jit(jax.jacfwd(f, argnums=(0, 1)))(0.25, 0.295)
    gr = jax.jit(jax.jacrev(f, argnums=(0, 1)))(0.25, 0.295)
    eps = 1e-6
    fd_r = (f(0.25 + eps, 0.295) - f(0.25 - eps, 0.295)) / (2 * eps)
    fd_k = (f(0.25, 0.295 + eps) - f(0.25, 0.295 - eps)) / (2 * eps)
    for a, b in ((g[0], fd_r), (g[1], fd_k), (gr[0], fd_r), (gr[1], fd_k)):
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-7)


# ----------------------------------------------------------------------------- ball


def _event_driven(h0, e, g, v0, n):
    """Impact times and apex heights by integrating y'' = -g with a floor event and restarts."""

    def rhs(t, y):
        return [y[1], -g]

    def floor(t, y):
        return y[0]

    floor.terminal, floor.direction = True, -1
    t, y, impacts, apexes = 0.0, [h0, v0], [], []
    for _ in range(n):
        sol = solve_ivp(
            rhs, (t, t + 100.0), y, method="DOP853", rtol=1e-13, atol=1e-15, events=floor
        )
        t = sol.t_events[0][0]
        impacts.append(t)
        v = -e * sol.y_events[0][0][1]
        apexes.append(v * v / (2 * g))  # the apex of the next flight (energy), checked below
        y = [0.0, v]
    return np.array(impacts), np.array(apexes)


@pytest.mark.parametrize("h0, e, v0", [(1.3, 0.7, 0.0), (0.4, 0.55, 2.1), (2.0, 1.0, -0.5)])
def test_ball_impacts_vs_event_driven(h0, e, v0):
    g = 9.81
    n = 6
    times_ref, apex_ref = _event_driven(h0, e, g, v0, n)
    times = _times(h0, e, n, g, v0)
    np.testing.assert_allclose(times, times_ref, rtol=1e-11)
    np.testing.assert_allclose(_apexes(h0, e, n, g, v0), apex_ref, rtol=1e-11)
    # closed-form recursion
    u = math.sqrt(v0 * v0 + 2 * g * h0)
    rec = [(v0 + u) / g]
    for k in range(1, n):
        rec.append(rec[-1] + 2 * e**k * u / g)
    np.testing.assert_allclose(times, rec, rtol=1e-14)


def test_ball_rest_time_is_the_limit():
    h0, e = 1.3, 0.8
    t1 = math.sqrt(2 * h0 / 9.81)
    assert float(_rest(h0, e)) == pytest.approx(t1 * (1 + e) / (1 - e), rel=1e-14)
    times = _times(h0, e, 400)
    assert float(times[-1]) == pytest.approx(float(_rest(h0, e)), rel=1e-14)
    # with an initial upward velocity: the sum of all flights
    u = math.sqrt(1.5**2 + 2 * 9.81 * h0)
    flights = (1.5 + u) / 9.81 + sum(2 * e**k * u / 9.81 for k in range(1, 400))
    assert float(_rest(h0, e, 9.81, 1.5)) == pytest.approx(flights, rel=1e-14)
    assert math.isinf(float(_rest(h0, 1.0)))
    assert float(_rest(h0, 0.0)) == pytest.approx(t1, rel=1e-15)


def test_ball_height():
    h0, e, v0, g = 1.3, 0.6, 0.9, 9.81
    times = np.asarray(_times(h0, e, 5, g, v0))
    t_rest = float(_rest(h0, e, g, v0))
    u = math.sqrt(v0 * v0 + 2 * g * h0)
    ts = np.concatenate([np.linspace(0, times[3], 200), [t_rest, t_rest + 0.5]])
    ref = np.where(ts < times[0], h0 + v0 * ts - g * ts**2 / 2, 0.0)
    for k in range(3):
        s = ts - times[k]
        inside = (ts >= times[k]) & (ts < times[k + 1])
        ref = np.where(inside, e ** (k + 1) * u * s - g * s**2 / 2, ref)
    h = _height(jnp.asarray(ts), h0, e, g, v0)
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-12)
    assert np.all(np.asarray(h) >= 0)
    np.testing.assert_allclose(
        analytic.ball_height(jnp.asarray(ts), h0, e, g, v0), h, rtol=0, atol=1e-15
    )
    # apex after the first bounce
    t_apex = times[0] + e * u / g
    assert float(_height(t_apex, h0, e, g, v0)) == pytest.approx(
        float(_apexes(h0, e, 1, g, v0)[0]), rel=1e-13
    )
    # max_bounces: bounces after the modelled ones are rest on the floor
    assert float(_height(times[2] + 1e-3, h0, e, g, v0, max_bounces=2)) == 0.0
    assert float(_height(times[2] + 1e-3, h0, e, g, v0, max_bounces=3)) > 0.0


def test_ball_gradients_closed_form_and_fd():
    h0, e, v0, g, n = 1.1, 0.65, 0.7, 9.81, 5

    def tk(h0, e, v0):
        return _times(h0, e, n, g, v0)

    jac = jax.jit(jax.jacrev(tk, argnums=(0, 1, 2)))(h0, e, v0)
    jac_fwd = jax.jit(jax.jacfwd(tk, argnums=(0, 1, 2)))(h0, e, v0)
    u = math.sqrt(v0 * v0 + 2 * g * h0)
    k = np.arange(n)
    S = np.array([sum(e**i for i in range(1, j + 1)) for j in k])
    dS = np.array([sum(i * e ** (i - 1) for i in range(1, j + 1)) for j in k])
    np.testing.assert_allclose(jac[0], (1 + 2 * S) / u, rtol=1e-13)  # u1 = sqrt(v0^2 + 2 g h0)
    np.testing.assert_allclose(jac[1], 2 * u / g * dS, rtol=1e-13)
    np.testing.assert_allclose(jac[2], (1 + v0 / u * (1 + 2 * S)) / g, rtol=1e-13)
    eps = 1e-6
    args = [h0, e, v0]
    for i in range(3):
        up, dn = list(args), list(args)
        up[i] += eps
        dn[i] -= eps
        fd = (tk(*up) - tk(*dn)) / (2 * eps)
        np.testing.assert_allclose(jac[i], fd, rtol=1e-8)
        np.testing.assert_allclose(jac_fwd[i], jac[i], rtol=1e-14)
    # at e = 0 (a dead ball) the derivative of e^k is still finite and exact
    d0 = jax.jit(jax.grad(lambda e: _times(h0, e, 3, g, v0)[-1]))(0.0)
    assert float(d0) == pytest.approx(2 * u / g, rel=1e-14)
    # heights, mid flight between impacts 2 and 3
    times = _times(h0, e, 3, g, v0)
    t = float(0.4 * times[1] + 0.6 * times[2])
    hfun = lambda h0, e, v0: _height(t, h0, e, g, v0)  # noqa: E731
    gh = jax.jit(jax.grad(hfun, argnums=(0, 1, 2)))(h0, e, v0)
    for i in range(3):
        up, dn = list(args), list(args)
        up[i] += eps
        dn[i] -= eps
        assert float(gh[i]) == pytest.approx(float((hfun(*up) - hfun(*dn)) / (2 * eps)), rel=1e-7)


def test_ball_batching_and_errors():
    h0 = jnp.array([0.5, 1.0, 1.5])
    e = jnp.array([[0.3], [0.8]])
    times = _times(h0, e, 4)
    assert times.shape == (2, 3, 4)
    np.testing.assert_allclose(times[1, 2], _times(1.5, 0.8, 4), rtol=1e-15)
    assert _apexes(h0, e, 2).shape == (2, 3, 2)
    assert _rest(h0, e).shape == (2, 3)
    assert _height(jnp.linspace(0, 1, 5)[:, None, None], h0, e[..., 0][:, None]).shape == (5, 2, 3)
    vm = jax.jit(jax.vmap(lambda h: _times(h, 0.5, 3)))(h0)
    np.testing.assert_allclose(vm, _times(h0, 0.5, 3), rtol=1e-15)
    assert _times(1, 0.5, 2).dtype == jnp.float64
    for bad in (0, 2.0, True):
        with pytest.raises(ValueError, match="n must be a Python int >= 1"):
            analytic.ball_impact_times(1.0, 0.5, bad)
    with pytest.raises(ValueError, match="max_bounces must be a Python int >= 1"):
        analytic.ball_height(0.1, 1.0, 0.5, max_bounces=0)
