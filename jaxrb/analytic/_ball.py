"""A ball dropped (or thrown straight up) onto a floor with coefficient of restitution e.

No spin, no drag: the ball's lowest point moves on parabolas under gravity g and Newton's
impact law v' = -e v at the floor (docs/theory.md, section 8). Heights (m) are of the
lowest point above the floor, times in s, velocities in m/s (positive up). All functions are
jittable and differentiable with respect to h0, restitution, v0 and g; every argument
broadcasts over leading batch axes.

Derivation. The first impact speed is u1 = sqrt(v0^2 + 2 g h0), reached at
t1 = (v0 + u1) / g. After the k-th impact the ball leaves at e^k u1 and flies for
2 e^k u1 / g, so the n-th impact is at t_n = t1 + (2 u1 / g) sum_{k=1}^{n-1} e^k and the apex
after the k-th bounce is e^(2k) u1^2 / (2 g) = e^(2k) h_top, h_top = h0 + v0^2 / (2 g).
The flights sum to the Zeno time t_rest = t1 + 2 u1 e / (g (1 - e)) (t1 (1 + e) / (1 - e) for
v0 = 0), after which the ball lies on the floor; for e = 1 it never comes to rest (inf).
Gradients with respect to h0 are singular where u1 = 0 (h0 = v0 = 0: the ball starts at rest
on the floor).
"""

import jax.numpy as jnp

from .._typing import Array, ArrayLike

__all__ = ["ball_apex_heights", "ball_height", "ball_impact_times", "ball_rest_time"]


def _count(n, name: str) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"{name} must be a Python int >= 1 (a static count), got {n!r}")
    return n


def _first_impact(h0, v0, g):
    """(u1, t1): speed and time of the first impact."""
    u1 = jnp.sqrt(v0 * v0 + 2.0 * g * h0)
    return u1, (v0 + u1) / g


def _powers(e, n: int) -> Array:
    """e^1 ... e^n along a new last axis (products only: differentiable at e = 0)."""
    e = jnp.asarray(e)
    return jnp.cumprod(jnp.broadcast_to(e[..., None], e.shape + (n,)), axis=-1)


def _params(*xs) -> list[Array]:
    """Float arrays (ints become the default float), broadcast together."""
    out = []
    for x in xs:
        a = jnp.asarray(x)
        if not jnp.issubdtype(a.dtype, jnp.floating):
            a = a.astype(jnp.result_type(float))
        out.append(a)
    return jnp.broadcast_arrays(*out)


def _impacts(h0, e, g, v0, n: int):
    """Impact times (..., n) and rebound speeds (..., n) after each impact."""
    u1, t1 = _first_impact(h0, v0, g)
    p = _powers(e, n)
    partial = jnp.concatenate([jnp.zeros_like(p[..., :1]), jnp.cumsum(p[..., :-1], axis=-1)], -1)
    times = t1[..., None] + (2.0 * u1 / g)[..., None] * partial
    return times, u1[..., None] * p


def ball_impact_times(
    h0: ArrayLike, restitution: ArrayLike, n: int, g: ArrayLike = 9.81, v0: ArrayLike = 0.0
) -> Array:
    """Times (s) of the first `n` impacts: t_1 = (v0 + u1) / g, t_(k+1) - t_k = 2 e^k u1 / g.

    **Arguments:**

    - `h0`: initial height (m) of the ball's lowest point above the floor, >= 0.
    - `restitution`: e in [0, 1].
    - `n`: how many impacts (static Python int >= 1).
    - `g`: gravity (m/s^2).
    - `v0`: initial upward velocity (m/s); 0 for a drop.

    **Returns:** shape (..., n), the batch shape being that of the broadcast arguments.
    """
    n = _count(n, "n")
    h0, e, g, v0 = _params(h0, restitution, g, v0)
    return _impacts(h0, e, g, v0, n)[0]


def ball_apex_heights(
    h0: ArrayLike, restitution: ArrayLike, n: int, g: ArrayLike = 9.81, v0: ArrayLike = 0.0
) -> Array:
    """Apex heights (m) after each of the first `n` bounces: e^(2k) h_top, k = 1..n,
    h_top = h0 + v0^2 / (2 g).

    **Arguments:** as `ball_impact_times`.

    **Returns:** shape (..., n).
    """
    n = _count(n, "n")
    h0, e, g, v0 = _params(h0, restitution, g, v0)
    h_top = h0 + v0 * v0 / (2.0 * g)
    p = _powers(e, n)
    return h_top[..., None] * p * p


def ball_rest_time(
    h0: ArrayLike, restitution: ArrayLike, g: ArrayLike = 9.81, v0: ArrayLike = 0.0
) -> Array:
    """Zeno time (s) at which the bounces accumulate: t1 + 2 u1 e / (g (1 - e)).

    For a drop (v0 = 0) this is t1 (1 + e) / (1 - e); inf for e = 1.

    **Arguments:** as `ball_impact_times` (no `n`).

    **Returns:** shape (...).
    """
    h0, e, g, v0 = _params(h0, restitution, g, v0)
    u1, t1 = _first_impact(h0, v0, g)
    return t1 + 2.0 * u1 * e / (g * (1.0 - e))


def ball_height(
    t: ArrayLike,
    h0: ArrayLike,
    restitution: ArrayLike,
    g: ArrayLike = 9.81,
    v0: ArrayLike = 0.0,
    max_bounces: int = 100,
) -> Array:
    """Height (m) of the ball's lowest point at times `t` (s, from release at t = 0).

    h0 + v0 t - g t^2 / 2 before the first impact; e^k u1 s - g s^2 / 2 with s = t - t_k
    between the k-th and (k+1)-th impacts; 0 from the Zeno time `ball_rest_time` on. The
    first `max_bounces` impacts are modelled exactly; later bounces (all of apex at most
    e^(2 max_bounces + 2) h_top) are replaced by rest on the floor.

    **Arguments:**

    - `t`: times (s), broadcast with the other arguments.
    - `h0`, `restitution`, `g`, `v0`: as `ball_impact_times`.
    - `max_bounces`: static Python int >= 1, the number of impacts modelled exactly.

    **Returns:** heights (m), the broadcast shape of all arguments.
    """
    nb = _count(max_bounces, "max_bounces")
    t, h0, e, g, v0 = _params(t, h0, restitution, g, v0)
    times, speeds = _impacts(h0, e, g, v0, nb)
    n_hit = jnp.sum(times <= t[..., None], axis=-1)
    idx = jnp.clip(n_hit - 1, 0, nb - 1)[..., None]
    tk = jnp.take_along_axis(times, idx, axis=-1)[..., 0]
    vk = jnp.take_along_axis(speeds, idx, axis=-1)[..., 0]
    s = t - tk
    bounce = vk * s - 0.5 * g * s * s
    bounce = jnp.where(bounce > 0, bounce, jnp.zeros_like(bounce))
    flight = h0 + v0 * t - 0.5 * g * t * t
    h = jnp.where(n_hit == 0, flight, bounce)
    t_rest = ball_rest_time(h0, e, g, v0)
    return jnp.where(t >= t_rest, jnp.zeros_like(h), h)
