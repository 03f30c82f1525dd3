"""Exact flow of a torque-free rigid body with three distinct principal moments.

No time stepping: the state at any time t is evaluated directly, at a cost independent of t.

- Angular velocity: exact, Jacobi elliptic functions (`jaxrb.analytic.asymmetric_top`).
- Attitude: with the world angular momentum L fixed, write the body's attitude as 3-1-3 Euler
  angles relative to a world frame whose z axis is along L, about body axes (i, j, p) where the
  polar axis p is the largest- or the smallest-moment axis, whichever L stays farther from over
  a period (from the extremes of the elliptic functions), so the nutation angle theta stays
  away from its singular values 0 and pi (for a needle-like body with I1 << I2 < I3 this is
  axis 1, not the axis the motion circulates about). Then
  theta and phi follow algebraically from L_body = J omega(t):
      L_body / |L| = (sin theta sin phi, sin theta cos phi, cos theta),
  and the precession angle obeys
      psi_dot = |L| (I_i w_i^2 + I_j w_j^2) / (I_i^2 w_i^2 + I_j^2 w_j^2),
  a positive function of the elliptic phase u = omega_p t + u0 with period 2K(m). Its integral
  is evaluated spectrally: `n_fourier` samples over one period give the Fourier coefficients
  (the trapezoid rule is exponentially accurate for periodic analytic functions), and the
  antiderivative of the series is evaluated at u(t) (secular part + bounded periodic part, the
  phase reduced modulo the period). This is the "cheap accurate" route instead of the closed
  form with incomplete elliptic integrals of the third kind / theta functions (van Zon &
  Schofield 2007): the error is at round-off level for ordinary bodies with the default 64
  samples and degrades only near the separatrix (m -> 1), where psi_dot has sharp peaks of
  width ~1 in u while the period 2K grows like ln(16 / m1); raise `n_fourier` there
  (tests/test_hard_cases.py uses 256 at m1 ~ 1e-8; 64 is not enough there).

Quaternions scalar first, body -> world; omega in the body frame (rad/s); SI units.
Translation is free flight: pos(t) = pos0 + vel0 t.
"""

import functools

import jax
import jax.numpy as jnp

from ._quaternion import matrix_to_quat, quat_conjugate, quat_multiply, quat_normalize
from ._state import State
from .analytic._elliptic import ellipj_m1, ellipk_m1
from .analytic._tops import asymmetric_top_params


def _qz(a):
    z = jnp.zeros_like(a)
    return jnp.stack([jnp.cos(0.5 * a), z, z, jnp.sin(0.5 * a)], -1)


def _qx(a):
    z = jnp.zeros_like(a)
    return jnp.stack([jnp.cos(0.5 * a), jnp.sin(0.5 * a), z, z], -1)


