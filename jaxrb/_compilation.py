"""Process-wide compilation settings that make jaxrb's programs quicker to start.

jaxrb never changes JAX's global configuration by itself; `speed_up_compilation` is for a
program's entry point (the `jaxrb` command line calls it, and so can a script or notebook):

- JAX's persistent compilation cache: a compiled program is written to a directory and read
  back by the next process that compiles the same program, instead of compiling it again;
- on the CPU, XLA's older kernel emitters (`--xla_cpu_use_fusion_emitters=false`): for
  jaxrb's contact programs (tens of thousands of small operations) they compile in about
  four fifths of the time and run no slower (measured on a 2-core x86 CPU: a die's
  program 55 s -> 43 s of compile CPU time, its 16 s throw about 0.23 s either way);
- on the CPU, without XLA's pass that hoists loop-invariant code out of while loops
  (`--xla_disable_hlo_passes=while-loop-invariant-code-motion`): in a contact program's
  loops nested three deep (a fit's iterations, the passes between events, the solver's
  steps) it cost the most compile time of any pass, and hoisting gained nothing at run time
  (a 2-core x86 CPU: `fit_contact`'s program compiled in 21 s instead of 30-34 s, the
  default die scene in 10.2 s instead of 11.2-12.1 s, and B4's die ran in 19-20 ms
  instead of 23-28 ms; B1's batched free bodies ran as fast either way). Left out where an
  accelerator may run the programs (an accelerator plugin installed and `JAX_PLATFORMS`
  not `cpu`), where it has not been measured;
- on the CPU, every while loop whose operations XLA can emit itself (no library call: a
  matrix product it hands to Eigen, a custom call, a scatter) compiled as one kernel, loop
  and body together, up to `SMALL_LOOP_BYTES` of data accessed in one pass of its body
  (XLA's default is 1 KB): a contact simulation's solver loop then runs without a kernel
  launch per fused operation (a 2-core x86 CPU: a coin rolling on its rim for 1 s at
  tolerance 1e-12, 16552 steps, in 0.37-0.42 s instead of 1.53 s; a roulette ball's first
  second on the wall, 1048 steps, in 28 ms instead of 171 ms; B1's free bodies as before;
  compile times as before). The bound, 256 KB: on a 2-core AMD EPYC B4's dice, coins and a
  roulette ball ran as fast with 128 KB as with 64 MB (a die's throw 8.9 ms, twice as long
  with 32 KB), while from 1 MB up the loop over a contact simulation's segments inside a
  fit (with its forward derivatives: 26 thousand of the program's 28 thousand lines of
  HLO) became one kernel too, and `fit_contact`'s first call took 72-85 s instead of
  26 s. Also left out where an accelerator may run the programs;
- on the CPU, no YNNPACK library fusions (`--xla_cpu_experimental_ynn_fusion_type=`):
  XLA hands small float64 matrix products (8 x 8 and up) and the reductions around them to
  that library, and a loop that holds such a call cannot be compiled as one kernel (above).
  Without them the impact law's loops (its Gauss-Seidel sweeps and polishing solves, 12 x
  12) compile whole too (a 2-core x86 CPU, both programs in one process, runs alternating,
  medians: the default die scene's throw in 68 ms instead of 103 ms, B4's dice 64 ms
  instead of 91 ms each; B1's free bodies, a coin on its rim and a roulette ball as
  before; the die's compile up to 10 % longer). A contact simulation's loop over its
  segments still runs kernel by kernel: it holds a sort (the impact law orders the touching
  points), and compiled as one kernel it took 145 s instead of 28 s to compile. Left out
  where an accelerator may run the programs;
- optionally (`nan_checks`), equinox's run-time checks without host callbacks, so that
  derivative programs compiled by the caller's own `jax.jit` can be cached too;
- jaxrb's traced programs (`programs`): the persistent cache still needs every program
  traced before it can look it up, and tracing a contact simulation takes longer than
  loading its compiled code; `persistent_jit` keeps the traced programs of jaxrb's own
  entry points beside the compiled ones;
- a size bound on that directory: the files used longest ago are removed when it holds
  more (`jaxrb._cache_size`).
"""

import importlib.metadata
import importlib.util
import os
import pkgutil
import sys
from pathlib import Path

import jax

from ._cache_size import cache_max_bytes, hook_jax_cache, prune_cache
from ._persistent import keep_programs

CPU_FLAG = "--xla_cpu_use_fusion_emitters=false"
LOOP_HOISTING_FLAG = "--xla_disable_hlo_passes=while-loop-invariant-code-motion"
SMALL_LOOP_BYTES = 1 << 18  # 256 KB
SMALL_LOOPS_FLAG = (
    f"--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={SMALL_LOOP_BYTES}"
)
LIBRARY_FUSIONS_FLAG = "--xla_cpu_experimental_ynn_fusion_type="


def default_cache_dir() -> Path:
    """The user's cache directory for jaxrb's compiled programs: `$JAXRB_CACHE_DIR` if set,
    else `$XDG_CACHE_HOME/jaxrb/jax` (default `~/.cache/jaxrb/jax`; on Windows
    `%LOCALAPPDATA%/jaxrb/jax`; on macOS `~/Library/Caches/jaxrb/jax`)."""
    if os.environ.get("JAXRB_CACHE_DIR"):
        return Path(os.environ["JAXRB_CACHE_DIR"]).expanduser()
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        base = Path(os.environ["LOCALAPPDATA"])
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "jaxrb" / "jax"


def _backend_started() -> bool:
    from jax._src import xla_bridge

    return bool(xla_bridge._backends)


