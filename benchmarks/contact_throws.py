# ruff: noqa: E501  (table strings)
"""Random throws of dice and coins onto the floor: a physical sanity study of the contact
engine, with pictures (docs/contact.md).

N dice (16 mm cube, 4.5 g) and N coins (radius 12 mm, thickness 2 mm, 7.5 g) are thrown from
heights U(0.05, 0.3) m with a random attitude (about a uniformly random axis, by an angle
U(0, pi)), spin U(-40, 40) rad/s per body axis and
horizontal speed U(-0.5, 0.5) m/s onto a floor with restitution U(0.2, 0.8) and friction
U(0.2, 0.8); saves every 5 ms until T = 4 s (dice: long enough for all to come to rest) or
2 s (coins: one rolling on its rim without dissipation never stops); `jaxrb.simulate` with
`throw=False`, `max_impacts` = 200, jitted once and called per body (or `jax.vmap`ped over
`--chunk` bodies).

Each body is checked for what a picture would show:

- *sinks*: its lowest point more than `contact_tol` (1e-9 m) under the floor at a save, or
  at an event (`ContactLog.max_penetration`);
- *gains energy*: its energy rises between two saves by more than the solver's tolerance
  (`rtol` times its initial energy plus m g 1 cm), or across an event by more than lifting
  it out of a penetration within `contact_tol` can add, m g contact_tol
  (`ContactLog.max_energy_rise`; docs/contact.md, section 5). A body flagged for a rise
  between saves is thrown again at `rtol` / 10 and / 100: where its rise falls at least
  threefold with each tenfold tighter tolerance, it is the solver's error, which converges
  away (counted apart in the table), not a gain the model makes;
- *jumps*: it moves or turns between two saves farther than its energy allows: with the
  kinetic energy K at most E(t) - m g z_min (z_min: the lowest its mass centre can be) while
  the energy does not rise, |x(t+dt) - x(t)| <= dt sqrt(2 K / m) and the angle turned
  <= dt sqrt(2 K / I_min);
- its result code, and how it ends (resting on a face, on an edge or rim, moving).

`--shapes d4,d8,d12,d20` throws the regular polyhedral dice of `jaxrb.dice` (same density as
the cube); for them the table adds how squarely each ends on a face and how often each number
came up. `--shapes ball_in_bowl,ball_on_cone` throws a ball (20 mm, 50 g) the same way into a
spherical bowl of radius 0.3 m, or onto a cone of inclination 0.3 rad (apex rounded, radius
5 cm), both with rolling
resistance 0.01 (the "floor" of the checks is then that surface); `ball_on_wheel` onto that
cone bounded by a smooth wall of radius 0.1 m (a small roulette wheel: track and wall).
`--shapes bar` throws a narrow box (24 x 8 x 8 mm, 5 g) onto floors of friction U(0.3, 1.5),
where a body on an edge or corner can meet the Painlevé paradox (its result code then says
so, and the run stops there).

Writes `contact_throws.md` (the table and the counts), `contact_throws.png` (energy above
the floor over time, the lowest point's height, the final state) and per shape
`contact_throws_SHAPE.npz` (the per-body checks and counts) to `--out`; existing files are
kept unless `--force`. Bodies run in compiled batches of `--chunk` with progress printed.

Run: python -m benchmarks.contact_throws --n 1000 --out bench_out
"""

import argparse
import functools
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

G = 9.81
SAVE_INTERVAL = 0.005  # s
REFINE = (10, 100)  # a body whose energy rises between saves is thrown again at rtol / these
PLURAL = {"die": "dice", "coin": "coins"}
# mass (kg), shape, the lowest height of its mass centre on the floor (m), T (s): long enough
# for every die to come to rest; a coin rolling on its rim without dissipation never does
SHAPES = {
    "die": (0.0045, lambda: jaxrb.Box(jnp.full(3, 0.008)), 0.008, 4.0),
    "coin": (0.0075, lambda: jaxrb.Cylinder(0.012, 0.001), 0.001, 2.0),
}
DICE_DENSITY = 0.0045 / 0.016**3  # kg/m^3, that of the cube die


DICE = {f"d{sides}": sides for sides in (4, 8, 12, 20)}
PLURAL.update({name: f"{name} dice" for name in DICE})


def _polyhedral_die(sides):
    """(mass, shape, inradius, T) of the regular die with `sides` faces (jaxrb.dice sizes)."""
    shape = jaxrb.dice.BUILDERS[sides]().shape
    inradius = min(
        float(jnp.dot(n, shape.vertices[f[0]]))
        for n, f in zip(shape.face_normals(), shape.faces, strict=True)
    )
    return (DICE_DENSITY * float(shape.volume), lambda: shape, inradius, 4.0)


