"""`persistent_jit`: `equinox.filter_jit` whose traced program is kept on disk between runs.

JAX's persistent compilation cache keeps compiled programs, but every new process still
traces and lowers the Python function before it can look the program up; for a contact
simulation that is most of a warm start (a coin's batch: 19 s of tracing and 2.6 s of
lowering against 4.4 s of loading its compiled program, on a 2-core x86 CPU).
`persistent_jit` also keeps the lowered program itself (`jax.export`, serialised), keyed by
what the program is made from, and a later process loads it instead of tracing.

Beside it goes the executable XLA compiled from it for this machine (`<key>.<machine>.exe`,
the machine being the backend, device, `XLA_FLAGS` and processor), and a later process loads
that first: no lowering, no lookup in JAX's cache (a die's contact program: 0.9 s against
1.4 s on a 2-core x86 CPU). An executable read back from JAX's persistent cache serialises
without its code (loaded again, it fails with "Function ... not found"), so where JAX's cache
served the compile, what is kept is the executable as that cache held it. A program that
calls a custom kernel is kept only where the kernels are LAPACK's (a `stablehlo.custom_call`
such as the SVD or LU on a CPU): jaxlib sets them up when it lowers such a call, so the
process that loads the executable sets them up first (without it, a segmentation fault, as
in JAX issue 28908). An executable that does not load, or loads and fails at its first run,
is removed and the call traced as usual.

The key is a SHA-256 of: the source of the `jaxrb` package, the file that defines `fn`, the
files and folders named in `sources`, `fn`'s name, the static part of the arguments (every
leaf that is not an array, as `equinox.filter_jit` splits them), the shapes and dtypes of
the array leaves, the versions of JAX, jaxlib, equinox, diffrax, optimistix and lineax, and
the settings that change a trace (`jax_enable_x64`, the dtype promotion, how equinox's
checks are traced now).
Values `fn` closes over are keyed like static arguments, and arrays it closes over (which
the trace bakes in as constants) by their values. So the contract is: `fn` is a pure
function of its arguments and of the code in those files; a global value it reads must not
change between runs. Where the key cannot be made stable (a text naming a memory address, a
function closing over a traced value or an array of more than `MAX_KEYED_CONSTANT`
elements, a class or function defined outside those files and packages), or the program
cannot be exported (a host callback), or the process has several devices, the call is
`equinox.filter_jit`'s, untouched. An edit to a file is seen at the next call, to a folder
within `FOLDER_REFRESH_S`.
"""

import contextlib
import copyreg
import functools
import gc
import hashlib
import importlib.metadata
import os
import pickle
import re
import sys
import time
import warnings
import zlib
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
from jax import export

from ._cache_size import hook_jax_cache, mark_used, write_atomically

_PACKAGES = ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "lineax")
_RUNTIME_ERROR = getattr(jax.errors, "JaxRuntimeError", RuntimeError)  # XLA's, at run time


def _missing_reduce(_):
    return (_equinox_missing, ())


def _equinox_missing():
    from equinox._module._flatten import MISSING

    return MISSING


try:  # equinox marks absent fields with a sentinel; unpickled, it must be that same object
    from equinox._module._flatten import _Missing

    copyreg.pickle(_Missing, _missing_reduce)
except ImportError:  # another equinox: output structures are then checked on load
    pass


def _source_digest(paths: tuple[str, ...]) -> str:
    """SHA-256 over the files at `paths` (files, or folders searched recursively: the
    sources and data files such as example scenes, not compiled Python or Markdown),
    named relative to each path's parent. A file is read again when it changes on disk; a
    folder is searched again at most once a second (`FOLDER_REFRESH_S`), so a call costs
    a few stat calls, not a walk of the package."""
    h = hashlib.sha256()
    for root in paths:
        root = Path(root)
        if root.is_dir():
            h.update(_folder_digest(root).encode())
        elif root.is_file():
            h.update(root.name.encode())
            h.update(_stat_digest(root).encode())
    return h.hexdigest()


FOLDER_REFRESH_S = 1.0
_FOLDERS: dict[Path, tuple[float, str]] = {}  # folder -> (when searched, digest)


