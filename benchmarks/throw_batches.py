"""Batches of dice throws with few and many impacts: what a batch costs per die.

N dice (16 mm cube, 4.5 g) thrown onto a floor with friction 0.3 and a restitution per die
drawn from U(0.3, 0.95), from heights U(0.1, 0.3) m with a random attitude, spin
U(-30, 30) rad/s per body axis and horizontal speed U(-0.5, 0.5) m/s; T = 5 s, 11 saves,
`max_impacts` = 200, Tsit5 at rtol = atol = 1e-8, float64. Methods, each on the same throws:

- loop: the compiled one-die `jaxrb.simulate` called once per die (with `--loop K`, on the
  first K dice only: its cost per die and the impact counts compared are those K dice's);
- vmap: `jax.jit(jax.vmap(jaxrb.simulate))` over the batch (every member runs as many passes
  as the longest throw);
- lanes L: `jaxrb.simulate_throws` with L lanes refilled as throws finish; "default" is its
  default lane count (`jaxrb.contact.default_lanes`: 1 on a CPU, 64 on a GPU). One lane on
  a CPU splits the throws over the CPU devices, and the benchmarks start JAX with one per
  core (`benchmarks/__init__.py`); the loop and vmap run on the first.

The table gives the steady wall time per die (the second call), the first call minus the
steady one (compile), and how many dice keep the loop's impact count (a die's landing is
chaotic: batched arithmetic differs from unbatched by roundoff, which a long tumbling throw
amplifies; see `tests/test_contact_dice.py` for the short-horizon comparison).

Run: python -m benchmarks.throw_batches --n 64 --lanes default,8,16 --out bench_out
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore

HALF, MASS, FRICTION = 0.008, 0.0045, 0.3
MAX_IMPACTS = 200


def scene_with(restitution):
    body = jaxrb.RigidBody(jnp.asarray(MASS), shape=jaxrb.Box(jnp.full(3, HALF)))
    floor = jaxrb.Floor(restitution, jnp.asarray(FRICTION))
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=floor)


def throws(n, seed=0):
    """(restitutions (N,), initial states with leaves (N, ...))."""
    k = jax.random.split(jax.random.key(seed), 6)
    e = jax.random.uniform(k[0], (n,), minval=0.3, maxval=0.95)
    z = jax.random.uniform(k[1], (n,), minval=0.1, maxval=0.3)
    q = jaxrb.quat_normalize(jax.random.normal(k[2], (n, 4)))
    w = jax.random.uniform(k[3], (n, 3), minval=-30.0, maxval=30.0)
    vxy = jax.random.uniform(k[4], (n, 2), minval=-0.5, maxval=0.5)
    v = jnp.concatenate([vxy, jnp.zeros((n, 1))], -1)
    pos = jnp.stack([jnp.zeros(n), jnp.zeros(n), z], -1)
    return e, jaxrb.make_state(pos=pos, quat=q, vel=v, omega=w)


def timed(fn):
    """(first call s, steady call s, output)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return first, time.perf_counter() - t0, out


def run(n, lanes, t_end, n_loop=None):
    e, states = throws(n)
    ts = jnp.linspace(0.0, t_end, 11)
    kw = dict(max_impacts=MAX_IMPACTS, throw=False)
    one = jax.jit(lambda e, s: jaxrb.simulate(scene_with(e), s, ts, **kw))

    n_loop = n if n_loop is None else min(n_loop, n)

    def loop():
        return [one(e[i], jax.tree.map(lambda x, i=i: x[i], states)) for i in range(n_loop)]

    vmapped = jax.jit(jax.vmap(lambda e, s: jaxrb.simulate(scene_with(e), s, ts, **kw)))
    scenes = jax.vmap(scene_with)(e)
    loop_name = "loop of the compiled one-die simulate"
    if n_loop < n:
        loop_name += f" (first {n_loop} dice)"
    methods = [(loop_name, loop)]
    methods.append(("jax.vmap(simulate)", lambda: vmapped(e, states)))
    for L in lanes:
        count = jaxrb.contact.default_lanes(n) if L is None else L
        label = f"{count} lane{'s' if count > 1 else ''}"
        methods.append(
            (
                f"simulate_throws, {'default: ' if L is None else ''}{label}",
                lambda L=L: jaxrb.simulate_throws(
                    scenes, states, ts, batched_scene=True, lanes=L, max_impacts=MAX_IMPACTS
                ),
            )
        )
    rows, loop_counts, loop_cost = [], None, None
    for name, fn in methods:
        first, steady, out = timed(fn)
        if isinstance(out, list):  # the loop, over its own dice
            members = n_loop
            counts = np.array([int(r.impacts.count) for r in out])
            ok = np.array([int(r.result._value) == 0 for r in out])
        else:
            members = n
            counts = np.asarray(out.impacts.count)
            ok = np.asarray(out.result._value) == 0
        per_die = steady / members
        if loop_counts is None:
            loop_counts, loop_cost = counts, per_die
        rows.append(
            (
                name,
                per_die * 1e3,
                loop_cost / per_die,
                first - steady,
                float(np.mean(counts[:n_loop] == loop_counts)),
                int(np.sum(~ok)),
            )
        )
        print(f"{name}: {per_die * 1e3:.1f} ms per die", flush=True)
    return rows, loop_counts


def table(rows, loop_counts, n, t_end):
    lines = [
        f"{n} dice, T = {t_end} s, device {C.device_name()}; impacts per die (the loop's "
        f"dice): mean {loop_counts.mean():.1f}, min {loop_counts.min()}, max {loop_counts.max()}",
        "",
        "| method | ms per die | loop's cost / this | compile (s) | same impact count as the "
        "loop | non-successful |",
        "|---|---|---|---|---|---|",
    ]
    for name, ms, ratio, compile_s, same, bad in rows:
        lines.append(f"| {name} | {ms:.1f} | {ratio:.2f} | {compile_s:.0f} | {same:.0%} | {bad} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description="batches of dice throws: loop, vmap, lanes")
    p.add_argument("--n", type=int, default=64, help="dice")
    p.add_argument(
        "--lanes",
        default="default,8,16",
        help="comma-separated lane counts ('default': simulate_throws' own choice)",
    )
    p.add_argument("--t-end", type=float, default=5.0)
    p.add_argument("--loop", type=int, default=None, help="run the loop on the first K dice only")
    p.add_argument("--out", default=None, help="folder for throw_batches.md")
    p.add_argument("--force", action="store_true", help="overwrite an existing result")
    a = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    lanes = [None if x == "default" else int(x) for x in a.lanes.split(",") if x]
    paths = C.output_paths(p, a.out, ["throw_batches.md"], a.force) if a.out else None
    rows, counts = run(a.n, lanes, a.t_end, a.loop)
    text = table(rows, counts, a.n, a.t_end)
    print(text)
    if paths:
        with open(paths[0], "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
