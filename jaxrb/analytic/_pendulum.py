"""The fixed-axis pendulum sample problem (docs/theory.md, section 6): exact motion and
bearing force.

A rigid body turns about a fixed horizontal axis through O; its mass centre C is at distance
`r` (m) from O and its radius of gyration about the axis is `k_O` (m), so J_O = m k_O^2 and
k_O^2 = k_C^2 + r^2 >= r^2. It is released from rest with OC horizontal (theta = 0); theta (rad)
is measured downward from that horizontal, in the direction the body falls. Units SI.

Unit vectors in the plane of motion: e_n along the pendulum from C towards O, e_t
perpendicular to it in the direction of increasing theta. Then a_C = r w^2 e_n + r alpha e_t,
gravity has components m g sin(theta) along -e_n and m g cos(theta) along e_t.
"""

import dataclasses
import math

import jax.numpy as jnp

from .._typing import Array, ArrayLike
from ._elliptic import ellipj

__all__ = [
    "PendulumParams",
    "SAMPLE_PENDULUM",
    "pendulum_angular_acceleration",
    "pendulum_angular_velocity_squared",
    "pendulum_bearing_force",
    "pendulum_period",
    "pendulum_theta",
    "pendulum_theta_dot",
]


@dataclasses.dataclass(frozen=True)
class PendulumParams:
    """Parameters of the fixed-axis pendulum: mass (kg), r = |OC| (m), k_O (m), g (m/s^2)."""

    mass: float
    r: float
    k_O: float
    g: float = 9.81


SAMPLE_PENDULUM = PendulumParams(mass=7.5, r=0.25, k_O=0.295)
"""The sample problem of docs/theory.md, section 6: m = 7.5 kg, r = 0.25 m, k_O = 0.295 m,
g = 9.81 m/s^2."""


def pendulum_angular_acceleration(
    theta: ArrayLike, r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81
) -> Array:
    """alpha = theta_ddot = g r cos(theta) / k_O^2 (rad/s^2), from J_O alpha = m g r cos(theta).

    **Arguments:** `theta` (rad, measured downward from the horizontal), `r` (m), `k_O` (m),
    `g` (m/s^2); all broadcast.

    **Returns:** the angular acceleration (rad/s^2).
    """
    return g * r * jnp.cos(theta) / (k_O * k_O)


def pendulum_angular_velocity_squared(
    theta: ArrayLike, r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81
) -> Array:
    """w^2 = 2 g r sin(theta) / k_O^2 (rad^2/s^2), energy conservation from rest at theta = 0.

    **Arguments:** as `pendulum_angular_acceleration`.

    **Returns:** the squared angular velocity (rad^2/s^2).
    """
    return 2.0 * g * r * jnp.sin(theta) / (k_O * k_O)


def pendulum_bearing_force(
    theta: ArrayLike, mass: ArrayLike, r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81
) -> tuple[Array, Array, Array]:
    """The force (N) the bearing at O exerts on the body, at angle theta.

    Newton's law for the mass centre, m a_C = m g + O, in components:

    - along e_n (C towards O): m r w^2 = -m g sin(theta) + On, so
      On = m g (1 + 2 r^2 / k_O^2) sin(theta), positive towards O;
    - along e_t (increasing theta): m r alpha = m g cos(theta) - Ot, so
      Ot = m g (1 - r^2 / k_O^2) cos(theta), positive in the direction OPPOSITE to increasing
      theta (the bearing force is On e_n - Ot e_t). Since k_O >= r, Ot >= 0 for theta in
      [0, pi/2] (the bearing holds back the falling body) and Ot <= 0 for theta in [pi/2, pi].

    **Arguments:** `theta` (rad, downward from the horizontal), `mass` (kg), `r` (m), `k_O` (m),
    `g` (m/s^2); all broadcast.

    **Returns:** `(On, Ot, magnitude)` in N, magnitude = sqrt(On^2 + Ot^2).
    """
    ratio = (r * r) / (k_O * k_O)
    mg = mass * g
    On = mg * (1.0 + 2.0 * ratio) * jnp.sin(theta)
    Ot = mg * (1.0 - ratio) * jnp.cos(theta)
    return On, Ot, jnp.sqrt(On * On + Ot * Ot)


_M = 0.5  # elliptic parameter m = sin^2(amplitude / 2), amplitude pi/2 about the vertical
_K_HALF = 1.8540746773013719  # K(1/2) = scipy.special.ellipk(0.5) (a constant: no jax at import)


def _omega0(r, k_O, g):
    return jnp.sqrt(g * r / (k_O * k_O))


def pendulum_period(r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81) -> Array:
    """Period (s) of the swing theta: 0 -> pi -> 0: 4 K(1/2) / omega0, omega0^2 = g r / k_O^2."""
    return 4.0 * _K_HALF / _omega0(r, k_O, g)


def pendulum_theta(t: ArrayLike, r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81) -> Array:
    """Exact angle theta(t) (rad, downward from the horizontal) after release from rest at 0.

    With phi = pi/2 - theta the angle from the downward vertical, phi_ddot = -omega0^2 sin(phi),
    omega0^2 = g r / k_O^2: a pendulum of amplitude pi/2, so (Jacobi elliptic functions with
    parameter m = sin^2(pi/4) = 1/2) sin(phi/2) = k cn(u)/dn(u), cos(phi/2) = k'/dn(u) with
    u = omega0 t and k = k' = 1/sqrt(2), i.e. phi = 2 arctan(cn(omega0 t | 1/2)). theta swings
    between 0 and pi with period `pendulum_period`.

    **Arguments:** `t` (s), `r` (m), `k_O` (m), `g` (m/s^2); all broadcast.

    **Returns:** theta (rad).
    """
    u = _omega0(r, k_O, g) * t
    _, cn, _ = ellipj(u, _M)
    return 0.5 * math.pi - 2.0 * jnp.arctan(cn)


def pendulum_theta_dot(t: ArrayLike, r: ArrayLike, k_O: ArrayLike, g: ArrayLike = 9.81) -> Array:
    """Exact angular velocity theta_dot(t) (rad/s): 2 omega0 sn dn / (1 + cn^2), u = omega0 t.

    **Arguments:** as `pendulum_theta`.

    **Returns:** theta_dot (rad/s); positive for the first half swing (0 < u < 2 K(1/2)).
    """
    w0 = _omega0(r, k_O, g)
    sn, cn, dn = ellipj(w0 * t, _M)
    return 2.0 * w0 * sn * dn / (1.0 + cn * cn)