def _folder_digest(root: Path) -> str:
    searched = _FOLDERS.get(root)
    now = time.monotonic()
    if searched is not None and now - searched[0] < FOLDER_REFRESH_S:
        return searched[1]
    h = hashlib.sha256()
    for f in sorted(root.rglob("*")):
        if "__pycache__" in f.parts or f.suffix in (".pyc", ".md") or not f.is_file():
            continue
        h.update(f.relative_to(root.parent).as_posix().encode())
        h.update(_stat_digest(f).encode())
    _FOLDERS[root] = (now, h.hexdigest())
    return _FOLDERS[root][1]


def _stat_digest(f: Path) -> str:
    stat = f.stat()
    return _file_digest(str(f), stat.st_mtime_ns, stat.st_size)


@functools.cache
def _file_digest(path: str, mtime_ns: int, size: int) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@functools.cache
def _versions() -> str:
    out = []
    for name in _PACKAGES:
        try:
            out.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            out.append(f"{name}=?")
    return ",".join(out)


@functools.cache
def _package_roots() -> tuple[str, ...]:
    """Folders of the packages whose versions are in the key, and of Python itself."""
    import sysconfig

    roots = [sysconfig.get_paths()["stdlib"]]
    for name in _PACKAGES + ("numpy",):
        module = sys.modules.get(name) or importlib.import_module(name)
        roots.append(str(Path(module.__file__).parent))
    return tuple(roots)


MAX_KEYED_CONSTANT = 1 << 16  # larger arrays closed over are not hashed: traced as usual


class _Describer:
    """Names the static part of a call as text, stable across processes, or finds that it
    cannot (`None`): a memory address in the text, a function closing over a traced value
    or a large array, or a class or function defined outside the files the key covers
    (`roots`) and the packages whose versions it holds (an edit there would not change the
    key)."""

    def __init__(self, roots):
        self.roots = tuple(str(Path(r).resolve()) for r in roots) + _package_roots()

    def trusted_file(self, filename) -> bool:
        if not filename:
            return False
        path = str(Path(filename).resolve())
        return any(path == r or path.startswith(r + os.sep) for r in self.roots)

    def trusted_type(self, t) -> bool:
        if t.__module__ == "builtins":
            return True
        module = sys.modules.get(t.__module__)
        return self.trusted_file(getattr(module, "__file__", None))

    def tree(self, tree) -> str | None:
        leaves, treedef = jax.tree.flatten(tree)
        types = self.node_types(treedef)
        parts = [types, self.treedef_text(treedef)] + [self.leaf(x) for x in leaves]
        if any(p is None for p in parts):
            return None
        text = "|".join(parts)
        return None if " at 0x" in text else text

    def node_types(self, treedef) -> str | None:
        """The module and name of every node type (the tree's repr names classes only)."""
        names = []
        for t, _ in _node_data(treedef):
            if not self.trusted_type(t):
                return None
            names.append(f"{t.__module__}.{t.__qualname__}")
        return ",".join(names)

    def treedef_text(self, treedef) -> str | None:
        """The tree's structure as text: its repr, with each function held in a node's data
        (equinox's bound method holds its class's function) named as `function` names it,
        not by its repr, which carries a memory address."""
        text = repr(treedef)
        for fn in self.node_functions(treedef):
            named = self.function(fn)
            if named is None:
                return None
            text = text.replace(repr(fn), named)
        return text

    def node_functions(self, treedef) -> list:
        """The functions held in the node data of `treedef` (in tuples, lists and dicts)."""
        found = []
        for _, aux in _node_data(treedef):
            items = [aux]
            while items:
                item = items.pop()
                if isinstance(item, (tuple, list)):
                    items.extend(item)
                elif isinstance(item, dict):
                    items.extend(item.values())
                elif isinstance(item, functools.partial) or hasattr(item, "__code__"):
                    found.append(item)
        return found

    def leaf(self, x) -> str | None:
        if isinstance(x, jax.core.Tracer):  # closed over inside a transformation
            return None
        if eqx.is_array(x):  # a constant the function closes over: keyed by its value
            if np.size(x) > MAX_KEYED_CONSTANT:
                return None
            weak = getattr(x, "weak_type", False)  # a weak constant promotes differently
            x = np.asarray(x)
            digest = hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()
            return f"array{x.shape}{x.dtype.str}{'weak' if weak else ''}:{digest}"
        if isinstance(x, jax.tree_util.PyTreeDef):
            types, text = self.node_types(x), self.treedef_text(x)
            return None if types is None or text is None else f"treedef[{types}]{text}"
        if isinstance(x, functools.partial) or hasattr(x, "__code__"):
            return self.function(x)
        if not self.trusted_type(type(x)):
            return None
        return f"{type(x).__name__}:{x!r}"

    def function(self, fn, depth=0) -> str | None:
        """A function's name, where its code starts (file name and line: lambdas share a
        name) and what it closes over, through `functools.partial` and `functools.wraps`
        layers (`jax.jacfwd(f)` and `jax.jacrev(f)` differ in their own code)."""
        if depth > 20:
            return None
        if isinstance(fn, functools.partial):
            inner = self.function(fn.func, depth + 1)
            bound = self.tree((fn.args, fn.keywords))
            return None if inner is None or bound is None else f"partial({inner}; {bound})"
        code = getattr(fn, "__code__", None)
        if code is None or not self.trusted_file(code.co_filename):
            return None
        where = f"{Path(code.co_filename).name}:{code.co_firstlineno}"
        parts = [f"{fn.__module__}.{fn.__qualname__}@{where}"]
        for cell in fn.__closure__ or ():
            try:
                value = cell.cell_contents
            except ValueError:  # an empty cell
                continue
            parts.append(self.tree(value))
        wrapped = getattr(fn, "__wrapped__", None)
        if wrapped is not None:
            parts.append(self.function(wrapped, depth + 1))
        return None if any(p is None for p in parts) else "(" + ", ".join(parts) + ")"


