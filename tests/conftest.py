import os
from pathlib import Path

# equinox's run-time checks return NaN instead of raising through a host callback (read by
# equinox when it is imported, so before jax and jaxrb; inherited by the command lines and
# notebook kernels the tests start). JAX's persistent cache keeps no program with a host
# callback, and every derivative through an event time that a test compiles with its own
# `jax.jit` / `jax.jacfwd` carries one (the checked linear solve of the event time's
# implicit derivative): without this they were compiled again on every run of the suite.
# jaxrb flags failed solves in its own result codes, which the tests check.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402
import pytest  # noqa: E402

import jaxrb  # noqa: E402

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
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"  # as speed_up_compilation
# jaxrb's traced programs too (`jaxrb.persistent_jit`), in the same folder's `programs`: the
# command line and the notebooks' kernels keep them through these variables, also where the
# scene, the sweep's function or the fit's residuals come from the tests or the benchmarks
# (their files are then in the key; a function defined in a notebook's cell has no file)
_ROOT = Path(__file__).resolve().parent.parent
_SOURCES = [str(_ROOT / name) for name in ("tests", "benchmarks")]
os.environ["JAXRB_PROGRAMS"] = "1"
os.environ["JAXRB_PROGRAM_SOURCES"] = os.pathsep.join(_SOURCES)

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jaxrb.speed_up_compilation(cache_dir=_CACHE, program_sources=_SOURCES)  # + CPU compiler settings


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Drop every test module's compiled functions when it ends. Each XLA executable keeps a
    few memory mappings; the whole suite compiles enough of them to reach the kernel's limit
    (vm.max_map_count, 65530 by default), and XLA then aborts the process while compiling.
    Tests reuse compiled functions within a module, rarely across modules."""
    yield
    jax.clear_caches()


@pytest.fixture(autouse=True)
def _keep_programs_as_the_suite_set_them():
    """Put back after each test whether and where jaxrb keeps its traced programs. A test
    that calls `speed_up_compilation(cache=False)` in-process turns the keeping off for the
    whole process, and every test its worker ran after it then traced and lowered its
    programs again instead of loading them (a loaded d6's sweep: 26 s of tracing)."""
    from jaxrb import _persistent

    kept = dict(_persistent._KEEP)
    yield
    _persistent._KEEP.update(kept)


@pytest.fixture
def getkey():
    """A function returning a fresh PRNG key on each call (deterministic sequence)."""
    keys = iter(jax.random.split(jax.random.key(0), 10_000))
    return lambda: next(keys)