# a ball (20 mm, 50 g) thrown into a bowl of radius 0.3 m or onto a cone of inclination
# 0.3 rad (its apex rounded, radius 5 cm), with rolling resistance 0.01: the curved
# surfaces (docs/contact.md, section 8)
BALL = (0.05, lambda: jaxrb.Sphere(0.02))
SHAPES["ball_in_bowl"] = (*BALL, 0.02, 4.0)
SHAPES["ball_on_cone"] = (*BALL, 0.02 / np.cos(0.3), 4.0)
# and onto a small roulette wheel: that cone bounded by a smooth wall of radius 0.1 m (the
# ball meets track and wall, often both at once: docs/contact.md, section 11)
SHAPES["ball_on_wheel"] = (*BALL, 0.02 / np.cos(0.3), 4.0)
PLURAL.update(
    ball_in_bowl="balls in a bowl", ball_on_cone="balls on a cone", ball_on_wheel="balls on a wheel"
)
# a narrow box (24 x 8 x 8 mm, 5 g) thrown onto floors of friction U(0.3, 1.5) instead of
# U(0.2, 0.8): high enough for the Painlevé paradox (docs/contact.md, section 3)
SHAPES["bar"] = (0.005, lambda: jaxrb.Box(jnp.array([0.012, 0.004, 0.004])), 0.004, 4.0)
PLURAL["bar"] = "bars"
THROW_FRICTION = (0.2, 0.8)  # the floors' friction of `throws`: uniform in this range
FRICTION = {"bar": (0.3, 1.5)}  # the range THROW_FRICTION is mapped onto
FLOORS = {
    "ball_in_bowl": lambda e, mu: jaxrb.Bowl(e, mu, radius=0.3, rolling_resistance=0.01),
    "ball_on_cone": lambda e, mu: jaxrb.Cone(
        e, mu, inclination=0.3, rolling_resistance=0.01, tip_radius=0.05
    ),
    "ball_on_wheel": lambda e, mu: jaxrb.Wheel(
        e, mu, inclination=0.3, wall_radius=0.1, rolling_resistance=0.01, tip_radius=0.05
    ),
}
DEFAULT_SHAPES = "die,coin"
KINDS = ("die", "coin", *DICE, "ball_in_bowl", "ball_on_cone", "ball_on_wheel", "bar")


@functools.cache
def shape_of(kind):
    """(mass (kg), a function making the shape, the lowest height of the mass centre on the
    floor (m), T (s)) of `kind`. The polyhedral dice are built when first asked for, not at
    import: building one runs JAX, which would start its backend before `main` can choose
    the CPU compiler settings."""
    return _polyhedral_die(DICE[kind]) if kind in DICE else SHAPES[kind]


def throws(n, seed, uniform_attitude=False):
    """Random initial states and floors (restitution, friction) for n bodies.

    The attitude: a rotation about a uniformly random axis by an angle U(0, pi) (what this
    sanity study has always used; it favours attitudes near the identity: a rotation angle
    uniform over all rotations has the density (1 - cos a) / pi), or with
    `uniform_attitude` uniform over all rotations (a normalised 4-vector of standard
    normals), as the studies of outcomes need."""
    k = jax.random.split(jax.random.key(seed), 7)
    u = lambda key, lo, hi, shape=(n,): jax.random.uniform(  # noqa: E731
        key, shape, minval=lo, maxval=hi, dtype=jnp.float64
    )
    axis = jax.random.normal(k[0], (n, 3), dtype=jnp.float64)
    axis = axis / jnp.linalg.norm(axis, axis=-1, keepdims=True)
    quat = jaxrb.axis_angle_to_quat(axis, u(k[1], 0.0, np.pi))
    if uniform_attitude:
        quat = jax.random.normal(k[1], (n, 4), dtype=jnp.float64)
        quat = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    pos = jnp.stack([jnp.zeros(n), jnp.zeros(n), u(k[2], 0.05, 0.3)], -1)
    vel = jnp.concatenate([u(k[3], -0.5, 0.5, (n, 2)), jnp.zeros((n, 1))], -1)
    omega = u(k[4], -40.0, 40.0, (n, 3))
    state = jaxrb.make_state(pos=pos, quat=quat, vel=vel, omega=omega)
    return state, u(k[5], 0.2, 0.8), u(k[6], *THROW_FRICTION)