def _node_data(treedef):
    """(node type, auxiliary data) of each node of `treedef` that has them, depth first."""
    stack = [treedef]
    while stack:
        node = stack.pop()
        data = node.node_data()
        if data is not None:
            yield data
        stack.extend(node.children())


def _source_files(fn) -> tuple[str, ...]:
    """The files that define `fn` and the functions it wraps."""
    files = []
    for _ in range(20):
        if isinstance(fn, functools.partial):
            fn = fn.func
            continue
        code = getattr(fn, "__code__", None)
        if code is not None and code.co_filename not in files:
            files.append(code.co_filename)
        fn = getattr(fn, "__wrapped__", None)
        if fn is None:
            break
    return tuple(f for f in files if Path(f).is_file())


# jaxrb's own compiled entry points keep their programs only when asked:
# `speed_up_compilation(programs=True)` or the environment variable JAXRB_PROGRAMS=1; the
# user's own code they may key on: `program_sources` there, or JAXRB_PROGRAM_SOURCES (paths
# separated by os.pathsep)
_KEEP = {
    "on": os.environ.get("JAXRB_PROGRAMS", "") not in ("", "0"),
    "dir": None,
    "sources": tuple(p for p in os.environ.get("JAXRB_PROGRAM_SOURCES", "").split(os.pathsep) if p),
}
if _KEEP["on"]:  # jaxrb manages the cache folder: its prune needs JAX's reads marked
    hook_jax_cache()


def keep_programs(on: bool, cache_dir=None, sources=None) -> None:
    """Whether jaxrb's own entry points (`simulate`, `simulate_throws`, `simulate_batch`,
    `sweep`, the fits) keep their traced programs, and where (default `default_cache_dir()
    / "programs"`). `sources` (files or folders; None leaves them as they are): your own
    code, whose functions and classes (a force, a sweep's function, a fit's residuals) may
    then be in a kept program's key, with the content of these files."""
    _KEEP["on"] = bool(on)
    _KEEP["dir"] = cache_dir
    if on:
        hook_jax_cache()
    if sources is not None:
        _KEEP["sources"] = tuple(str(Path(p).expanduser().resolve()) for p in sources)


@contextlib.contextmanager
def garbage_collection_paused():
    """Python's cyclic garbage collector off for the duration (and back on after, if it was
    on). Tracing a contact program makes millions of short-lived objects, and the collector's
    passes over them were a third of the trace (a die's: 4.3 s with it, 2.7 s without, on a
    2-core x86 CPU); the cycles it leaves are collected at its next pass after."""
    was_on = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_on:
            gc.enable()


