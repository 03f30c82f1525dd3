"""Complete elliptic integral K, Jacobi elliptic functions sn, cn, dn, and F(phi | m), in jnp.

`jax.scipy.special` has none of these. Everything here uses a fixed number of iterations (no
data-dependent Python loops), so it is jit / vmap friendly, and works in float32 and float64.

Parameter convention (as scipy): `m = k^2` in [0, 1]. Every function has a variant taking the
complementary parameter `m1 = 1 - m` directly, which keeps full relative accuracy near the
separatrix m -> 1 (m1 down to the smallest normal float), where `1 - m` would cancel.

Algorithms:
- K(m) = pi / (2 AGM(1, sqrt(m1))) (arithmetic-geometric mean, A&S 17.6).
- sn, cn, dn: the argument is reduced modulo the period 2K (sn, cn change sign), folded into
  [0, K/2] with the quarter-period identities sn(K - x) = cd x, cn(K - x) = sqrt(m1) sd x,
  dn(K - x) = sqrt(m1) nd x, and evaluated by Bulirsch's descending Gauss/Landen recursion
  (R. Bulirsch, Numer. Math. 7 (1965) 78), which works with ratios (cs, dn) so every result has
  small relative error, including the small cn and dn near u = K when m1 is tiny.
- F(phi | m) = sin(phi) R_F(cos^2 phi, 1 - m sin^2 phi, 1) with Carlson's duplication
  (B. C. Carlson, Numer. Algorithms 10 (1995) 13), continued by F(phi + pi) = F(phi) + 2K.

Derivatives: `ellipj` / `ellipj_m1` have a `jax.custom_jvp` whose u-derivatives are the exact
identities sn' = cn dn, cn' = -sn dn, dn' = -m sn cn (cheap, exact, also at large u). The
derivative with respect to m (or m1) is obtained by forward-mode differentiation through the
fixed-iteration algorithm (correct but not specially tuned; infinite at m1 = 0).
"""

import math

import jax
import jax.numpy as jnp

from .._typing import Array, ArrayLike


def _as_float(x: ArrayLike) -> Array:
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    return x


def _n_levels(dtype) -> int:
    # AGM levels needed from b0 = sqrt(smallest normal) to convergence, plus a safety margin
    # (11 for float64, 8 for float32 are enough; computed once, see tests).
    return 14 if jnp.finfo(dtype).bits > 32 else 10


def _agm(m1: Array, n: int) -> Array:
    """AGM(1, sqrt(m1)) with n fixed steps."""

    def body(_, ab):
        a, b = ab
        return 0.5 * (a + b), jnp.sqrt(a * b)

    a, _ = jax.lax.fori_loop(0, n, body, (jnp.ones_like(m1), jnp.sqrt(m1)))
    return a


def _agm_levels(m1: Array, n: int):
    """Descending AGM from (1, sqrt(m1)): stacked a_0..a_{n-1}, b_0..b_{n-1}, and a_n."""

    def body(ab, _):
        a, b = ab
        return (0.5 * (a + b), jnp.sqrt(a * b)), (a, b)

    (a, _), (aa, bb) = jax.lax.scan(body, (jnp.ones_like(m1), jnp.sqrt(m1)), None, length=n)
    return aa, bb, a


def ellipk_m1(m1: ArrayLike) -> Array:
    """Complete elliptic integral of the first kind K as a function of m1 = 1 - m.

    **Arguments:**

    - `m1`: complementary parameter in [0, 1] (any shape); K = inf at m1 = 0.

    **Returns:**

    K(1 - m1) = pi / (2 AGM(1, sqrt(m1))), same shape and dtype. Relative accuracy ~1e-16
    (float64) for every m1 in [tiny, 1].
    """
    m1 = _as_float(m1)
    k = (0.5 * math.pi) / _agm(m1, _n_levels(m1.dtype))
    return jnp.where(m1 > 0, k, jnp.inf)


def ellipk(m: ArrayLike) -> Array:
    """Complete elliptic integral of the first kind K(m), m = k^2 in [0, 1] (as scipy's ellipk).

    Near m = 1 the input itself limits accuracy; prefer `ellipk_m1(1 - m)` with m1 computed
    without cancellation.
    """
    m = _as_float(m)
    return ellipk_m1(1.0 - m)


