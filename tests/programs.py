"""`persistent`: `jax.jit` for the tests' heavy helpers, whose traced programs are kept
between runs of the suite (`jaxrb.persistent_jit`, in the test cache's `programs` folder).

Tracing a contact simulation takes 10-20 s on a 2-core CPU, and a warm run of the suite
would otherwise trace every such helper again. The key covers the sources of jaxrb, of
these tests and of the benchmarks (which some tests import), so an edit anywhere there
traces again. As with `jax.jit`, Python numbers passed for non-static arguments are traced
(weakly typed), not made static.
"""

import functools
import inspect
from pathlib import Path

import jax
import jax.numpy as jnp

import jaxrb

_ROOT = Path(__file__).resolve().parents[1]
SOURCES = (_ROOT / "tests", _ROOT / "benchmarks")


def _traced(x):
    return jnp.asarray(x) if isinstance(x, (bool, int, float, complex)) else x


def persistent(fn=None, *, static_argnames=()):
    """`jax.jit(fn, static_argnames=...)` with its programs kept between runs."""
    if fn is None:
        return functools.partial(persistent, static_argnames=static_argnames)
    static_argnames = (static_argnames,) if isinstance(static_argnames, str) else static_argnames
    signature = inspect.signature(fn)
    program = jaxrb.persistent_jit(fn, sources=SOURCES)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        for name, value in bound.arguments.items():
            if name not in static_argnames:
                bound.arguments[name] = jax.tree.map(_traced, value)
        return program(*bound.args, **bound.kwargs)

    return call


def traces(entry) -> int | None:
    """Programs of a jaxrb entry point (`jaxrb._persistent.entry_point`) traced, or loaded
    from the kept ones, in this process; None where equinox's private cache count is gone."""
    size = getattr(entry.plain._cached, "_cache_size", None)
    return None if size is None else size() + len(entry.kept)
