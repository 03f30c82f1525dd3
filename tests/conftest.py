import jax
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture
def getkey():
    """A function returning a fresh PRNG key on each call (deterministic sequence)."""
    keys = iter(jax.random.split(jax.random.key(0), 10_000))
    return lambda: next(keys)