def _cpu_only() -> bool:
    """Whether JAX will run on the CPU alone: `JAX_PLATFORMS` is `cpu`, or it is unset and
    no accelerator plugin (CUDA, ROCm, TPU) is installed."""
    platforms = (jax.config.jax_platforms or "").strip().lower()
    if platforms:
        return platforms == "cpu"
    try:
        import jax_plugins
    except ImportError:
        plugins = []
    else:
        plugins = list(pkgutil.iter_modules(jax_plugins.__path__))
    entry = list(importlib.metadata.entry_points(group="jax_plugins"))
    return not plugins and not entry and importlib.util.find_spec("libtpu") is None


def cpu_compiler_flags(flags: str, cpu_only: bool) -> str:
    """`flags` (an `XLA_FLAGS` value) with the CPU settings of the module docstring added,
    each unless `flags` already sets that option; all but the first only if `cpu_only`."""
    added = []
    if "xla_cpu_use_fusion_emitters" not in flags:
        added.append(CPU_FLAG)
    if cpu_only and "xla_disable_hlo_passes" not in flags:
        added.append(LOOP_HOISTING_FLAG)
    if cpu_only and "xla_backend_extra_options" not in flags:
        added.append(SMALL_LOOPS_FLAG)
    if cpu_only and "xla_cpu_experimental_ynn_fusion_type" not in flags:
        added.append(LIBRARY_FUSIONS_FLAG)
    return " ".join([flags.strip(), *added]).strip()


def speed_up_compilation(
    cache: bool = True,
    cache_dir=None,
    nan_checks: bool = False,
    programs: bool = True,
    program_sources=None,
    max_cache_mb: float | None = None,
) -> Path | None:
    """Turn on the persistent compilation cache (if `cache`) in `cache_dir` (default
    `default_cache_dir()`; a contact scene's program takes 0.5-2 MB there, an eager
    operation's a few kB, its size is bounded by `max_cache_mb` below, and the directory can
    be deleted at any time), and, if JAX has not started its CPU backend yet and `XLA_FLAGS`
    does not choose otherwise, the CPU compiler settings of the module docstring (the
    quicker kernel emitters and, where only the CPU runs programs, no hoisting of
    loop-invariant code, small loops compiled as one kernel each, no YNNPACK fusions).
    Changes process-wide settings: call it once at the start of a program. Returns the
    cache directory (None without a cache).

    `nan_checks=True` also makes equinox's run-time checks (`equinox.error_if`, used inside
    diffrax, optimistix and lineax) return NaN where they fail instead of raising through a
    host callback, in every program the process compiles from then on (equinox's
    `EQX_ON_ERROR=nan`; left alone if the environment sets `EQX_ON_ERROR`). JAX's persistent
    cache keeps no program with a host callback, and a derivative through an event time
    (an impact, a mode change) carries such a check, in the linear solve of the event
    time's implicit derivative. jaxrb's own calls (`simulate`, the fits) compile their
    programs without it anyway; this setting is for derivatives compiled by your own
    `jax.jit`, e.g. `jax.jit(jax.grad(loss))` of a loss that calls `simulate`. A failed
    solve is still flagged in jaxrb's result codes, and `throw=True` still raises; your own
    equinox checks return NaN too.

    `programs=True` (with `cache`; `cache=False` turns it off) also keeps the traced
    programs of jaxrb's own entry points (`simulate`, `simulate_throws`, `simulate_batch`,
    the fits) in `cache_dir / "programs"`, with the executables compiled from them (about
    as large again as JAX's copy), so that a later process loads them instead of tracing
    and lowering (`persistent_jit`; a call whose scene holds a class defined outside jaxrb,
    e.g. your own force, is traced as usual). The key holds jaxrb's source, so an edit or
    another version traces again. `program_sources` (files or folders of your own code;
    default: the environment variable `JAXRB_PROGRAM_SOURCES`, paths separated by
    `os.pathsep`) lets the entry points keep programs that hold your own functions and
    classes too (a force, a `sweep`'s function, a fit's residuals), keyed by the content
    of those files: they must then depend only on code there, in jaxrb and in the packages
    whose versions the key holds (`persistent_jit`).
    `max_cache_mb` bounds the cache directory's size (megabytes; default
    `$JAXRB_CACHE_MAX_MB`, else 1024; 0 or "none" in the variable: no bound). An upgrade or
    an edit adds programs beside the old ones and nothing replaces them, so when the
    directory holds more, the files used longest ago are removed (down to 80 % of the
    bound), once, here.
    """
    if nan_checks and "EQX_ON_ERROR" not in os.environ:
        from ._solve import equinox_checks_mode, set_equinox_checks

        if equinox_checks_mode() == "raise":
            set_equinox_checks("nan")
    if not _backend_started():
        flags = os.environ.get("XLA_FLAGS", "")
        os.environ["XLA_FLAGS"] = cpu_compiler_flags(flags, _cpu_only())
    if not cache:
        keep_programs(False)
        return None
    directory = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    prune_cache(directory, cache_max_bytes(max_cache_mb))
    hook_jax_cache()  # reads marked for the next prune; writes whole files only
    jax.config.update("jax_compilation_cache_dir", str(directory))
    if programs:
        keep_programs(True, directory / "programs", program_sources)
    # every program, the smallest too: on a 2-core x86 CPU XLA compiles one of the small
    # programs that eager operations (a scene's checks, the plots' arithmetic) make in
    # 20-50 ms and reads it back in about 9 ms; a `jaxrb run` or a test makes hundreds
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return directory
