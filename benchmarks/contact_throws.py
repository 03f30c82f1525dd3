# ruff: noqa: E501  (table strings)
"""Random throws of dice and coins onto the floor: a physical sanity study of the contact
engine, with pictures (docs/contact.md).

N dice (16 mm cube, 4.5 g) and N coins (radius 12 mm, thickness 2 mm, 7.5 g) are thrown from
heights U(0.05, 0.3) m with a random attitude, spin U(-40, 40) rad/s per body axis and
horizontal speed U(-0.5, 0.5) m/s onto a floor with restitution U(0.2, 0.8) and friction
U(0.2, 0.8), T = 2 s, 401 saves; `jax.jit(jax.vmap(jaxrb.simulate))`, `throw=False`.

Each body is checked for what a picture would show:

- *sinks*: its lowest point more than `contact_tol` (1e-9 m) under the floor at a save, or
  at an event (`ContactLog.max_penetration`);
- *gains energy*: its energy rises between saves by more than 1e-9 of its initial energy
  above the floor (the solver's tolerance), or across an event (`ContactLog.max_energy_rise`);
- *jumps*: it moves between two saves farther than its speed allows
  (|x(t+dt) - x(t)| > 1.5 dt max(|v(t)|, |v(t+dt)|) + g dt^2);
- its result code, and how it ends (resting on a face, on an edge or rim, moving).

Writes `contact_throws.md` (the table and the counts) and `contact_throws.png` (energy above
the floor over time, the lowest point's height, the final state) to `--out`.

Run: python -m benchmarks.contact_throws --n 200 --out bench_out
"""

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore

T_END = 2.0
N_SAVE = 401
G = 9.81
SHAPES = {
    "die": (0.0045, lambda: jaxrb.Box(jnp.full(3, 0.008))),
    "coin": (0.0075, lambda: jaxrb.Cylinder(0.012, 0.001)),
}


def throws(n, seed):
    """Random initial states and floors (restitution, friction) for n bodies."""
    k = jax.random.split(jax.random.key(seed), 7)
    u = lambda key, lo, hi, shape=(n,): jax.random.uniform(  # noqa: E731
        key, shape, minval=lo, maxval=hi, dtype=jnp.float64
    )
    axis = jax.random.normal(k[0], (n, 3), dtype=jnp.float64)
    axis = axis / jnp.linalg.norm(axis, axis=-1, keepdims=True)
    quat = jaxrb.axis_angle_to_quat(axis, u(k[1], 0.0, np.pi))
    pos = jnp.stack([jnp.zeros(n), jnp.zeros(n), u(k[2], 0.05, 0.3)], -1)
    vel = jnp.concatenate([u(k[3], -0.5, 0.5, (n, 2)), jnp.zeros((n, 1))], -1)
    omega = u(k[4], -40.0, 40.0, (n, 3))
    state = jaxrb.make_state(pos=pos, quat=quat, vel=vel, omega=omega)
    return state, u(k[5], 0.2, 0.8), u(k[6], 0.2, 0.8)


def run(kind, n, seed):
    mass, make_shape = SHAPES[kind]
    shape = make_shape()
    ts = jnp.linspace(0.0, T_END, N_SAVE)

    def one(state, restitution, friction):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(mass, shape=shape),
            (jaxrb.Gravity(),),
            floor=jaxrb.Floor(restitution, friction),
        )
        tr = jaxrb.simulate(scene, state, ts, max_impacts=64, throw=False)
        lowest = jax.vmap(lambda p, q: shape.floor_distance(p, q, 0.0))(
            tr.states.pos, tr.states.quat
        )
        return tr, lowest, jaxrb.energy(scene, tr.states)

    fn = jax.jit(jax.vmap(one))
    args = throws(n, seed)
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    steady = time.perf_counter() - t0
    return out, args, first - steady, steady


def checks(out, kind, tol=1e-9):
    tr, lowest, energy = (jax.tree.map(np.asarray, x) for x in out)
    ts = np.asarray(tr.ts[0])
    dt = np.diff(ts)
    mass = SHAPES[kind][0]
    # energy above the floor's lowest possible potential (the mass centre at the floor)
    e0 = energy[:, :1] - 0.0
    scale = np.abs(e0[:, 0]) + mass * G * 0.01
    rise_saves = np.max(np.diff(energy, axis=1), axis=1) / scale
    speed = np.linalg.norm(tr.states.vel, axis=-1)
    step = np.linalg.norm(np.diff(tr.states.pos, axis=1), axis=-1)
    allowed = 1.5 * dt * np.maximum(speed[:, 1:], speed[:, :-1]) + G * dt**2
    jumps = np.sum(step > allowed, axis=1)
    code = np.asarray(tr.result._value).reshape(-1)
    final_kind = tr.contact.kind[:, -1]
    final_speed = speed[:, -1] + np.linalg.norm(tr.states.omega[:, -1], axis=-1) * 0.012
    return dict(
        ok=code == 0,
        sinks=(lowest.min(axis=1) < -tol) | (tr.contact.max_penetration > tol),
        gains=(rise_saves > 1e-9) | (tr.contact.max_energy_rise > 1e-12 * scale),
        jumps=jumps > 0,
        lowest=lowest,
        energy=energy,
        ts=ts,
        final_kind=final_kind,
        at_rest=final_speed < 1e-3,
        impacts=tr.impacts.count,
        events=tr.contact.events,
        zeno=tr.contact.zeno_merges,
        inconsistent=tr.contact.inconsistent,
        guards=tr.contact.energy_guards,
        min_lowest=lowest.min(axis=1),
        max_rise=np.maximum(rise_saves, tr.contact.max_energy_rise / scale),
    )


