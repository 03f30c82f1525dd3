"""The CPU compiler settings of `speed_up_compilation`: which flags it adds, that it leaves a
user's own choices alone, and that XLA honours the loop pass it turns off."""

import os
import re
import subprocess
import sys
from pathlib import Path

from jaxrb._compilation import (
    CPU_FLAG,
    LIBRARY_FUSIONS_FLAG,
    LOOP_HOISTING_FLAG,
    SMALL_LOOPS_FLAG,
    cpu_compiler_flags,
)


def test_the_cpu_flags_added_where_only_the_cpu_runs():
    assert cpu_compiler_flags("", cpu_only=True).split() == [
        CPU_FLAG,
        LOOP_HOISTING_FLAG,
        SMALL_LOOPS_FLAG,
        LIBRARY_FUSIONS_FLAG,
    ]
    assert cpu_compiler_flags(" --xla_foo=1 ", cpu_only=True).split() == [
        "--xla_foo=1",
        CPU_FLAG,
        LOOP_HOISTING_FLAG,
        SMALL_LOOPS_FLAG,
        LIBRARY_FUSIONS_FLAG,
    ]


def test_loop_pass_kept_where_an_accelerator_may_run():
    assert cpu_compiler_flags("", cpu_only=False) == CPU_FLAG


def test_a_users_own_choices_are_left_alone():
    mine = (
        "--xla_cpu_use_fusion_emitters=true --xla_disable_hlo_passes=algsimp "
        "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=0 "
        "--xla_cpu_experimental_ynn_fusion_type=individual_dot"
    )
    assert cpu_compiler_flags(mine, cpu_only=True) == mine


# In a process of its own: `speed_up_compilation` changes `XLA_FLAGS` before JAX starts its
# backend. A loop whose body computes sin(a) from an argument `a` that does not change in the
# loop: XLA's hoisting pass moves the sine out of the loop; with the pass off it stays in the
# loop's body. Prints the flags; whether a loop over 32 KB of data, one over 1 MB (more than
# `SMALL_LOOP_BYTES`) and one whose body holds an 8 x 8 float64 matrix product became one
# kernel each (a call XLA marks `xla_cpu_small_call`; by default only loops over less than
# 1 KB do, and none that holds a product XLA hands to YNNPACK); and whether the sine loop's
# body (or a computation it calls) holds the sine.
_PROBE = """
import re, sys
import jax, jax.numpy as jnp
import jaxrb
if sys.argv[1] == "on":
    jaxrb.speed_up_compilation(cache=False)
import os
jax.config.update("jax_enable_x64", True)
print(os.environ.get("XLA_FLAGS", ""))
g = lambda x: jax.lax.fori_loop(0, 5, lambda i, y: jnp.cos(y), x)
big = jax.jit(g).lower(jnp.ones(4096)).compile().as_text()
print("one kernel" if "xla_cpu_small_call" in big else "kernels")
huge = jax.jit(g).lower(jnp.ones(131072)).compile().as_text()
print("one kernel" if "xla_cpu_small_call" in huge else "kernels")
h = lambda m, x: jax.lax.fori_loop(0, 5, lambda i, y: jnp.tanh(m @ y.T), x)
product = jax.jit(h).lower(jnp.ones((8, 8)), jnp.ones((8, 8))).compile().as_text()
print("one kernel" if "xla_cpu_small_call" in product else "kernels")
f = lambda a, x: jax.lax.fori_loop(0, 5, lambda i, y: y + jnp.sin(a), x)
text = jax.jit(f).lower(jnp.ones(8), jnp.ones(8)).compile().as_text()
blocks = {}
for block in re.split(r"\\n(?=\\S)", text):
    head = re.match(r"(?:ENTRY )?%?([\\w.\\-]+)", block)
    if head:
        blocks[head.group(1)] = block
(body,) = re.findall(r"while\\(.*body=%?([\\w.\\-]+)", text)
seen, todo = set(), [body]
while todo:
    name = todo.pop()
    if name in seen or name not in blocks:
        continue
    seen.add(name)
    todo += re.findall(r"(?:calls|to_apply|body|condition)=%?([\\w.\\-]+)", blocks[name])
print("sine in loop" if any(" sine(" in blocks[n] for n in seen) else "sine hoisted")
"""


def _python(code, platforms, *args):
    """The standard output of `code` run by a new interpreter with `JAX_PLATFORMS=platforms`
    and no `XLA_FLAGS` of the suite's."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = platforms
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        env=env,
        check=True,
        timeout=120,
        capture_output=True,
        text=True,
    ).stdout


def _probe(mode):
    return _python(_PROBE, "cpu", mode).splitlines()[-5:]


def test_speed_up_compilation_sets_the_cpu_loop_passes():
    flags, loop, large_loop, product_loop, where = _probe("on")
    assert CPU_FLAG in flags.split() and LOOP_HOISTING_FLAG in flags.split()
    assert SMALL_LOOPS_FLAG in flags.split() and LIBRARY_FUSIONS_FLAG in flags.split()
    assert loop == "one kernel"
    assert large_loop == "kernels"  # above the bound: kernel by kernel, as by default
    assert product_loop == "one kernel"
    assert where == "sine in loop"
    # the probe can tell: without the settings XLA hoists the sine and runs both loops'
    # bodies kernel by kernel
    flags, loop, large_loop, product_loop, where = _probe("off")
    assert not re.search("xla_disable_hlo_passes|xla_backend_extra_options|ynn", flags)
    assert loop == "kernels" and large_loop == "kernels"
    assert product_loop == "kernels"
    assert where == "sine hoisted"


def test_loop_pass_left_on_where_jax_platforms_names_an_accelerator():
    """JAX_PLATFORMS=cuda on this machine: JAX never starts (nothing is computed), but the
    setting must not reach the programs an accelerator would compile."""
    code = (
        "import os, jaxrb; jaxrb.speed_up_compilation(cache=False); print(os.environ['XLA_FLAGS'])"
    )
    assert _python(code, "cuda").split() == [CPU_FLAG]


def test_importing_jaxrb_starts_no_backend():
    """`speed_up_compilation` can set the compiler only before JAX starts its backend, so no
    module of the package (nor the studies a script imports before its `main`) may compute
    anything with JAX at import."""
    code = """
import importlib, pkgutil, sys
sys.path.insert(0, sys.argv[1])
import jaxrb
from jax._src import xla_bridge
names = [m.name for m in pkgutil.walk_packages(jaxrb.__path__, "jaxrb.")]
names += ["benchmarks.roulette", "benchmarks.contact_throws", "benchmarks.b4_die_impacts"]
started = []
for name in names:
    importlib.import_module(name)
    if xla_bridge._backends and not started:
        started.append(name)
print(len(names), started[0] if started else "none")
"""
    root = str(Path(__file__).resolve().parents[1])  # the repository: the studies' package
    count, first = _python(code, "cpu", root).split()
    assert int(count) > 40
    assert first == "none", f"importing {first} started JAX's backend"
