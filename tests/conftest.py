import jax
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Drop every test module's compiled functions when it ends. Each XLA executable keeps a
    few memory mappings; the whole suite compiles enough of them to reach the kernel's limit
    (vm.max_map_count, 65530 by default), and XLA then aborts the process while compiling.
    Tests reuse compiled functions within a module, rarely across modules."""
    yield
    jax.clear_caches()


@pytest.fixture
def getkey():
    """A function returning a fresh PRNG key on each call (deterministic sequence)."""
    keys = iter(jax.random.split(jax.random.key(0), 10_000))
    return lambda: next(keys)
