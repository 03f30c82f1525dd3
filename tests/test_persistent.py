"""`jaxrb.persistent_jit`: a traced program is kept on disk and loaded by a later caller
instead of tracing again; anything that could make a kept program stale changes its key or
keeps it off the disk."""

import importlib.util
import pickle
import subprocess
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
import jaxrb._persistent as persistent

TRACES = []


def _model(x, y, power):
    TRACES.append(power)  # runs only while tracing
    return {"sum": jnp.sum(x**power) + y, "scaled": x * y}


class _Wrapped(eqx.Module):
    a: jax.Array
    label: str = eqx.field(static=True)


def _model_plus(offset):
    def model(x, y, power):
        TRACES.append(power)
        return {"sum": jnp.sum(x**power) + y + offset, "scaled": x * y}

    return model


def _with_module(m):
    TRACES.append(m.label)
    return m.a * 2.0


def _load(tmp_path, name, source):
    path = tmp_path / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def test_a_kept_program_is_loaded_without_tracing_and_gives_the_same_result(tmp_path):
    x, y = jnp.arange(3.0), jnp.asarray(2.0)
    first = jaxrb.persistent_jit(_model, cache_dir=tmp_path)
    TRACES.clear()
    out = first(x, y, 3)
    assert TRACES == [3]
    assert len(list(tmp_path.glob("*.bin"))) == 1
    # a new wrapper (as in a new process) reads the file and does not trace
    second = jaxrb.persistent_jit(_model, cache_dir=tmp_path)
    again = second(x, y, 3)
    assert TRACES == [3]
    assert set(again) == {"sum", "scaled"}
    np.testing.assert_array_equal(again["sum"], out["sum"])
    np.testing.assert_array_equal(again["scaled"], jnp.array([0.0, 2.0, 4.0]))
    assert float(again["sum"]) == 0.0 + 1.0 + 8.0 + 2.0
    # another static value or another shape is another program
    second(x, y, 2)
    second(jnp.arange(4.0), y, 3)
    assert TRACES == [3, 2, 3]
    assert len(list(tmp_path.glob("*.bin"))) == 3
    # under a transformation the call is equinox.filter_jit's (no file)
    g = jax.grad(lambda x: second(x, y, 3)["sum"])(x)
    np.testing.assert_allclose(g, 3 * x**2)
    assert len(list(tmp_path.glob("*.bin"))) == 3


def test_the_compiled_executable_is_kept_and_loaded_first(tmp_path):
    """Beside the exported program, the executable XLA compiled for this machine: a new
    caller loads it (no trace, no lowering); a damaged one is replaced. (The program adds a
    number new on each run, so that JAX's own cache cannot serve it at first.)"""
    x, y = jnp.arange(3.0), jnp.asarray(2.0)
    model = _model_plus(float(time.time_ns() % 10**12))
    TRACES.clear()
    out = jaxrb.persistent_jit(model, cache_dir=tmp_path)(x, y, 3)
    (program,) = tmp_path.glob("*.bin")
    (executable,) = tmp_path.glob("*.exe")
    assert executable.name.startswith(program.stem + ".")
    program.unlink()  # the executable alone serves a new caller
    again = jaxrb.persistent_jit(model, cache_dir=tmp_path)(x, y, 3)
    assert TRACES == [3]
    np.testing.assert_array_equal(again["sum"], out["sum"])
    np.testing.assert_array_equal(again["scaled"], out["scaled"])
    executable.write_bytes(b"damaged")  # and nothing else: removed, traced again
    third = jaxrb.persistent_jit(model, cache_dir=tmp_path)(x, y, 3)
    assert TRACES == [3, 3]
    np.testing.assert_array_equal(third["sum"], out["sum"])
    assert program.exists()
    # kept again, as JAX's cache held it (that cache served the compile): a new caller loads it
    assert executable.read_bytes() != b"damaged"
    program.unlink()
    fourth = jaxrb.persistent_jit(model, cache_dir=tmp_path)(x, y, 3)
    assert TRACES == [3, 3]
    np.testing.assert_array_equal(fourth["sum"], out["sum"])


def test_an_executable_that_loads_but_does_not_run_is_removed(tmp_path, monkeypatch):
    """An executable whose code is missing fails at its first run, not on loading: the call
    then removes its file and traces as usual, with the right result."""
    x, y = jnp.arange(3.0), jnp.asarray(2.0)
    out = jaxrb.persistent_jit(_model, cache_dir=tmp_path)(x, y, 6)
    (program,) = tmp_path.glob("*.bin")
    executable = program.with_suffix(f".{persistent._machine_key()}.exe")
    executable.write_bytes(b"loads, then fails")

    def missing_code(*leaves):
        raise jax.errors.JaxRuntimeError("NOT_FOUND: Function fusion not found (type id: 1)")

    def load(path, avals):
        _, out_tree = pickle.loads(program.read_bytes())
        return missing_code, out_tree

    monkeypatch.setattr(persistent, "_load_executable", load)
    TRACES.clear()
    again = jaxrb.persistent_jit(_model, cache_dir=tmp_path)(x, y, 6)
    assert TRACES == [6]
    assert not executable.exists()
    np.testing.assert_array_equal(again["sum"], out["sum"])
    np.testing.assert_array_equal(again["scaled"], out["scaled"])