def entry_point(fn):
    """`equinox.filter_jit(fn)` for jaxrb's own compiled functions, kept on disk as
    `persistent_jit` does when `keep_programs` is on. A call that cannot be kept (a host
    callback such as a progress bar, a user-defined force class) is traced as usual,
    silently."""
    kept = persistent_jit(
        fn, cache_dir=lambda: _KEEP["dir"], sources=lambda: _KEEP["sources"], quiet=True
    )

    @functools.wraps(fn)
    def call(*args, **kwargs):
        with garbage_collection_paused():
            return (kept if _KEEP["on"] else kept.plain)(*args, **kwargs)

    call.plain, call.kept = kept.plain, kept.kept

    return call


def persistent_jit(fn=None, *, cache_dir=None, sources=(), quiet=False):
    """`equinox.filter_jit(fn)`, with its traced program kept on disk in `cache_dir` (default
    `default_cache_dir() / "programs"`), so that a later process loads it instead of tracing
    `fn` again (module docstring: the key, and the contract that `fn` depends only on its
    arguments and on the source files the key covers: `jaxrb`'s own, `fn`'s file and
    `sources`, a sequence or a function returning one). Calls with traced arguments (inside
    another transformation) and arguments whose static part has no stable key go through
    `equinox.filter_jit` untouched.

    Use it as `@persistent_jit` or `persistent_jit(fn, sources=("my_helpers/",))`. The
    directory can be deleted at any time. Nothing in it is removed by `persistent_jit`;
    `speed_up_compilation` bounds the size of its cache directory, `programs` included.
    """
    if fn is None:
        return functools.partial(persistent_jit, cache_dir=cache_dir, sources=sources, quiet=quiet)
    jitted = eqx.filter_jit(fn)
    loaded = {}  # key -> (compiled call, output structure, its file until it has run), here

    @functools.wraps(fn)
    def call(*args, **kwargs):
        with garbage_collection_paused():
            return _call(*args, **kwargs)

    def _call(*args, **kwargs):
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, in_tree = jax.tree.flatten(dynamic)
        if any(isinstance(x, jax.core.Tracer) for x in leaves) or not _one_device(leaves):
            return jitted(*args, **kwargs)
        key = _key(fn, static, in_tree, leaves, sources)
        if key is None:
            return jitted(*args, **kwargs)
        if key not in loaded:
            loaded[key] = _load_or_export(key, fn, static, in_tree, leaves, cache_dir, quiet)
        if loaded[key] is None:  # could not be exported
            return jitted(*args, **kwargs)
        run, out_tree, unproven = loaded[key]
        if unproven is None:
            return jax.tree.unflatten(out_tree, run(*leaves))
        try:  # the first run of an executable read from its file
            out = run(*leaves)
        except _RUNTIME_ERROR:  # it loads but does not run: removed, traced again
            unproven.unlink(missing_ok=True)
            del loaded[key]
            return jitted(*args, **kwargs)
        loaded[key] = (run, out_tree, None)
        return jax.tree.unflatten(out_tree, out)

    call.plain = jitted  # the equinox.filter_jit it falls back on
    call.kept = loaded  # the programs kept or loaded in this process
    return call


def _one_device(leaves) -> bool:
    """Whether the process has one device. A loaded program's results are committed to its
    device, where `jax.jit`'s results from uncommitted arguments are not: with several
    devices, arrays that could be combined before could then not be."""
    return jax.device_count() == 1


