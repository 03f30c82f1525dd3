# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""Long runs: drift of energy, |L| and the quaternion norm over many rotation periods.

Torque-free B1 body (I = (1, 2, 3), omega0 = (1, 0, 1.5)) over `--periods` rotation periods
(default 1e4; the tests run a 100-period version): simulate_batch (diffrax Dopri8),
simulate (Tsit5), the Lie-group splitting and the exact flow. Heavy top (B2 scene) over
`--top-seconds`: energy error of the splitting (bounded) vs the adaptive Runge-Kutta methods
(drifting).

Run: python -m benchmarks.long_run --periods 10000 --out bench_out
"""

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxrb  # noqa: E402
from jaxrb._batched import simulate_batch  # noqa: E402
from jaxrb._exact_flow import torque_free_flow  # noqa: E402
from jaxrb._splitting import simulate_splitting  # noqa: E402
from jaxrb.analytic import flip_half_period  # noqa: E402

try:
    from . import _common as C, b2_heavy_top as B2
except ImportError:
    import _common as C  # type: ignore
    import b2_heavy_top as B2  # type: ignore


def drifts(scene, states, quat_norm_drift):
    E = jax.vmap(lambda s: jaxrb.energy(scene, s))(states)
    L = jax.vmap(lambda s: jaxrb.angular_momentum(scene, s))(states)
    Ln = jnp.linalg.norm(L, axis=-1)
    return (
        float(jnp.max(jnp.abs(E / E[0] - 1))),
        float(jnp.max(jnp.abs(Ln / Ln[0] - 1))),
        float(quat_norm_drift),
    )


def torque_free(periods):
    inertia = jnp.array([1.0, 2.0, 3.0])
    omega0 = jnp.array([1.0, 0.0, 1.5])
    period = 2 * float(flip_half_period(inertia, omega0))
    T = periods * period
    ts = jnp.linspace(0.0, T, 137)  # save times not commensurate with the period
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    s0 = jaxrb.make_state(omega=omega0)
    lines = [
        f"torque-free body, {periods} periods (T = {T:.4g} s)",
        "| method | rel. energy drift | rel. abs L drift | max abs quat norm - 1 | wall s (incl. compile) |",
        "|---|---|---|---|---|",
    ]
    runs = [
        (
            "simulate_batch Dopri8 tol 1e-10",
            lambda: simulate_batch(
                scene,
                jax.tree.map(lambda x: x[None], s0),
                ts,
                rtol=1e-10,
                atol=1e-10,
                max_steps=10**8,
            ),
        ),
        ("diffrax Tsit5 tol 1e-8", lambda: jaxrb.simulate(scene, s0, ts, max_steps=10**8)),
        ("splitting h 0.01", lambda: simulate_splitting(scene, s0, ts, dt=0.01)),
    ]
    for name, fn in runs:
        t0 = time.perf_counter()
        tr = jax.block_until_ready(fn())
        sec = time.perf_counter() - t0
        states = tr.states if tr.states.quat.ndim == 2 else jax.tree.map(lambda x: x[0], tr.states)
        e, ln, qn = drifts(scene, states, jnp.max(tr.quat_norm_drift))
        lines.append(f"| {name} | {e:.2e} | {ln:.2e} | {qn:.2e} | {sec:.1f} |")
    t0 = time.perf_counter()
    ex = jax.block_until_ready(torque_free_flow(inertia, s0, ts))
    sec = time.perf_counter() - t0
    e, ln, qn = drifts(scene, ex, jnp.max(jnp.abs(jnp.linalg.norm(ex.quat, axis=-1) - 1)))
    lines.append(f"| exact flow | {e:.2e} | {ln:.2e} | {qn:.2e} | {sec:.1f} |")
    return "\n".join(lines) + "\n", None


def heavy_top(seconds, out):
    scene = B2.make_scene()
    s0 = jax.tree.map(lambda x: x[0], B2.initial_states(1))
    ts = jnp.linspace(0.0, seconds, 201)
    res = {}
    lines = [
        f"heavy top, {seconds} s",
        "| method | max rel. energy error | final rel. energy error | wall s (incl. compile) |",
        "|---|---|---|---|",
    ]
    for name, fn in (
        ("splitting h 1e-3", lambda: simulate_splitting(scene, s0, ts, dt=1e-3)),
        (
            "diffrax Tsit5 tol 1e-6",
            lambda: jaxrb.simulate(scene, s0, ts, rtol=1e-6, atol=1e-6, max_steps=10**8),
        ),
        (
            "diffrax Dopri8 tol 1e-8",
            lambda: jaxrb.simulate(
                scene, s0, ts, solver=dfx.Dopri8(), rtol=1e-8, atol=1e-8, max_steps=10**8
            ),
        ),
    ):
        t0 = time.perf_counter()
        tr = jax.block_until_ready(fn())
        sec = time.perf_counter() - t0
        E = jax.vmap(lambda s: jaxrb.energy(scene, s))(tr.states)
        rel = jnp.abs(E / E[0] - 1)
        res[name] = rel
        lines.append(f"| {name} | {float(jnp.max(rel)):.2e} | {float(rel[-1]):.2e} | {sec:.1f} |")
    if out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4))
        for name, rel in res.items():
            ax.semilogy(ts[1:], rel[1:] + 1e-17, label=name)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("|E(t)/E(0) - 1|")
        ax.set_title(f"heavy top energy error, {C.device_name()}")
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(out, "long_run_energy.png"), dpi=110)
        plt.close(fig)
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description="long-run drift")
    p.add_argument("--periods", type=int, default=10_000)
    p.add_argument("--top-seconds", type=float, default=200.0)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    if a.out:
        os.makedirs(a.out, exist_ok=True)
    text = (
        f"device: `{C.device_name()}`\n\n"
        + torque_free(a.periods)[0]
        + "\n"
        + heavy_top(a.top_seconds, a.out)
    )
    print(text)
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        with open(os.path.join(a.out, "long_run.md"), "w") as f:
            f.write("## Long runs\n\n" + text)
    return text


if __name__ == "__main__":
    main()
