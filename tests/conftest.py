import os
from pathlib import Path

import jax
import pytest

import jaxrb

# Compiled programs go to their own cache beside the user's jaxrb cache (never into it):
# `jax-tests` next to `jaxrb.default_cache_dir()` (e.g. ~/.cache/jaxrb/jax-tests), or
# $JAXRB_TEST_CACHE_DIR. The workers share it, so a program two test modules use is compiled
# once, and a later run of the suite (of any checkout) reads back every program that has not
# changed. The command line (called in-process and in subprocesses by the tests) and the
# notebooks' kernels find the same directory through the environment.
_CACHE = Path(
    os.environ.get("JAXRB_TEST_CACHE_DIR") or jaxrb.default_cache_dir().with_name("jax-tests")
)
os.environ["JAXRB_CACHE_DIR"] = str(_CACHE)
os.environ["JAX_COMPILATION_CACHE_DIR"] = str(_CACHE)
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.5"

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jaxrb.speed_up_compilation(cache_dir=_CACHE)  # also the quicker CPU kernel emitters


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