def _key(fn, static, in_tree, leaves, sources) -> str | None:
    from . import __file__ as package_init
    from ._solve import equinox_checks_mode

    paths = (str(Path(package_init).parent),) + _source_files(fn)
    if callable(sources):
        sources = sources()
    paths += tuple(str(Path(s).resolve()) for s in sources)
    describe = _Describer(paths)
    name = describe.function(fn)
    described = describe.tree(static)
    structure = describe.treedef_text(in_tree)
    if name is None or described is None or structure is None or " at 0x" in structure:
        return None
    h = hashlib.sha256()
    for part in (
        _source_digest(paths),
        _versions(),
        name,
        described,
        structure,
        ";".join(f"{x.shape}{x.dtype}{getattr(x, 'weak_type', False)}" for x in leaves),
        str(jax.config.jax_enable_x64),
        str(jax.config.jax_numpy_dtype_promotion),
        str(jax.config.jax_numpy_rank_promotion),
        str(jax.config.jax_default_matmul_precision),
        str(equinox_checks_mode()),  # as traced now: jaxrb's calls trace them as NaN
        jax.default_backend(),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def _load_or_export(key, fn, static, in_tree, leaves, cache_dir, quiet):
    """(compiled call of the flat array leaves, output structure, the executable's file if it
    was read from one), or None where the program cannot be exported. Loads, in order of
    preference, the compiled executable kept for this machine, the exported program (then
    compiled: JAX's persistent cache may have it), or traces and exports `fn`; what it makes
    it keeps."""
    if callable(cache_dir):
        cache_dir = cache_dir()
    if cache_dir is None:
        from ._compilation import default_cache_dir

        cache_dir = default_cache_dir() / "programs"
    path = Path(cache_dir) / f"{key}.bin"
    avals = [jax.ShapeDtypeStruct(np.shape(x), x.dtype) for x in leaves]
    executable = path.with_suffix(f".{_machine_key()}.exe")
    loaded = _load_executable(executable, avals)
    if loaded is not None:
        return *loaded, executable
    exported = None
    if path.exists():
        try:
            program, out_tree = pickle.loads(path.read_bytes())
            exported = export.deserialize(bytearray(program))
            found = [(a.shape, a.dtype) for a in exported.in_avals]
            if found != [(a.shape, a.dtype) for a in avals]:
                exported = None
            else:
                mark_used(path)
        except Exception:  # a damaged or foreign file: export again and replace it
            exported = None
    if exported is None:
        # traced with the arguments' weak types (a weakly typed float64 scalar combines with
        # float32 arrays as float32, where a strong one would not combine at all)
        traced = [
            jax.ShapeDtypeStruct(np.shape(x), x.dtype, weak_type=getattr(x, "weak_type", False))
            for x in leaves
        ]
        made = _export(fn, static, in_tree, traced, quiet)
        if made is None:
            return None
        exported, out_tree, blob = made
        write_atomically(path, blob)  # whole files: workers may write the same key at once
    compiled, code = _compile(exported, avals)
    if code is not False:
        kernels = _custom_kernels(exported)
        if all(k.startswith("lapack_") for k in kernels):
            _keep_executable(executable, compiled, out_tree, code, lapack=bool(kernels))
    return compiled, out_tree, None


def _compile(exported, avals):
    """(the compiled program, its executable's bytes): None where XLA compiled it here (it
    then serialises whole), the bytes JAX's persistent cache held where that cache served it
    (the compiled program then serialises without its code), False where it was served but
    the bytes could not be seen (another JAX)."""
    from jax._src import compilation_cache

    extract = getattr(compilation_cache, "extract_executable_and_time", None)
    monitoring = jax.monitoring
    if extract is None or not hasattr(monitoring, "unregister_event_listener"):
        return jax.jit(exported.call).lower(*avals).compile(), False
    hits, read = [], []

    def count(event, **kwargs):
        if event == "/jax/compilation_cache/cache_hits":
            hits.append(event)

    def extract_and_see(entry):
        code, compile_time = extract(entry)
        read.append(code)
        return code, compile_time

    monitoring.register_event_listener(count)
    compilation_cache.extract_executable_and_time = extract_and_see
    try:
        compiled = jax.jit(exported.call).lower(*avals).compile()
    finally:
        compilation_cache.extract_executable_and_time = extract
        monitoring.unregister_event_listener(count)
    if not hits:
        return compiled, None
    return compiled, (read[-1] if len(read) == 1 else False)


def _custom_kernels(exported) -> set[str]:
    """The custom kernels the exported program calls (`stablehlo.custom_call` targets)."""
    if b"custom_call" not in exported.mlir_module_serialized:
        return set()
    return set(re.findall(r"custom_call @([\w.$-]+)", exported.mlir_module()))


def _set_up_lapack() -> bool:
    """Set jaxlib's LAPACK kernels up, as lowering a call to one does; False where this
    jaxlib has no such set-up."""
    try:
        from jaxlib import lapack

        lapack._lapack.initialize()
    except Exception:  # noqa: BLE001
        return False
    return True


def _export(fn, static, in_tree, avals, quiet):
    """Trace and export `fn` at `avals`: (exported, output structure, the file's bytes), or
    None where it cannot be exported (warned about unless `quiet`)."""
    out_tree = []

    def flat(*flat_leaves):
        args, kwargs = eqx.combine(jax.tree.unflatten(in_tree, flat_leaves), static)
        out_leaves, tree = jax.tree.flatten(fn(*args, **kwargs))
        out_tree.append(tree)
        return out_leaves

    try:
        exported = export.export(jax.jit(flat))(*avals)
        program = exported.serialize()
        blob = pickle.dumps((bytes(program), out_tree[-1]))
        if pickle.loads(blob)[1] != out_tree[-1]:
            raise ValueError("the output structure does not survive pickling")
    except Exception as error:  # noqa: BLE001  (any failure: trace as usual instead)
        if not quiet:
            warnings.warn(
                f"persistent_jit: {getattr(fn, '__qualname__', fn)} is traced as usual "
                f"({type(error).__name__}: {str(error)[:200]})",
                stacklevel=4,
            )
        return None
    return exported, out_tree[-1], blob


@functools.cache
def _machine_key() -> str:
    """What a compiled executable depends on besides its program: the backend and its
    version, the device, XLA's flags and, on a CPU, the processor (its model and features:
    XLA compiles for the host's instruction set). 16 hex digits."""
    import platform

    device = jax.devices()[0]
    parts = [
        device.platform,
        device.client.platform_version,
        device.device_kind,
        os.environ.get("XLA_FLAGS", ""),
        platform.machine(),
    ]
    if device.platform == "cpu":
        try:
            info = Path("/proc/cpuinfo").read_text().split("\n\n")[0]
            parts += [ln for ln in info.splitlines() if ln.startswith(("model name", "flags"))]
        except OSError:
            parts.append(platform.processor())
    return hashlib.sha256("\0".join(parts).encode()).hexdigest()[:16]


def _load_executable(path: Path, avals):
    """The compiled executable kept at `path` and its output structure, or None (absent,
    damaged, or made for other argument types)."""
    if not path.exists():
        return None
    try:
        from jax.experimental import serialize_executable

        payload, in_tree, out_tree, exe_out_tree, lapack = pickle.loads(path.read_bytes())
        if lapack and not _set_up_lapack():
            return None
        compiled = serialize_executable.deserialize_and_load(
            zlib.decompress(payload), in_tree, exe_out_tree
        )
        found = [(a.shape, a.dtype) for a in jax.tree.leaves(compiled.args_info)]
        if found != [(a.shape, a.dtype) for a in avals]:
            return None
        mark_used(path)
        return compiled, out_tree
    except Exception:  # noqa: BLE001  (a damaged or foreign file: removed, compiled again)
        path.unlink(missing_ok=True)
        return None


def _keep_executable(path: Path, compiled, out_tree, code=None, lapack=False) -> None:
    """Keep `compiled` at `path` (compressed; skipped where the backend cannot serialise),
    with `code` (an executable's bytes as JAX's cache held them) in place of its own
    serialisation where given; `lapack`: whether it calls LAPACK's kernels."""
    try:
        from jax.experimental import serialize_executable

        if code is None:
            payload, in_tree, exe_out_tree = serialize_executable.serialize(compiled)
        else:
            payload, in_tree, exe_out_tree = _serialize_with_code(compiled, code)
        blob = pickle.dumps((zlib.compress(payload, 1), in_tree, out_tree, exe_out_tree, lapack))
    except Exception:  # noqa: BLE001  (no serialisation: the exported program is kept)
        return
    write_atomically(path, blob)


def _serialize_with_code(compiled, code: bytes):
    """`jax.experimental.serialize_executable.serialize(compiled)`, with `code` as the
    serialised XLA executable (its pickler swapped for the call)."""
    from jax._src.lib import _jax, xla_client
    from jax.experimental import serialize_executable

    pickler = serialize_executable._JaxPjrtPickler

    class WithCode(pickler):
        def persistent_id(self, obj):
            if isinstance(obj, (xla_client.LoadedExecutable, _jax.Executable)):
                return ("exec", code)
            return super().persistent_id(obj)

    serialize_executable._JaxPjrtPickler = WithCode
    try:
        return serialize_executable.serialize(compiled)
    finally:
        serialize_executable._JaxPjrtPickler = pickler
