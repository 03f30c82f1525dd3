"""Programs with a derivative through an event time stay cacheable: equinox's checked
linear solve in the implicit derivative of a root (an event time) must not reach a compiled
program as a host callback, which JAX's persistent compilation cache refuses."""

import logging

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxrb
from jaxrb.fit import least_squares_fit

_NOT_CACHED = "because it uses host callbacks"


def _root(z):
    """The real root x of x^3 + z x - 1 (z > 0), found by Newton's method; its derivative
    in z is the implicit one (optimistix), with its checked linear solve."""
    fn = lambda x, z: x**3 + z * x - 1.0  # noqa: E731
    return optx.root_find(fn, optx.Newton(1e-12, 1e-12), jnp.ones(()), z, throw=False).value


@pytest.fixture
def raising_checks(monkeypatch, caplog):
    """equinox's default (errors raise through a host callback), whatever the suite sets;
    the compiler's cache messages captured."""
    monkeypatch.delenv("EQX_ON_ERROR", raising=False)
    monkeypatch.setattr(eqx._errors, "EQX_ON_ERROR", "raise")
    jax.clear_caches()  # no check traced in another mode is reused
    caplog.set_level(logging.DEBUG, logger="jax._src.compiler")
    yield caplog
    jax.clear_caches()


def _refused(caplog, tag):
    return [r for r in caplog.records if _NOT_CACHED in r.getMessage() and tag in r.getMessage()]


def test_fits_compile_their_derivatives_without_host_callbacks(raising_checks):
    """The control first: the caller's own jax.jit of a forward derivative through a root
    has the host callback (so the check can see one). jaxrb's least-squares fit, run next
    in the same process, differentiates its residuals (through the same root) inside its own
    compiled solver: no host callback reaches that program, although equinox had kept the
    raising form of the same check from the control."""

    def _caller_program_a(z):
        return jax.jacfwd(_root)(z)

    d = jax.jit(_caller_program_a)(jnp.asarray(2.0))
    x = float(_root(jnp.asarray(2.0)))
    np.testing.assert_allclose(float(d), -x / (3 * x**2 + 2.0), rtol=1e-12)
    assert _refused(raising_checks, "_caller_program_a")

    data = jnp.stack([_root(jnp.asarray(1.5)), _root(jnp.asarray(3.0))])
    fit = least_squares_fit(
        lambda z, _: jnp.stack([_root(z[0]), _root(2.0 * z[0])]) - data,
        jnp.array([3.0]),
        lambda z: (z[0],),
        ("z",),
        ("z",),
    )
    assert fit.converged
    np.testing.assert_allclose(float(fit.values["z"]), 1.5, rtol=1e-8)
    assert not _refused(raising_checks, "_solve")


def test_nan_checks_make_the_callers_derivative_programs_cacheable(raising_checks):
    """`speed_up_compilation(nan_checks=True)`: equinox's checks return NaN, so the caller's
    own derivative program has no host callback (and a singular check gives NaN)."""
    jaxrb.speed_up_compilation(cache=False, nan_checks=True)
    assert eqx._errors.EQX_ON_ERROR == "nan"

    def _caller_program_b(z):
        return jax.jacfwd(_root)(z)

    d = jax.jit(_caller_program_b)(jnp.asarray(2.0))
    x = float(_root(jnp.asarray(2.0)))
    np.testing.assert_allclose(float(d), -x / (3 * x**2 + 2.0), rtol=1e-12)
    assert not _refused(raising_checks, "_caller_program_b")