def _sncndn_core(x: Array, m1: Array, n: int):
    """sn, cn, dn for 0 <= x <= K/2 (Bulirsch's recursion with n fixed levels), m1 > 0."""
    aa, bb, c = _agm_levels(m1, n)
    # Below sqrt(eps) the Taylor series is exact to rounding and avoids overflow of cot(x).
    small = x < jnp.sqrt(jnp.finfo(x.dtype).eps)
    xs = jnp.where(small, 1.0, x)
    y = xs * c
    a = jnp.cos(y) / jnp.sin(y)  # cot; y in (0, pi/4]
    c = c * a

    def body(carry, level):
        a, c, dn = carry
        b, bn = level
        a = a * c
        c = c * dn
        dn = (bn + a) / (b + a)
        return (c / b, c, dn), None

    (a, c, dn), _ = jax.lax.scan(body, (a, c, jnp.ones_like(x)), (aa, bb), reverse=True)
    # c = cs(x) = cn / sn
    sn = 1.0 / jnp.sqrt(c * c + 1.0)
    cn = c * sn
    m = 1.0 - m1
    x2 = x * x
    sn_t = x * (1.0 - (1.0 + m) * x2 / 6.0)
    cn_t = 1.0 - 0.5 * x2
    dn_t = 1.0 - 0.5 * m * x2
    return (
        jnp.where(small, sn_t, sn),
        jnp.where(small, cn_t, cn),
        jnp.where(small, dn_t, dn),
    )


def _ellipj_m1_impl(u: Array, m1: Array):
    n = _n_levels(u.dtype)
    at_one = m1 <= 0.0  # m = 1: sn = tanh, cn = dn = sech (K infinite)
    m1s = jnp.where(at_one, 1.0, m1)
    K = ellipk_m1(m1s)
    # u = 2K j + v, v in [-K, K]; sn and cn change sign with every half period 2K.
    j = jnp.round(u / (2.0 * K))
    v = u - j * (2.0 * K)
    odd = jnp.remainder(j, 2.0) != 0.0
    w = jnp.abs(v)
    upper = w > 0.5 * K
    x = jnp.where(upper, K - w, w)
    x = jnp.clip(x, 0.0, 0.5 * K)
    s, c, d = _sncndn_core(x, m1s, n)
    k1 = jnp.sqrt(m1s)
    sn_w = jnp.where(upper, c / d, s)
    cn_w = jnp.where(upper, k1 * s / d, c)
    dn_w = jnp.where(upper, k1 / d, d)
    sign = jnp.where(odd, -1.0, 1.0)
    sn = sign * jnp.where(v < 0, -sn_w, sn_w)
    cn = sign * cn_w
    # m = 1 limit
    sech = 1.0 / jnp.cosh(u)
    sn = jnp.where(at_one, jnp.tanh(u), sn)
    cn = jnp.where(at_one, sech, cn)
    dn = jnp.where(at_one, sech, dn_w)
    return sn, cn, dn


@jax.custom_jvp
def _ellipj_m1(u, m1):
    return _ellipj_m1_impl(u, m1)


@_ellipj_m1.defjvp
def _ellipj_m1_jvp(primals, tangents):
    u, m1 = primals
    du, dm1 = tangents
    (sn, cn, dn), (sn_m, cn_m, dn_m) = jax.jvp(lambda mm: _ellipj_m1_impl(u, mm), (m1,), (dm1,))
    m = 1.0 - m1
    return (sn, cn, dn), (
        cn * dn * du + sn_m,
        -sn * dn * du + cn_m,
        -m * sn * cn * du + dn_m,
    )


def ellipj_m1(u: ArrayLike, m1: ArrayLike) -> tuple[Array, Array, Array]:
    """Jacobi elliptic functions sn, cn, dn of argument u and complementary parameter m1 = 1 - m.

    **Arguments:**

    - `u`: argument (any shape, any size: reduced modulo the period first).
    - `m1`: complementary parameter 1 - m in [0, 1], broadcast against `u`. m1 = 0 gives the
      limit (tanh u, sech u, sech u).

    **Returns:**

    `(sn, cn, dn)`, each of the broadcast shape. Absolute error ~ eps (1 + |u| / K) in float64,
    with small relative error in cn and dn near u = K even for m1 ~ 1e-12 and smaller.
    Differentiable: exact u-derivatives (custom JVP), m1-derivatives by AD of the algorithm.
    """
    u = _as_float(u)
    m1 = _as_float(m1)
    u, m1 = jnp.broadcast_arrays(u, m1)
    return _ellipj_m1(u, m1)