def floor_friction(kind, friction):
    """The floors' friction coefficients of throws of `kind` for the `friction` of `throws`
    (uniform in THROW_FRICTION): mapped linearly onto the kind's own range (`FRICTION`)."""
    if kind not in FRICTION:
        return friction
    lo, hi = FRICTION[kind]
    low, high = THROW_FRICTION
    return lo + (friction - low) * (hi - lo) / (high - low)


def run(kind, n, seed, chunk, rtol, max_impacts, members=None):
    """Simulate n throws of `kind` (or only the throws `members` of them) in chunks of
    `chunk` bodies (one compilation; progress printed per chunk). Returns the outputs, the
    throws, the compile time and the run time (s)."""
    mass, make_shape, _, t_end = shape_of(kind)
    shape = make_shape()
    ts = jnp.linspace(0.0, t_end, round(t_end / SAVE_INTERVAL) + 1)

    def one(state, restitution, friction):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(mass, shape=shape),
            (jaxrb.Gravity(),),
            floor=FLOORS.get(kind, jaxrb.Floor)(restitution, friction),
        )
        tr = jaxrb.simulate(
            scene, state, ts, max_impacts=max_impacts, throw=False, rtol=rtol, atol=rtol
        )
        lowest = jax.vmap(lambda p, q: scene.floor.body_distance(shape, p, q))(
            tr.states.pos, tr.states.quat
        )
        return tr, lowest, jaxrb.energy(scene, tr.states)

    state, restitution, friction = throws(n, seed)
    args = (state, restitution, floor_friction(kind, friction))
    if members is not None:
        args = jax.tree.map(lambda x: x[np.asarray(members)], args)
        n = len(members)
    chunk = min(chunk, n)
    pad = -n % chunk
    padded = jax.tree.map(lambda x: jnp.concatenate([x, x[:pad]]) if pad else x, args)
    # chunk 1: one body per call (no vmap), so no body waits for the slowest of a batch
    batched = jax.vmap(one) if chunk > 1 else lambda *a: jax.tree.map(lambda x: x[None], one(*a))
    head = jax.tree.map(lambda x: x[:chunk] if chunk > 1 else x[0], padded)
    t0 = time.perf_counter()
    fn = jax.jit(batched).lower(*head).compile()
    compile_s = time.perf_counter() - t0
    outs, t0, shown = [], time.perf_counter(), time.perf_counter()
    for k in range(0, n + pad, chunk):
        part = jax.tree.map(lambda x, k=k: x[k : k + chunk] if chunk > 1 else x[k], padded)
        outs.append(jax.block_until_ready(fn(*part)))
        done = min(k + chunk, n)
        if time.perf_counter() - shown > 30 or done == n:
            shown = time.perf_counter()
            print(f"  {kind}: {done}/{n} bodies, {shown - t0:.0f} s", flush=True)
    run_s = time.perf_counter() - t0
    out = jax.tree.map(lambda *xs: jnp.concatenate(xs)[:n], *outs)
    return out, args, compile_s, run_s


def checks(out, kind, rtol, contact_tol=1e-9):
    """What a picture would show, per body (module docstring)."""
    tr, lowest, energy = (jax.tree.map(np.asarray, x) for x in out)
    ts = np.asarray(tr.ts[0])
    dt = np.diff(ts)
    mass, make_shape, lowest_centre, _ = shape_of(kind)
    inertia = jaxrb.RigidBody(mass, shape=make_shape()).inertia_matrix
    smallest_moment = float(np.min(np.linalg.eigvalsh(np.asarray(inertia))))
    # energy on the scale of the throw: its initial energy plus m g 1 cm
    scale = np.abs(energy[:, 0]) + mass * G * 0.01
    rise_saves = np.max(np.diff(energy, axis=1), axis=1) / scale
    # energy never rises, so the kinetic energy within a save interval is at most the energy
    # at its start less the lowest potential energy (to the solver's tolerance): that bounds
    # how far the body can move and turn in it
    kinetic_max = energy[:, :-1] - mass * G * lowest_centre + rtol * scale[:, None]
    kinetic_max = np.maximum(kinetic_max, 0.0)
    step = np.linalg.norm(np.diff(tr.states.pos, axis=1), axis=-1)
    turned = np.asarray(jaxrb.quat_geodesic_angle(tr.states.quat[:, 1:], tr.states.quat[:, :-1]))
    moves = step > dt * np.sqrt(2 * kinetic_max / mass) + 1e-12
    turns = turned > dt * np.sqrt(2 * kinetic_max / smallest_moment) + 1e-9
    code = np.asarray(tr.result._value).reshape(-1)
    final_kind = tr.contact.kind[:, -1]
    speed = np.linalg.norm(tr.states.vel, axis=-1)
    final_speed = speed[:, -1] + np.linalg.norm(tr.states.omega[:, -1], axis=-1) * 0.012
    # across an event the energy may rise by what lifting the body out of a penetration
    # within contact_tol adds (docs/contact.md, section 5): m g contact_tol
    event_rise = tr.contact.max_energy_rise
    rises, event_gain = rise_saves > rtol, event_rise > mass * G * contact_tol
    return dict(
        ok=code == 0,
        code=code,
        sinks=(lowest.min(axis=1) < -contact_tol) | (tr.contact.max_penetration > contact_tol),
        rises=rises,
        event_gain=event_gain,
        gains=rises | event_gain,
        jumps=np.any(moves | turns, axis=1),
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
        rise_saves=rise_saves,
        event_rise=event_rise,
    )


