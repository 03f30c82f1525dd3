"""How long a die scene takes to compile, against how long it takes to run.

    python -m benchmarks.compile_times --out bench_out [--batch 16] [--xla-defaults]

The default scene of `jaxrb run` (a 16 mm die thrown onto a table, contact engine, float64):
one die (`jaxrb.simulate`), and a batch of `--batch` dice with random spins
(`jax.vmap(jaxrb.simulate)`). For each: tracing and lowering (s), XLA's compile (s), the
optimised program's size (lines of HLO text) and the steady run time (best of 3), with no
persistent cache, so every number is a cold start's. XLA's CPU settings are those that
`jaxrb run` and `jaxrb.speed_up_compilation` choose (the older kernel emitters, no hoisting
of loop-invariant code, small loops as one kernel, no YNNPACK fusions), or XLA's defaults
with `--xla-defaults`. Writes
`compile_times.md`.
"""

import argparse
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402
from jaxrb._scene_file import default_scene_path, load_scene, make_solver  # noqa: E402

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore


def measure(fn, arg, repeats=3):
    """(lower s, compile s, HLO lines, best run s, output) of `jax.jit(fn)` at `arg`."""
    jitted = jax.jit(fn)
    t0 = time.perf_counter()
    lowered = jitted.lower(arg)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    lines = compiled.as_text().count("\n")
    out = jax.block_until_ready(compiled(arg))
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(compiled(arg))
        runs.append(time.perf_counter() - t)
    return t1 - t0, t2 - t1, lines, min(runs), out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="overwrite earlier results")
    p.add_argument("--batch", type=int, default=16, help="dice in the vmapped batch")
    p.add_argument(
        "--xla-defaults",
        "--default-emitters",
        dest="xla_defaults",
        action="store_true",
        help="XLA's default CPU settings (kernel emitters, loop passes)",
    )
    a = p.parse_args(argv)
    if a.batch < 1:
        p.error("--batch must be >= 1")
    (path,) = C.output_paths(p, a.out, ["compile_times.md"], a.force)
    if not a.xla_defaults:
        jaxrb.speed_up_compilation(cache=False)  # the compiler settings only: no cache
    spec = load_scene(default_scene_path())
    kwargs = dict(spec.options, solver=make_solver(spec.options["solver"]), throw=False)

    def one(state0):
        return jaxrb.simulate(spec.scene, state0, spec.ts, **kwargs)

    spins = np.random.default_rng(0).normal(size=(a.batch, 3)) * 15.0
    batch = jax.tree.map(lambda x: jnp.broadcast_to(x, (a.batch, *jnp.shape(x))), spec.state0)
    batch = eqx.tree_at(lambda s: s.omega, batch, jnp.asarray(spins))
    rows = []
    for label, fn, arg in (
        ("one die", one, spec.state0),
        (f"{a.batch} dice, jax.vmap", jax.vmap(one), batch),
    ):
        low, comp, lines, run, out = measure(fn, arg)
        impacts = np.asarray(out.impacts.count).ravel().tolist()
        rows.append((label, low, comp, lines, run, impacts))
        print(
            f"{label}: lower {low:.2f} s, compile {comp:.2f} s, {lines} HLO lines, "
            f"run {run * 1e3:.1f} ms, impacts {impacts}",
            flush=True,
        )
    settings = "XLA's defaults" if a.xla_defaults else os.environ.get("XLA_FLAGS", "")
    text = "\n".join(
        [
            f"# Compile against run time, the default die scene ({C.device_name()}; "
            f"XLA flags: {settings}; Python {sys.version.split()[0]}, jax {jax.__version__})\n",
            "| call | trace + lower (s) | compile (s) | optimised HLO (lines) | run (ms) "
            "| impacts |",
            "|---|---|---|---|---|---|",
            *(
                f"| {label} | {low:.2f} | {comp:.2f} | {lines} | {run * 1e3:.1f} | "
                f"{', '.join(map(str, imp)) if len(imp) <= 4 else f'{sum(imp)} in all'} |"
                for label, low, comp, lines, run, imp in rows
            ),
            "",
        ]
    )
    with open(path, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