def ellipj(u: ArrayLike, m: ArrayLike) -> tuple[Array, Array, Array]:
    """Jacobi elliptic functions (sn, cn, dn) of u with parameter m = k^2 in [0, 1].

    Same as `ellipj_m1(u, 1 - m)` (scipy.special.ellipj's parameter convention; scipy also
    returns the amplitude, see `ellip_amplitude`). Use `ellipj_m1` when m is within ~1e-6 of 1.
    """
    m = _as_float(m)
    return ellipj_m1(u, 1.0 - m)


def ellip_amplitude(u: ArrayLike, m: ArrayLike) -> Array:
    """Jacobi amplitude am(u | m) = atan2(sn, cn), continuous in u (am(u + 2K) = am(u) + pi)."""
    u = _as_float(u)
    m = _as_float(m)
    u, m = jnp.broadcast_arrays(u, m)
    K = ellipk(m)
    sn, cn, _ = ellipj(u, m)
    j = jnp.round(u / (2.0 * K))  # 0 where K = inf (m = 1)
    sign = jnp.where(jnp.remainder(j, 2.0) != 0.0, -1.0, 1.0)
    return jnp.arctan2(sign * sn, sign * cn) + j * math.pi


def carlson_rf(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> Array:
    """Carlson's symmetric integral R_F(x, y, z) = 1/2 int_0^inf dt / sqrt((t+x)(t+y)(t+z)).

    x, y, z >= 0, at most one zero. Fixed number of duplication steps (enough for float64 when
    the ratio of the arguments is up to ~1e300), then the fifth-order series.
    """
    x, y, z = (_as_float(a) for a in (x, y, z))
    x, y, z = jnp.broadcast_arrays(x, y, z)
    n = 26 if jnp.finfo(x.dtype).bits > 32 else 14

    def body(_, xyz):
        x, y, z = xyz
        sx, sy, sz = jnp.sqrt(x), jnp.sqrt(y), jnp.sqrt(z)
        lam = sx * sy + sx * sz + sy * sz
        return 0.25 * (x + lam), 0.25 * (y + lam), 0.25 * (z + lam)

    x, y, z = jax.lax.fori_loop(0, n, body, (x, y, z))
    mu = (x + y + z) / 3.0
    dx, dy, dz = 1.0 - x / mu, 1.0 - y / mu, 1.0 - z / mu
    e2 = dx * dy - dz * dz
    e3 = dx * dy * dz
    series = 1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0
    return series / jnp.sqrt(mu)


def _f_from_sncndn(sn: Array, cn: Array, dn2: Array, K: Array) -> Array:
    """u in (-2K, 2K] with sn(u) = sn, cn(u) = cn, given dn(u)^2 = dn2 (computed accurately)."""
    f = sn * carlson_rf(cn * cn, dn2, jnp.ones_like(cn))  # F of the angle in [-pi/2, pi/2]
    return jnp.where(cn >= 0, f, jnp.where(sn >= 0, 2.0 * K - f, -2.0 * K - f))


def ellip_inc_f_m1(phi: ArrayLike, m1: ArrayLike) -> Array:
    """Incomplete elliptic integral of the first kind F(phi | m) with m1 = 1 - m given directly.

    **Arguments:**

    - `phi`: amplitude (rad), any real value; F(phi + k pi) = F(phi) + 2 k K.
    - `m1`: complementary parameter in (0, 1].

    **Returns:**

    F(phi | 1 - m1) = int_0^phi dtheta / sqrt(1 - m sin^2 theta), the inverse of am(., m).
    """
    phi = _as_float(phi)
    m1 = _as_float(m1)
    phi, m1 = jnp.broadcast_arrays(phi, m1)
    j = jnp.round(phi / math.pi)
    r = phi - j * math.pi  # in [-pi/2, pi/2]
    s, c = jnp.sin(r), jnp.cos(r)
    dn2 = m1 * s * s + c * c  # = 1 - m sin^2 r without cancellation
    K = ellipk_m1(m1)
    f = s * carlson_rf(c * c, dn2, jnp.ones_like(r))
    return f + 2.0 * j * K


def ellip_inc_f(phi: ArrayLike, m: ArrayLike) -> Array:
    """Incomplete elliptic integral of the first kind F(phi | m) (as scipy.special.ellipkinc)."""
    m = _as_float(m)
    return ellip_inc_f_m1(phi, 1.0 - m)