def _single(inertia, quat0, omega0, t, n_fourier):
    """One body: (omega (T..., 3), quat (T..., 4)) at times t (any shape)."""
    dtype = omega0.dtype
    p = asymmetric_top_params(inertia, omega0)
    S = p.perm
    eye = jnp.eye(3, dtype=dtype)
    cyc = jnp.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], dtype=dtype)
    a1, a2, a3 = p.amplitudes
    I_s = jnp.abs(S) @ inertia  # sorted moments
    r1 = jnp.sqrt(p.m1)
    # L_sorted where sn = 0 and where sn = 1 (the extremes of every component over a period)
    w_sn0 = jnp.stack([a1, 0.0 * a2, a3])
    w_sn1 = jnp.where(
        p.about_axis3, jnp.stack([0.0 * a1, a2, a3 * r1]), jnp.stack([a1 * r1, a2, 0.0 * a3])
    )
    L_ext = jnp.stack([I_s * w_sn0, I_s * w_sn1])
    L2_tot = jnp.sum(L_ext[0] ** 2)
    # polar axis: sorted axis 3 or 1, whichever L stays farther from (largest min |L_perp|)
    perp3 = jnp.min(L2_tot - L_ext[:, 2] ** 2)
    perp1 = jnp.min(L2_tot - L_ext[:, 0] ** 2)
    polar1 = perp1 > perp3
    cyc_s = jnp.where(polar1, cyc, eye)  # sorted -> (i, j, p)
    P = cyc_s @ S  # body -> body' = (i, j, p) axes, det +1
    I_b = jnp.abs(P) @ inertia  # moments about the body' axes

    def omega_sorted(u):
        sn, cn, dn = ellipj_m1(u, jnp.broadcast_to(p.m1, u.shape))
        return jnp.where(
            p.about_axis3,
            jnp.stack([a1 * cn, a2 * sn, a3 * dn], -1),
            jnp.stack([a1 * dn, a2 * sn, a3 * cn], -1),
        )

    def omega_primed(u):  # components on (i, j, p)
        return omega_sorted(u) @ cyc_s.T

    L_vec0 = I_b * (P @ omega0)
    L_norm = jnp.sqrt(jnp.sum(L_vec0 * L_vec0))

    def psi_rate(u):
        w = omega_primed(u)
        num = I_b[0] * w[..., 0] ** 2 + I_b[1] * w[..., 1] ** 2
        den = (I_b[0] * w[..., 0]) ** 2 + (I_b[1] * w[..., 1]) ** 2
        ok = den > 0
        return jnp.where(ok, L_norm * num / jnp.where(ok, den, 1.0), L_norm / I_b[2])

    def angles(w):
        L = I_b * w
        theta = jnp.arctan2(jnp.sqrt(L[..., 0] ** 2 + L[..., 1] ** 2), L[..., 2])
        phi = jnp.arctan2(L[..., 0], L[..., 1])
        return theta, phi

    # Fourier series of psi_rate over one period 2K of u (n_fourier samples, trapezoid rule).
    K = ellipk_m1(jnp.maximum(p.m1, jnp.finfo(dtype).tiny))
    period = 2.0 * K
    M = n_fourier
    s = jnp.arange(M, dtype=dtype) * (period / M)
    f = psi_rate(p.u0 + s)
    c = jnp.fft.rfft(f) / M
    n = jnp.arange(1, c.shape[0], dtype=dtype)
    an = 2.0 * jnp.real(c[1:])
    bn = -2.0 * jnp.imag(c[1:])
    if M % 2 == 0:  # the Nyquist term is cos-only with weight 1, and integrates to ~0: drop it
        an = an.at[-1].set(0.0)
        bn = bn.at[-1].set(0.0)
    a0 = jnp.real(c[0])
    k = 2.0 * jnp.pi / period

    t = jnp.asarray(t, dtype)
    delta = p.frequency * t  # phase advance u(t) - u0 (signed)
    r = delta - period * jnp.floor(delta / period)  # reduced to [0, period)
    nk = n * k
    periodic = jnp.sum(
        an * jnp.sin(nk * r[..., None]) / nk + bn * (1.0 - jnp.cos(nk * r[..., None])) / nk, -1
    )
    integral = a0 * delta + periodic
    freq_safe = jnp.where(p.frequency != 0, p.frequency, 1.0)
    psi = jnp.where(p.frequency != 0, integral / freq_safe, (L_norm / I_b[2]) * t)

    w_t = omega_primed(p.u0 + delta)
    theta, phi = angles(w_t)
    theta0, phi0 = angles(P @ omega0)
    q313 = quat_multiply(quat_multiply(_qz(psi), _qx(theta)), _qz(phi))
    q313_0 = quat_multiply(_qx(theta0), _qz(phi0))
    qP = matrix_to_quat(P)
    qW = quat_multiply(
        quat_multiply(quat_normalize(quat0), quat_conjugate(qP)), quat_conjugate(q313_0)
    )
    quat = quat_multiply(quat_multiply(qW, q313), qP)
    omega = w_t @ P  # body components = P^T omega'
    return omega, quat


def torque_free_flow(inertia, state: State, t, *, n_fourier: int = 64) -> State:
    """The exact torque-free motion of a free body from `state` after time `t`.

    **Arguments:**

    - `inertia`: principal moments (I1, I2, I3) about the body axes (kg m^2), shape (3,),
      three distinct values (for equal moments use `jaxrb.analytic.symmetric_top` /
      `spherical_top`).
    - `state`: a `State`, leaves with any leading batch shape B (quat body -> world).
    - `t`: elapsed time(s) (s), a scalar or an array of shape Tt.
    - `n_fourier`: samples per period for the spectral precession-angle integral (static).

    **Returns:** a `State` with leaves of shape B + Tt + (k,): pos0 + vel0 t, quat (unit),
    vel0, omega (body frame). jit / vmap / grad safe.
    """
    return _flow(jnp.asarray(inertia), state, jnp.asarray(t), n_fourier)


@functools.partial(jax.jit, static_argnums=3)
def _flow(inertia, state, t, n_fourier):
    batch = state.omega.shape[:-1]
    dtype = state.omega.dtype
    inertia = inertia.astype(dtype)
    t = jnp.asarray(t, dtype)
    flat = lambda x: x.reshape((-1,) + x.shape[len(batch) :])  # noqa: E731
    quat0, omega0 = flat(jnp.broadcast_to(state.quat, batch + (4,))), flat(state.omega)
    fn = lambda q, w: _single(inertia, q, w, t, n_fourier)  # noqa: E731
    omega, quat = jax.vmap(fn)(quat0, omega0)
    omega = omega.reshape(batch + t.shape + (3,))
    quat = quat.reshape(batch + t.shape + (4,))
    expand = lambda x: jnp.broadcast_to(x, batch + (3,))[..., *([None] * t.ndim), :]  # noqa: E731
    pos = expand(state.pos) + expand(state.vel) * t[..., None]
    vel = jnp.broadcast_to(expand(state.vel), pos.shape)
    return State(pos=pos, quat=quat, vel=vel, omega=omega)
