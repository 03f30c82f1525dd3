# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""B1's speed targets, measured interleaved: every method on the same tolerance grid, one
process, one device, each configuration timed twice in a row per round.

    python -m benchmarks.b1_targets --out bench_out [--n 1000] [--rounds 5] [--force]

The problem and the error measure are B1's (`benchmarks/b1_torque_free.py`): a torque-free
body with I = (1, 2, 3), N bodies, T = 20, the worst body's error against the exact omega and
a Dopri8 reference attitude at tol 1e-13. Each adaptive method runs at every tolerance of one
grid (rtol = atol, a traced argument, so one compilation per method); its error is taken from
the first call, its time is the best over the rounds (the second call of a pair is the
quicker one where the first follows another program's). For each method the cheapest
configuration whose error is <= 1e-8 is compared with the batched solve's. MuJoCo's C RK4
(all N bodies in one scene) joins each round where the `mujoco` package is installed.
Plain diffrax's own batched solve of the hand-written right-hand side (one solve, the worst
body's RMS norm) shows what the batched solve costs without jaxrb around it.
Beside the targets' methods, `jaxrb.simulate` of the first body alone (no `jax.vmap`) with
Tsit5 and Dopri8 shows which solver is cheaper for one body: the default solver's choice by
tolerance.

Timing every configuration in every round, rather than each method's rows one after the
other, keeps a change in the machine's load from favouring one method: a second job on
one of the two cores slows some methods more than others.

Writes `b1_targets.md` and `b1_targets.png` (error against time per body).
"""

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C, b1_torque_free as B1
except ImportError:  # run as a script
    import _common as C  # type: ignore
    import b1_torque_free as B1  # type: ignore

BOUND = 1e-8  # the error the targets are stated at
TOLS = (1e-7, 1e-8, 3e-9, 1e-9, 7e-10, 5e-10, 4e-10, 3e-10, 2e-10, 1e-10)
MUJOCO_STEPS = (0.01, 0.005, 0.0025)
BATCHED = "jaxrb.simulate, batched state (one solve), Dopri8"
ALONE = "jaxrb.simulate, the first body alone"  # not a B1 target: the default solver's choice


def methods(n):
    """(name, function of the tolerance returning (omega_T, quat_T, steps per body), bodies)
    for every adaptive method: on the same N bodies, and `jaxrb.simulate` on the first of
    them alone (no `jax.vmap`: what decides the default solver for one body)."""
    omega0 = B1.initial_omegas(n)
    scene = B1.scene_for(jnp.float64)
    ts = jnp.array([0.0, B1.T_END])
    states0 = jaxrb.make_state(omega=omega0)

    def through_jaxrb(solver, batched, alone=False):
        def one(s, tol):
            return jaxrb.simulate(scene, s, ts, solver=solver, rtol=tol, atol=tol, throw=False)

        fn = jax.jit(one if batched or alone else jax.vmap(one, in_axes=(0, None)))
        start = jax.tree.map(lambda x: x[0], states0) if alone else states0

        def call(tol):
            tr = fn(start, jnp.asarray(tol))
            w, q = tr.states.omega[..., -1, :], tr.states.quat[..., -1, :]
            return w.reshape(-1, 3), q.reshape(-1, 4), tr.num_steps

        return call

    def plain(solver, batch=False):
        """The hand-written rhs: vmapped (each body its own solve), or with `batch` one solve
        of all bodies whose controller takes the worst body's RMS norm (no jaxrb around it)."""
        if batch:
            fn = jax.jit(
                lambda w, tol: B1.plain_solve(solver, w, ts, tol, B1.members_first_rms_norm)
            )
        else:
            one = lambda w, tol: B1.plain_solve(solver, w, ts, tol)  # noqa: E731
            fn = jax.jit(jax.vmap(one, in_axes=(0, None)))
        return lambda tol: fn(omega0, jnp.asarray(tol))

    return omega0, [
        (BATCHED, through_jaxrb(dfx.Dopri8(), True), n),
        ("jaxrb.simulate, batched state (one solve), Tsit5", through_jaxrb(dfx.Tsit5(), True), n),
        ("plain diffrax Tsit5, hand-written rhs, vmap", plain(dfx.Tsit5()), n),
        ("plain diffrax Dopri8, hand-written rhs, vmap", plain(dfx.Dopri8()), n),
        (
            "plain diffrax Dopri8, hand-written rhs, one solve (batch norm)",
            plain(dfx.Dopri8(), batch=True),
            n,
        ),
        ("vmap(jaxrb.simulate), Tsit5", through_jaxrb(dfx.Tsit5(), False), n),
        ("vmap(jaxrb.simulate), Dopri8", through_jaxrb(dfx.Dopri8(), False), n),
        (ALONE + ", Tsit5", through_jaxrb(dfx.Tsit5(), False, alone=True), 1),
        (ALONE + ", Dopri8", through_jaxrb(dfx.Dopri8(), False, alone=True), 1),
    ]


def measure(n, rounds):
    """Rows (method, setting, error, best us/body, steps per body) of every configuration."""
    omega0, adaptive = methods(n)
    errors = {n: B1.make_errors(omega0)[0], 1: B1.make_errors(omega0[:1])[0]}
    configs = [
        (name, f"tol {tol:.0e}", lambda f=f, tol=tol: f(tol), k)
        for name, f, k in adaptive
        for tol in TOLS
    ]
    for h in MUJOCO_STEPS:
        go = B1.mujoco_runner(omega0, h)
        if go is not None:
            configs.append(("MuJoCo C RK4, N bodies in one scene", f"h {h:g}", go, n))
    found = {}
    for name, setting, call, k in configs:  # compiles, and the error of each configuration
        w, q, steps = jax.block_until_ready(call())
        found[name, setting] = [
            errors[k](w, q),
            math.inf,
            float(jnp.mean(jnp.asarray(steps, float))),
            k,
        ]
    for r in range(rounds):
        for name, setting, call, _ in configs:
            for _ in range(2):  # a call right after another program's can be slow (caches)
                t0 = time.perf_counter()
                jax.block_until_ready(call())
                found[name, setting][1] = min(found[name, setting][1], time.perf_counter() - t0)
        print(f"round {r + 1} of {rounds} done", flush=True)
    return [
        (name, setting, e, best / k * 1e6, steps)
        for (name, setting), (e, best, steps, k) in found.items()
    ]


def cheapest(rows, name):
    ok = [r for r in rows if r[0] == name and r[2] <= BOUND]
    return min(ok, key=lambda r: r[3], default=None)


def report(rows, n, rounds):
    """The markdown report: the cheapest configuration of each method with error <= 1e-8
    and its speed-up against the batched solve, then every row."""
    base = cheapest(rows, BATCHED)
    lines = [
        f"# B1 targets, measured interleaved (N = {n}, {rounds} rounds, device {C.device_name()}, "
        f"jax {jax.__version__}, diffrax {dfx.__version__})",
        "",
        f"Cheapest configuration of each method with error <= {BOUND:g}, against the batched "
        "solve (time per body, best of the rounds):",
        "",
        "| method | setting | error | us/body | batched solve's speed-up |",
        "|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r[0] for r in rows if not r[0].startswith(ALONE)):
        r = cheapest(rows, name)
        if r is None:
            lines.append(f"| {name} | none with error <= {BOUND:g} | - | - | - |")
        else:
            ratio = f"{r[3] / base[3]:.1f}x" if base is not None else "-"
            lines.append(f"| {name} | {r[1]} | {r[2]:.2e} | {r[3]:.1f} | {ratio} |")
    lines += [
        "",
        "Every configuration:",
        "",
        "| method | setting | error | us/body | steps per body |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {a} | {b} | {e:.2e} | {t:.1f} | {s:.0f} |" for a, b, e, t, s in rows]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="bench_out")
    p.add_argument("--n", type=int, default=1000, help="bodies in the batch")
    p.add_argument("--rounds", type=int, default=5, help="timed rounds over all configurations")
    p.add_argument("--force", action="store_true", help="overwrite an earlier report")
    a = p.parse_args(argv)
    if a.n < 1 or a.rounds < 1:
        p.error("--n and --rounds must be >= 1")
    path, png = C.output_paths(p, a.out, ["b1_targets.md", "b1_targets.png"], a.force)
    rows = measure(a.n, a.rounds)
    text = report(rows, a.n, a.rounds)
    with open(path, "w") as f:
        f.write(text)
    print(text)
    device = jax.devices()[0]
    C.plot_work_precision(
        [
            C.Row("B1", m, "float64", setting, a.n, e, t, math.nan, k)
            for m, setting, e, t, k in rows
        ],
        f"B1 targets, N = {a.n}, best of {a.rounds} interleaved rounds "
        f"({device.platform}:{device.device_kind})",
        png,
        legend_outside=True,
    )


if __name__ == "__main__":
    main()