def refined_rises(kind, n, seed, members, rtol, max_impacts):
    """The largest energy rise between saves (relative, as in `checks`) of the throws
    `members`, thrown again at `rtol` / each of `REFINE`: (len(REFINE), len(members))."""
    rises = []
    for factor in REFINE:
        out, _, _, _ = run(kind, n, seed, 1, rtol / factor, max_impacts, members=members)
        rises.append(checks(out, kind, rtol / factor)["rise_saves"])
    return np.stack(rises)


def plot(results, path):
    fig, axes = plt.subplots(len(results), 3, figsize=(15, 4.2 * len(results)), squeeze=False)
    for row, (kind, r) in zip(axes, results.items(), strict=True):
        ts, energy = r["ts"], r["energy"]
        e_rel = (energy - energy[:, -1:]) / (energy[:, :1] - energy[:, -1:] + 1e-30)
        ax = row[0]
        ax.plot(ts, e_rel.T, lw=0.4, alpha=0.5)
        ax.set(
            title=f"{PLURAL[kind]}: energy above its final value / initial",
            xlabel="t (s)",
            ylabel="(E - E_end) / (E_0 - E_end)",
        )
        ax = row[1]
        lowest = r["lowest"]
        ax.plot(ts, np.maximum(lowest.T, 1e-13), lw=0.4, alpha=0.5)
        ax.set_yscale("log")
        ax.axhline(1e-9, color="k", ls="--", lw=0.8, label="contact_tol 1e-9 m")
        ax.set(
            title=f"{PLURAL[kind]}: lowest point above the floor (below: {np.sum(r['sinks'])} bodies)",
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
        ax.set(title=f"{PLURAL[kind]}: contact at t = {ts[-1]:g} s", ylabel="bodies")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def code_summary(code):
    names = {int(item._value): name for name, item in jaxrb.RESULTS._name_to_item.items()}
    vals, counts = np.unique(code[code != 0], return_counts=True)
    return ", ".join(f"{names.get(int(v), v)} {k}" for v, k in zip(vals, counts, strict=True))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=200, help="bodies per shape")
    p.add_argument(
        "--shapes",
        default=DEFAULT_SHAPES,
        help=f"comma-separated, of: {', '.join(KINDS)} (die: the cube as a Box)",
    )
    p.add_argument(
        "--chunk",
        type=int,
        default=1,
        help="bodies per compiled call: 1 (default) runs them one by one, >1 under vmap "
        "(a vmapped batch runs as long as its slowest member)",
    )
    p.add_argument("--max-impacts", type=int, default=200)
    p.add_argument("--rtol", type=float, default=1e-8, help="solver rtol = atol")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="overwrite earlier results")
    args = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    shapes = args.shapes.split(",")
    for kind in shapes:
        if kind not in KINDS:
            p.error(f"--shapes: unknown shape {kind!r} (known: {', '.join(KINDS)})")
    default = args.shapes == DEFAULT_SHAPES
    stem = "contact_throws" if default else "contact_throws_" + "_".join(shapes)
    names = [stem + ".md", stem + ".png"] + [f"contact_throws_{kind}.npz" for kind in shapes]
    paths = C.output_paths(p, args.out, names, args.force)
    device = C.device_name()
    results, lines, faces_notes = {}, [], []
    lines.append(
        f"# Random throws of dice and coins (N = {args.n} each, rtol = atol = {args.rtol:g}, "
        f"max_impacts = {args.max_impacts}, {args.chunk} per call, "
        f"{device})\n"
    )
    lines.append(
        "| shape | successful | not successful (codes) | sink | gain energy | jump | at rest (on a face) | impacts (mean) | events (mean) | bodies with a Zeno merge (merges) | inconsistent (total) | energy guards (total) | deepest (m) | largest rise between saves (rel.) | largest rise at an event (J) | compile (s) | s per body |"
    )
    lines.append("|---" * 17 + "|")
    for kind in shapes:
        out, _, compile_s, run_s = run(
            kind, args.n, args.seed, args.chunk, args.rtol, args.max_impacts
        )
        r = checks(out, kind, args.rtol)
        # a rise between saves that falls with the tolerance is the solver's error
        rose = np.flatnonzero(r["rises"])
        r["rise_refined"] = np.full((len(REFINE), args.n), np.nan)
        if rose.size:
            r["rise_refined"][:, rose] = refined_rises(
                kind, args.n, args.seed, rose, args.rtol, args.max_impacts
            )
        chain = np.vstack([r["rise_saves"][None], r["rise_refined"]])
        r["solver_error"] = r["rises"] & np.all(chain[1:] <= chain[:-1] / 3, axis=0)
        r["gains"] = (r["rises"] & ~r["solver_error"]) | r["event_gain"]
        results[kind] = r
        on_face = r["final_kind"] == jaxrb.contact.KIND_NAMES.index("face")
        solver = int(r["solver_error"].sum())
        solver_note = f" ({solver} more within the solver's error)" if solver else ""
        lines.append(
            f"| {kind} | {r['ok'].sum()} | {code_summary(r['code']) or 'none'} | "
            f"{r['sinks'].sum()} | {r['gains'].sum()}{solver_note} | "
            f"{r['jumps'].sum()} | {r['at_rest'].sum()} ({np.sum(r['at_rest'] & on_face)}) | "
            f"{r['impacts'].mean():.1f} | "
            f"{r['events'].mean():.1f} | {np.sum(r['zeno'] > 0)} ({r['zeno'].sum()}) | "
            f"{r['inconsistent'].sum()} | "
            f"{r['guards'].sum()} | {max(-r['min_lowest'].min(), 0):.2g} | "
            f"{r['rise_saves'].max():.2g} | {r['event_rise'].max():.2g} | "
            f"{compile_s:.0f} | {run_s / args.n:.3f} |"
        )
        print(lines[-1], flush=True)
        if kind in DICE:
            die = jaxrb.dice.BUILDERS[DICE[kind]]()
            final_quat = out[0].states.quat[:, -1]
            r["alignment"] = np.asarray(die.face_alignment(final_quat))
            r["outcome"] = np.asarray(die.outcome(final_quat))
            counts = np.bincount(r["outcome"], minlength=die.sides + 1)[1:]
            faces_notes.append(
                f"- {kind}: lowest face alignment (cos of the tilt) "
                f"{r['alignment'].min():.12f}; numbers 1-{die.sides} came up "
                + " ".join(str(c) for c in counts)
            )
        per_body = {k: v for k, v in r.items() if k not in ("lowest", "energy", "ts")}
        np.savez(os.path.join(args.out, f"contact_throws_{kind}.npz"), **per_body)
        bad = np.flatnonzero(~r["ok"] | r["sinks"] | r["gains"] | r["jumps"])
        if bad.size:
            lines.append(
                f"\n{PLURAL[kind]} flagged (index: result ok, sinks, gains, jumps): "
                + ", ".join(
                    f"{i}: {bool(r['ok'][i])}, {bool(r['sinks'][i])}, {bool(r['gains'][i])}, {bool(r['jumps'][i])}"
                    for i in bad[:20]
                )
                + "\n"
            )
        if rose.size:
            lines.append(
                f"\n{PLURAL[kind]} whose energy rose between saves by more than rtol "
                "(relative rise at rtol, rtol/10, rtol/100): "
                + ", ".join(
                    f"{i}: {r['rise_saves'][i]:.2g}, {r['rise_refined'][0, i]:.2g}, "
                    f"{r['rise_refined'][1, i]:.2g}"
                    + (" (the solver's error)" if r["solver_error"][i] else "")
                    for i in rose[:20]
                )
                + "\n"
            )
    plot(results, paths[1])
    if faces_notes:
        lines += ["", "Polyhedral dice at the end:", *faces_notes]
    text = "\n".join(lines) + f"\n\n![throws]({os.path.basename(paths[1])})\n"
    with open(paths[0], "w") as f:
        f.write(text)
    print(text)
    print("wrote", ", ".join(paths))


if __name__ == "__main__":
    main()
