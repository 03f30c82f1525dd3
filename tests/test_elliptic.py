"""Jacobi elliptic functions, K(m) and F(phi | m) in jnp vs scipy, mpmath and identities."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special as ss

from jaxrb.analytic import (
    ellip_amplitude,
    ellip_inc_f,
    ellip_inc_f_m1,
    ellipj,
    ellipj_m1,
    ellipk,
    ellipk_m1,
)

mpmath = pytest.importorskip("mpmath", reason="mpmath is the high-precision reference")

_ellipj_m1 = jax.jit(ellipj_m1)
_ellipj = jax.jit(ellipj)


def _mp_sncndn(u, m1):
    with mpmath.workdps(max(40, int(-np.log10(m1)) + 30)):
        m = 1 - mpmath.mpf(m1)
        return [float(mpmath.ellipfun(f, mpmath.mpf(u), m=m)) for f in ("sn", "cn", "dn")]


def test_ellipk_vs_scipy_and_mpmath():
    m = np.linspace(0.0, 0.999, 200)
    np.testing.assert_allclose(jax.jit(ellipk)(m), ss.ellipk(m), rtol=2e-15)
    for m1 in [0.3, 1e-6, 1e-12, 1e-30, 1e-300]:
        with mpmath.workdps(max(40, int(-np.log10(m1)) + 30)):
            ref = float(mpmath.ellipk(1 - mpmath.mpf(m1)))
        assert float(ellipk_m1(m1)) == pytest.approx(ref, rel=1e-15)
    assert float(ellipk_m1(0.0)) == np.inf
    assert float(ellipk(0.0)) == pytest.approx(np.pi / 2, rel=1e-16)


def test_ellipj_vs_scipy():
    m = np.linspace(0.0, 0.99, 23)[:, None]
    u = np.linspace(-30.0, 30.0, 61)[None, :]
    sn, cn, dn = _ellipj(u, m)
    r = ss.ellipj(u, m)
    for a, b in zip((sn, cn, dn), r[:3], strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=5e-14)
    np.testing.assert_allclose(ellip_amplitude(u, m), r[3], rtol=0, atol=5e-14)


@pytest.mark.parametrize("m1", [0.5, 1e-6, 1e-10, 1e-12, 1e-300])
def test_ellipj_m1_near_separatrix_vs_mpmath(m1):
    K = float(ellipk_m1(m1))
    u = np.concatenate([np.linspace(1e-3, 4 * K, 29), [1e-9, 0.5 * K, 0.999999 * K, 7.3 * K]])
    sn, cn, dn = (np.asarray(a) for a in _ellipj_m1(u, np.full_like(u, m1)))
    ref = np.array([_mp_sncndn(x, m1) for x in u])
    # absolute error ~ eps (1 + u / K); relative error of cn, dn small even where they are tiny
    assert np.max(np.abs(np.stack([sn, cn, dn], -1) - ref)) < 5e-14
    big = np.abs(ref[:, 1]) > 1e-7
    assert np.max(np.abs(cn[big] / ref[big, 1] - 1)) < 1e-9
    assert np.max(np.abs(dn / ref[:, 2] - 1)) < 1e-12


def test_ellipj_large_u_near_separatrix_vs_mpmath():
    u = np.array([100.3, 517.25, 1234.5])
    for m1 in [1e-6, 1e-10]:
        sn, cn, dn = (np.asarray(a) for a in _ellipj_m1(u, np.full_like(u, m1)))
        ref = np.array([_mp_sncndn(x, m1) for x in u])
        np.testing.assert_allclose(np.stack([sn, cn, dn], -1), ref, rtol=0, atol=1e-12)


def test_identities_and_limits():
    u = jnp.linspace(-50.0, 50.0, 101)[:, None]
    m1 = jnp.array([1.0, 0.7, 0.1, 1e-4, 1e-9, 1e-14, 0.0])[None, :]
    sn, cn, dn = _ellipj_m1(u, m1)
    m = 1.0 - m1
    np.testing.assert_allclose(sn**2 + cn**2, 1.0, atol=4e-16 * 4)
    np.testing.assert_allclose(dn**2 + m * sn**2, 1.0, atol=4e-16 * 4)
    # m = 0: circular functions; m = 1: hyperbolic
    np.testing.assert_allclose(sn[:, 0], jnp.sin(u[:, 0]), atol=1e-14)
    np.testing.assert_allclose(sn[:, -1], jnp.tanh(u[:, 0]), atol=1e-16)
    np.testing.assert_allclose(cn[:, -1], 1 / jnp.cosh(u[:, 0]), atol=1e-16)
    # periodicity 4K and half-period sign change
    K = ellipk_m1(m1[0, 1:-1])
    s1, c1, d1 = _ellipj_m1(0.3 + 2 * K, m1[0, 1:-1])
    s0, c0, d0 = _ellipj_m1(0.3 + 0 * K, m1[0, 1:-1])
    np.testing.assert_allclose(s1, -s0, atol=1e-14)
    np.testing.assert_allclose(c1, -c0, atol=1e-14)
    np.testing.assert_allclose(d1, d0, atol=1e-14)


def test_derivatives_vs_finite_differences():
    u = jnp.linspace(-7.0, 9.0, 17)
    h = 1e-6
    fwd = jax.jit(jax.vmap(jax.jacfwd(ellipj_m1, argnums=(0, 1))))
    rev = jax.jit(jax.vmap(jax.jacrev(lambda x, y: jnp.stack(ellipj_m1(x, y)))))
    for m1 in [0.6, 1e-3, 1e-8]:
        mm = jnp.full_like(u, m1)
        jac = fwd(u, mm)
        jac_rev = rev(u, mm)
        plus = jnp.stack(_ellipj_m1(u + h, mm))
        minus = jnp.stack(_ellipj_m1(u - h, mm))
        fd_u = (plus - minus) / (2 * h)
        np.testing.assert_allclose(jnp.stack([j[0] for j in jac]), fd_u, atol=1e-8)
        np.testing.assert_allclose(jac_rev.T, fd_u, atol=1e-8)
        sn, cn, dn = _ellipj_m1(u, mm)
        np.testing.assert_allclose(jac[0][0], cn * dn, atol=1e-15)
        np.testing.assert_allclose(jac[1][0], -sn * dn, atol=1e-15)
        np.testing.assert_allclose(jac[2][0], -(1 - m1) * sn * cn, atol=1e-15)
        # m1 derivative (AD through the algorithm) vs central differences in m1; at m1 = 1e-8
        # central differences cannot resolve it (step ~ m1 needed), so only the u part is checked
        if m1 < 1e-4:
            continue
        hm = 1e-7 * m1
        fd_m = (jnp.stack(_ellipj_m1(u, mm + hm)) - jnp.stack(_ellipj_m1(u, mm - hm))) / (2 * hm)
        scale = 1 + jnp.abs(fd_m)
        assert float(jnp.max(jnp.abs(jnp.stack([j[1] for j in jac]) - fd_m) / scale)) < 1e-5


def test_inc_f_inverts_amplitude():
    m = np.array([0.0, 0.3, 0.9, 0.99])[:, None]
    phi = np.linspace(-1.4, 1.4, 15)[None, :]
    np.testing.assert_allclose(jax.jit(ellip_inc_f)(phi, m), ss.ellipkinc(phi, m), rtol=1e-14)
    # beyond pi/2 and near the separatrix: F(am(u)) = u
    for m1 in [0.4, 1e-6, 1e-12]:
        u = jnp.linspace(-20.0, 20.0, 41)
        am = ellip_amplitude(u, 1.0 - m1) if m1 > 1e-3 else None
        if am is not None:
            np.testing.assert_allclose(ellip_inc_f_m1(am, m1), u, atol=1e-13)
        with mpmath.workdps(50):
            ref = float(mpmath.ellipf(mpmath.mpf(1.2), 1 - mpmath.mpf(m1)))
        assert float(ellip_inc_f_m1(1.2, m1)) == pytest.approx(ref, rel=1e-14)


def test_float32_and_vmap():
    u = jnp.linspace(0.0, 20.0, 41, dtype=jnp.float32)
    m1 = jnp.float32(1e-4)
    sn, cn, dn = ellipj_m1(u, m1)
    assert sn.dtype == jnp.float32
    r = ss.ellipj(np.asarray(u, np.float64), 1 - 1e-4)
    np.testing.assert_allclose(sn, r[0], atol=3e-5)
    np.testing.assert_allclose(dn, r[2], atol=3e-5)
    assert ellipk_m1(m1).dtype == jnp.float32
    batched = jax.vmap(ellipj_m1, in_axes=(None, 0))(
        jnp.linspace(0.0, 3.0, 4), jnp.array([0.5, 0.1])
    )
    assert batched[0].shape == (2, 4)
    np.testing.assert_allclose(
        batched[2][1], _ellipj_m1(jnp.linspace(0.0, 3.0, 4), 0.1)[2], atol=1e-15
    )