def plot(results, path):
    fig, axes = plt.subplots(len(results), 3, figsize=(15, 4.2 * len(results)), squeeze=False)
    for row, (kind, r) in zip(axes, results.items(), strict=True):
        ts, energy = r["ts"], r["energy"]
        e_rel = (energy - energy[:, -1:]) / (energy[:, :1] - energy[:, -1:] + 1e-30)
        ax = row[0]
        ax.plot(ts, e_rel.T, lw=0.4, alpha=0.5)
        ax.set(
            title=f"{kind}s: energy above its final value / initial",
            xlabel="t (s)",
            ylabel="(E - E_end) / (E_0 - E_end)",
        )
        ax = row[1]
        lowest = r["lowest"]
        ax.plot(ts, np.maximum(lowest.T, 1e-13), lw=0.4, alpha=0.5)
        ax.set_yscale("log")
        ax.axhline(1e-9, color="k", ls="--", lw=0.8, label="contact_tol 1e-9 m")
        ax.set(
            title=f"{kind}s: lowest point above the floor (below: {np.sum(r['sinks'])} bodies)",
            xlabel="t (s)",
            ylabel="height (m), clipped at 1e-13",
        )
        ax.legend(loc="upper right", fontsize=8)
        ax = row[2]
        names = jaxrb.contact.KIND_NAMES
        counts = [
            [np.sum((r["final_kind"] == k) & r["at_rest"]) for k in range(4)],
            [np.sum((r["final_kind"] == k) & ~r["at_rest"]) for k in range(4)],
        ]
        x = np.arange(4)
        ax.bar(x - 0.2, counts[0], 0.4, label="at rest")
        ax.bar(x + 0.2, counts[1], 0.4, label="moving")
        ax.set_xticks(x, names)
        ax.set(title=f"{kind}s: contact at t = {ts[-1]:g} s", ylabel="bodies")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=200, help="bodies per shape")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="bench_out")
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    device = C.device_name()
    results, lines = {}, []
    lines.append(f"# Random throws of dice and coins (N = {args.n} each, {device})\n")
    lines.append(
        "| shape | successful | sink | gain energy | jump | at rest | impacts (mean) | events (mean) | Zeno merges (mean) | inconsistent (total) | energy guards (total) | deepest (m) | largest rise (rel.) | compile (s) | s per body |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for kind in SHAPES:
        out, _, compile_s, steady = run(kind, args.n, args.seed)
        r = checks(out, kind)
        results[kind] = r
        lines.append(
            f"| {kind} | {r['ok'].sum()} | {r['sinks'].sum()} | {r['gains'].sum()} | "
            f"{r['jumps'].sum()} | {r['at_rest'].sum()} | {r['impacts'].mean():.1f} | "
            f"{r['events'].mean():.1f} | {r['zeno'].mean():.2f} | {r['inconsistent'].sum()} | "
            f"{r['guards'].sum()} | {max(-r['min_lowest'].min(), 0):.2g} | "
            f"{r['max_rise'].max():.2g} | {compile_s:.0f} | {steady / args.n:.3f} |"
        )
        print(lines[-1], flush=True)
        bad = np.flatnonzero(~r["ok"] | r["sinks"] | r["gains"] | r["jumps"])
        if bad.size:
            lines.append(
                f"\n{kind}s flagged (index: result ok, sinks, gains, jumps): "
                + ", ".join(
                    f"{i}: {bool(r['ok'][i])}, {bool(r['sinks'][i])}, {bool(r['gains'][i])}, {bool(r['jumps'][i])}"
                    for i in bad[:20]
                )
                + "\n"
            )
    plot(results, os.path.join(args.out, "contact_throws.png"))
    text = "\n".join(lines) + "\n\n![throws](contact_throws.png)\n"
    path = os.path.join(args.out, "contact_throws.md")
    with open(path, "w") as f:
        f.write(text)
    print(text)
    print("wrote", path)


if __name__ == "__main__":
    main()
