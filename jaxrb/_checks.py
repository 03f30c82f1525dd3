"""Trace-time argument checks shared by the geometry and model layers.

Structural mistakes (wrong shapes, wrong types) raise here at trace time, naming the
argument. Value checks that need concrete numbers (non-finite input) raise only when the
value is concrete, i.e. outside jit; under jit they are the caller's job (result flags).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


def as_float_array(x, name: str, trailing: tuple[int, ...]) -> jax.Array:
    """`x` as a floating array whose last axes are `trailing`; raises a ValueError naming `name`."""
    try:
        arr = jnp.asarray(x)
    except TypeError as e:
        raise TypeError(f"{name} must be an array of numbers, got {type(x).__name__}") from e
    if not jnp.issubdtype(arr.dtype, jnp.floating):
        arr = arr.astype(jnp.result_type(float))
    n = len(trailing)
    if arr.ndim < n or tuple(arr.shape[arr.ndim - n :]) != trailing:
        want = "(..., " + ", ".join(str(t) for t in trailing) + ")"
        raise ValueError(f"{name} must have shape {want}, got shape {tuple(arr.shape)}")
    return arr


def is_concrete(x) -> bool:
    """True when `x` holds concrete values (not a tracer under jit/vmap/grad)."""
    return not isinstance(x, jax.core.Tracer)


def require_finite(arr: jax.Array, name: str) -> None:
    """Raise a ValueError naming `name` if a concrete `arr` holds NaN or inf."""
    if is_concrete(arr) and not bool(np.all(np.isfinite(np.asarray(arr)))):
        raise ValueError(f"{name} contains non-finite values (NaN or inf)")


class Requirement(NamedTuple):
    """A condition on a model parameter: `ok` is True (elementwise) where `value` obeys `rule`.

    Models list their requirements once (`requirements()`); the same list raises a ValueError
    for concrete values where the model is made and gives a traceable flag in `simulate`.
    """

    field: str
    value: object
    rule: str
    ok: jax.Array


def as_computed(x) -> np.ndarray:
    """A concrete `x` as a numpy array in which subnormal floats are 0. XLA on a CPU flushes
    them to 0 in some programs and not in others; with the checks below, which count them
    as 0 too, a concrete check made in numpy agrees with the same check traced. E.g. a mass
    of 1e-320 kg is > 0 in neither."""
    a = np.asarray(x)
    if np.issubdtype(a.dtype, np.floating):
        a = np.where(np.abs(a) < np.finfo(a.dtype).tiny, np.zeros_like(a), a)
    return a


def _namespace(x):
    """(numpy, x as a numpy array, subnormals 0) for concrete values, checked without
    compiling anything; (jax.numpy, x) for traced ones."""
    return (np, as_computed(x)) if is_concrete(x) else (jnp, x)


def finite(x) -> jax.Array:
    xp, x = _namespace(x)
    return xp.isfinite(x)


def _smallest_normal(x, xp):
    """The smallest positive normal number of x's float dtype (0 for other dtypes). XLA on
    a CPU flushes subnormals to 0 in some programs and not in others, so every check that
    compares with 0 counts |x| below it as 0."""
    return xp.finfo(x.dtype).tiny if xp.issubdtype(x.dtype, xp.floating) else 0


def finite_positive(x) -> jax.Array:
    """Finite and > 0 (a subnormal counts as 0)."""
    xp, x = _namespace(x)
    tiny = _smallest_normal(x, xp)
    return xp.isfinite(x) & ((x >= tiny) if tiny else (x > 0))


def finite_nonnegative(x) -> jax.Array:
    """Finite and >= 0 (a subnormal counts as 0)."""
    xp, x = _namespace(x)
    tiny = _smallest_normal(x, xp)
    return xp.isfinite(x) & ((x > -tiny) if tiny else (x >= 0))


def nonzero_rows(q) -> jax.Array:
    """Whether each row of `q` (last axis) has an entry that is not 0 (a subnormal counts
    as 0): a quaternion with a norm."""
    xp, q = _namespace(q)
    return xp.any(xp.abs(q) >= _smallest_normal(q, xp), axis=-1)


def all_met(requirements) -> jax.Array:
    """True when every requirement holds everywhere (traceable; concrete flags are combined
    in numpy, without compiling anything)."""
    oks = [r.ok for r in requirements]
    if all(is_concrete(ok) for ok in oks):
        return jnp.asarray(all(bool(np.all(np.asarray(ok))) for ok in oks))
    return jnp.all(jnp.array([jnp.all(ok) for ok in oks] or [True]))


def raise_unmet(owner: str, requirements) -> None:
    """Raise a ValueError naming `owner.field`, the rule and the value, for the first
    concrete requirement that fails; traced requirements are left to the result flag."""
    for r in requirements:
        if is_concrete(r.ok) and not bool(np.all(np.asarray(r.ok))):
            value = np.asarray(r.value)
            shown = value.tolist() if value.size <= 9 else f"an array of shape {value.shape}"
            raise ValueError(f"{owner}.{r.field} must be {r.rule}, got {shown}")
