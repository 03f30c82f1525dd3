"""Quaternion-rate relations against central finite differences of a known motion q(t)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb

H = 1e-5  # central differences: truncation ~H^2 |q'''| ~ 1e-10, roundoff ~1e-16 / H ~ 1e-11


def attitude(t):
    """A known, non-uniform motion: two rotations about different axes at varying rates."""
    a = jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, 3.0]), 0.7 * t + 0.3 * t**2)
    b = jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, -1.0]), jnp.sin(2.0 * t))
    return jaxrb.quat_multiply(a, b)


def fd(f, t, h=H):
    return (f(t + h) - f(t - h)) / (2 * h)


def fd2(f, t, h=1e-4):
    return (f(t + h) - 2 * f(t) + f(t - h)) / h**2


TIMES = [0.0, 0.4, 1.3, 2.9]


@pytest.mark.parametrize("t", TIMES)
def test_angular_velocity_from_quat_rate(t):
    q, q_dot = attitude(t), fd(attitude, t)
    R, R_dot = jaxrb.quat_to_matrix(q), fd(lambda s: jaxrb.quat_to_matrix(attitude(s)), t)
    # independent definitions: Omega = R^T R_dot (body), R_dot R^T (world)
    w_body = jaxrb.omega_from_angular_velocity_matrix(R.T @ R_dot)
    w_world = jaxrb.omega_from_angular_velocity_matrix(R_dot @ R.T)
    np.testing.assert_allclose(jaxrb.omega_body_from_quat_rate(q, q_dot), w_body, atol=1e-9)
    np.testing.assert_allclose(jaxrb.omega_world_from_quat_rate(q, q_dot), w_world, atol=1e-9)
    np.testing.assert_allclose(R @ w_body, w_world, atol=1e-9)
    np.testing.assert_allclose(
        jaxrb.angular_velocity_matrix(R, R_dot), jaxrb.skew(w_body), atol=1e-9
    )
    # and back: q_dot from omega (body or world), a unit quaternion's rate is orthogonal to it
    np.testing.assert_allclose(jaxrb.quat_rate(q, w_body), q_dot, atol=1e-9)
    np.testing.assert_allclose(jaxrb.quat_rate_world(q, w_world), q_dot, atol=1e-9)
    assert abs(float(jnp.dot(q, q_dot))) < 1e-9


@pytest.mark.parametrize("t", TIMES)
def test_angular_acceleration_from_quat(t):
    q, q_ddot = attitude(t), fd2(attitude, t)

    def w_body(s):
        return jaxrb.omega_body_from_quat_rate(attitude(s), fd(attitude, s))

    np.testing.assert_allclose(
        jaxrb.angular_acceleration_from_quat(q, q_ddot), fd(w_body, t, 1e-4), atol=1e-6
    )


def test_G_and_E_matrices():
    q = attitude(0.8)
    G, E = jaxrb.quat_G(q), jaxrb.quat_E(q)
    np.testing.assert_allclose(G @ G.T, jnp.eye(3), atol=1e-14)  # rows orthonormal
    np.testing.assert_allclose(E @ E.T, jnp.eye(3), atol=1e-14)
    np.testing.assert_allclose(E @ G.T, jaxrb.quat_to_matrix(q), atol=1e-14)  # R = E G^T
    np.testing.assert_allclose(G @ q, 0.0, atol=1e-15)
    np.testing.assert_allclose(E @ q, 0.0, atol=1e-15)


def test_batched_jit_and_grad():
    ts = jnp.linspace(0.0, 2.0, 5)
    qs = jax.vmap(attitude)(ts)
    q_dots = jax.vmap(jax.jacfwd(attitude))(ts)
    w = jaxrb.omega_body_from_quat_rate(qs, q_dots)  # leading batch axis
    assert w.shape == (5, 3)
    np.testing.assert_allclose(jax.jit(jaxrb.omega_body_from_quat_rate)(qs, q_dots), w)
    np.testing.assert_allclose(jaxrb.quat_rate(qs, w), q_dots, atol=1e-13)
    # gradients are finite at the identity with zero rate
    g = jax.grad(lambda q: jnp.sum(jaxrb.quat_rate(q, jnp.ones(3)) ** 2))(jnp.array([1.0, 0, 0, 0]))
    assert np.all(np.isfinite(g))


def test_bad_shapes_name_the_argument():
    with pytest.raises(ValueError, match="q_dot|q"):
        jaxrb.omega_body_from_quat_rate(jnp.ones(4), jnp.ones(3))
    with pytest.raises(ValueError, match="omega"):
        jaxrb.quat_rate(jnp.ones(4), jnp.ones(4))
