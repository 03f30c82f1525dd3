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


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Groups for parallel workers (pytest-xdist, `--dist loadgroup`): a test module's tests
    run on one worker, so that the compiled functions they share are compiled once; a test
    marked `compiles_alone` (its programs are its own, and take long to compile) is a group
    of its own (with its parameter cases, or each case alone with `per_case=True`), so that
    the slowest modules are spread over the workers."""
    for item in items:
        alone = item.get_closest_marker("compiles_alone")
        if alone is None:
            group = item.path.name
        elif alone.kwargs.get("per_case", False):
            group = item.nodeid
        else:
            group = f"{item.path.name}::{item.originalname}"
        item.add_marker(pytest.mark.xdist_group(group))


@pytest.fixture
def getkey():
    """A function returning a fresh PRNG key on each call (deterministic sequence)."""
    keys = iter(jax.random.split(jax.random.key(0), 10_000))
    return lambda: next(keys)