_LOAD_ALONE = """
import sys
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
from jaxrb._persistent import _load_executable

inputs = np.load(sys.argv[2])
results = {}
for name in sys.argv[3:]:
    args = [inputs[f"{name}_{i}"] for i in range(len(inputs.files)) if f"{name}_{i}" in inputs]
    avals = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in args]
    run, out_tree = _load_executable(Path(inputs[f"{name}_path"].item()), avals)
    for i, leaf in enumerate(jax.tree.leaves(jax.tree.unflatten(out_tree, run(*args)))):
        results[f"{name}_{i}"] = np.asarray(leaf)
np.savez(sys.argv[1], **results)
"""


def test_executables_read_from_jax_cache_or_calling_lapack_run_in_a_new_process(tmp_path):
    """Two executables a new process loads by themselves and runs: one whose compile JAX's
    persistent cache served (kept as that cache held it: its own serialisation lacks the
    code, and run fails with "Function ... not found"), and one calling LAPACK (whose
    kernels the loading process sets up first: without that, a segmentation fault)."""
    x, y = jnp.arange(3.0), jnp.asarray(2.0)
    first, second, third = tmp_path / "first", tmp_path / "second", tmp_path / "third"
    jaxrb.persistent_jit(_model, cache_dir=first)(x, y, 4)  # now in JAX's cache
    out = jaxrb.persistent_jit(_model, cache_dir=second)(x, y, 4)  # served by it
    assert float(out["sum"]) == 0.0 + 1.0 + 16.0 + 2.0
    offset = (time.time_ns() % 10**6) * 1e-12  # new on each run: compiled here, not read back

    def inverse(m):
        return jnp.linalg.inv(m) + offset

    m = jnp.array([[2.0, 1.0], [1.0, 3.0]])
    inv = jaxrb.persistent_jit(inverse, cache_dir=third)(m)
    np.testing.assert_allclose(inv - offset, np.linalg.inv(np.asarray(m)), rtol=1e-12)
    (served,) = second.glob("*.exe")
    (lapack,) = third.glob("*.exe")
    inputs = {"served_0": x, "served_1": y, "served_path": str(served)}
    inputs |= {"lapack_0": m, "lapack_path": str(lapack)}
    np.savez(tmp_path / "inputs.npz", **inputs)
    results = tmp_path / "results.npz"
    args = [str(results), str(tmp_path / "inputs.npz"), "served", "lapack"]
    proc = subprocess.run(
        [sys.executable, "-c", _LOAD_ALONE, *args], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    loaded = np.load(results)
    np.testing.assert_array_equal(loaded["served_0"], out["scaled"])  # leaves sorted by key
    np.testing.assert_array_equal(loaded["served_1"], out["sum"])
    np.testing.assert_array_equal(loaded["lapack_0"], inv)


def test_modules_keep_their_static_fields_in_the_key(tmp_path):
    f = jaxrb.persistent_jit(_with_module, cache_dir=tmp_path)
    TRACES.clear()
    f(_Wrapped(jnp.ones(2), "a"))
    f(_Wrapped(jnp.ones(2), "b"))
    g = jaxrb.persistent_jit(_with_module, cache_dir=tmp_path)
    np.testing.assert_array_equal(g(_Wrapped(jnp.ones(2), "b")), [2.0, 2.0])
    assert TRACES == ["a", "b"]


def test_equinox_checks_mode_is_in_the_key(tmp_path):
    """A program traced with equinox's checks as NaN is not loaded where they raise."""
    from jaxrb._solve import equinox_checks_mode, set_equinox_checks

    def checked(x):
        return eqx.error_if(x, x < 0, "negative")

    before = equinox_checks_mode()
    try:
        set_equinox_checks("nan")
        f = jaxrb.persistent_jit(checked, cache_dir=tmp_path)
        assert np.isnan(float(f(jnp.asarray(-1.0))))
        set_equinox_checks("raise")
        with pytest.warns(UserWarning, match="traced as usual"):  # a host callback now
            with pytest.raises(Exception, match="negative"):
                jaxrb.persistent_jit(checked, cache_dir=tmp_path)(jnp.asarray(-1.0))
    finally:
        set_equinox_checks(before)
    assert len(list(tmp_path.glob("*.bin"))) == 1


def test_an_edited_source_file_traces_again(tmp_path):
    store = tmp_path / "programs"
    one = _load(tmp_path, "persistent_edit_one", "def f(x):\n    return x + 1.0\n")
    assert float(jaxrb.persistent_jit(one.f, cache_dir=store)(jnp.asarray(1.0))) == 2.0
    two = _load(tmp_path, "persistent_edit_one", "def f(x):\n    return x + 10.0\n")
    assert float(jaxrb.persistent_jit(two.f, cache_dir=store)(jnp.asarray(1.0))) == 11.0
    assert len(list(store.glob("*.bin"))) == 2


def _scaled_by(data):
    def scaled(x):
        return x * data

    return scaled


def test_arrays_closed_over_are_keyed_by_their_values(tmp_path):
    """Constants baked into the trace: a closure over other values is another program."""
    ones = jnp.ones(3)
    for data in (jnp.arange(3.0), jnp.arange(3.0) + 5.0, jnp.arange(3.0)):
        out = jaxrb.persistent_jit(_scaled_by(data), cache_dir=tmp_path)(ones)
        np.testing.assert_array_equal(out, data)
    assert len(list(tmp_path.glob("*.bin"))) == 2


def test_a_weakly_typed_constant_is_another_program(tmp_path):
    """x * c with x float32: a weak float64 c keeps float32, a strong one promotes."""
    x = jnp.ones(2, jnp.float32)
    with jax.numpy_dtype_promotion("standard"):
        weak = jaxrb.persistent_jit(_scaled_by(jnp.asarray(2.0)), cache_dir=tmp_path)(x)
        strong = jaxrb.persistent_jit(_scaled_by(jnp.float64(2.0)), cache_dir=tmp_path)(x)
    assert weak.dtype == jnp.float32
    assert strong.dtype == jnp.float64


def test_what_cannot_be_keyed_is_traced_as_usual(tmp_path):
    # a closure over a traced value (inside a transformation), and over a large array
    def loss(p):
        return jnp.sum(jaxrb.persistent_jit(_scaled_by(p), cache_dir=tmp_path)(jnp.ones(3)))

    np.testing.assert_array_equal(jax.grad(loss)(jnp.arange(3.0)), [1.0, 1.0, 1.0])
    large = jnp.ones(persistent.MAX_KEYED_CONSTANT + 1)
    out = jaxrb.persistent_jit(_scaled_by(large), cache_dir=tmp_path)(jnp.asarray(2.0))
    assert float(out[0]) == 2.0
    # a function from outside the files the key covers, passed as a static argument
    namespace = {}
    exec("def outside(x):\n    return x * 3.0\n", namespace)  # noqa: S102

    def apply(fn, x):
        return fn(x)

    np.testing.assert_array_equal(
        jaxrb.persistent_jit(apply, cache_dir=tmp_path)(namespace["outside"], jnp.ones(2)),
        [3.0, 3.0],
    )
    assert list(tmp_path.glob("*.bin")) == []


def test_entry_points_keep_programs_of_the_users_sources_only_when_named(tmp_path):
    """`jaxrb.sweep` of a function from a file of the user's: traced as usual, unless its
    folder is among the program sources (then its content is in the key)."""
    source, store = tmp_path / "src", tmp_path / "programs"
    source.mkdir()
    module = _load(source, "persistent_sweep_row", "def f(row):\n    return 2.0 * row\n")
    before = dict(persistent._KEEP)
    try:
        for sources, kept in (([], 0), ([source], 1)):
            persistent.keep_programs(True, store, sources=sources)
            out = jaxrb.sweep(module.f, jnp.arange(3.0), progress=False)
            np.testing.assert_array_equal(out, [0.0, 2.0, 4.0])
            assert len(list(store.glob("*.bin"))) == kept
    finally:
        persistent._KEEP.update(before)


def test_a_program_with_a_host_callback_is_traced_as_usual_with_a_warning(tmp_path):
    def prints(x):
        jax.debug.print("x = {}", x)
        return x + 1.0

    with pytest.warns(UserWarning, match="traced as usual"):
        out = jaxrb.persistent_jit(prints, cache_dir=tmp_path)(jnp.asarray(1.0))
    assert float(out) == 2.0
    assert list(tmp_path.glob("*.bin")) == []


def test_programs_are_traced_with_the_garbage_collector_paused(tmp_path, monkeypatch):
    """Python's cyclic garbage collector is off while a kept or plain entry point traces its
    program (a third of a contact program's trace went to its passes) and back on after;
    a caller that had turned it off keeps it off."""
    import gc

    monkeypatch.setitem(persistent._KEEP, "on", False)  # the entry point traces, never loads
    seen = []

    def double(x):
        seen.append(gc.isenabled())  # runs only while tracing
        return 2.0 * x

    kept = persistent.persistent_jit(double, cache_dir=tmp_path)
    plain = persistent.entry_point(lambda x: double(x) + 1.0)
    assert gc.isenabled()
    np.testing.assert_allclose(kept(jnp.arange(3.0)), [0.0, 2.0, 4.0])
    np.testing.assert_allclose(plain(jnp.arange(2.0)), [1.0, 3.0])
    assert seen == [False, False]
    assert gc.isenabled()
    gc.disable()
    try:
        with persistent.garbage_collection_paused():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()
