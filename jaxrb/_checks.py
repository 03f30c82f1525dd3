"""Trace-time argument checks shared by the geometry and model layers.

Structural mistakes (wrong shapes, wrong types) raise here at trace time, naming the
argument. Value checks that need concrete numbers (non-finite input) raise only when the
value is concrete, i.e. outside jit; under jit they are the caller's job (result flags).
"""

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
