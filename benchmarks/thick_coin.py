# ruff: noqa: E501  (table strings)
"""The thick coin: how often a tossed cylinder lands on its side, against its thickness
(the contact engine, float64).

Coins of diameter d = 24 mm and thickness h (`--ratios`: h / d) are thrown `--n` times each
with the random throws of `contact_throws.py` (height U(0.05, 0.3) m, attitude uniform
over all rotations, spin U(-40, 40) rad/s about each axis, sideways speed U(-0.5, 0.5) m/s; restitution
and friction U(0.2, 0.8)), the same draws for every thickness. Air resistance on its
rotation is a damping moment -c w with c = 2 /s times the coin's moment of inertia about a
diameter: without it (no rolling resistance is modelled for a cylinder) a thin coin rolling
upright on its rim rolls for ever and never shows a face. At T = `--t-end` a coin whose axis
is within 10 deg of vertical shows a face (heads or tails: it may still spin or wobble on it,
as Euler's disk does, but cannot stand up again), one whose axis is within 10 deg of
horizontal shows its side (it may still roll on it); any other is unsettled (counted, and
left out of the frequencies). A thick coin spinning down flat is an Euler's disk: its
wobble, and the stick-slip of the rim point it rolls on, run ever faster as it comes down,
and it may use up its 4 x 100 + 16 contact events before T; its run stops there
(`RESULTS.max_events_reached`) with its outcome already decided, and is read there (the
table counts these runs).

The side frequency, with its 95 % Wilson interval, is compared with the closed forms of the
non-bouncing coin (Yong & Mahadevan 2011, Am. J. Phys. 79, 1195): the coin rests on the
side its mass centre falls over, so for an attitude uniformly random on the sphere
P(side) = h / sqrt(h^2 + d^2) (a third at h / d = 1 / sqrt(8) = 0.354), and for a coin
flipped vigorously about a diameter (its axis uniform in a plane) P(side) = (2 / pi)
atan(h / d) (a third at h / d = 1 / sqrt(3) = 0.577). The bouncing coin of Murray & Teare
(1993, Phys. Rev. E 48, 2547) lands on its side less often: about 1 in 6000 for an American
nickel (h / d = 0.092).

One throw per compiled call through `jaxrb.sweep` (`rtol = atol = 1e-8`, `max_impacts` 100);
`--chunk K` runs K throws per call instead (vmapped in lockstep: the way to use a GPU), and
`--rows DIR` keeps each finished chunk in DIR, so that a run stopped part-way resumes there.

Writes `thick_coin.md`, `thick_coin.png` and `thick_coin.npz` to `--out`; existing files
are kept unless `--force`.

Run: python -m benchmarks.thick_coin --n 100 --out bench_out
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C
    from .contact_throws import throws
    from .dice_outcomes import wilson
except ImportError:
    import _common as C  # type: ignore
    from contact_throws import throws  # type: ignore
    from dice_outcomes import wilson  # type: ignore

DIAMETER, MASS = 0.024, 0.0075
FACE, SIDE, UNSETTLED = 0, 1, 2
MAX_EVENTS = int(jaxrb.RESULTS.max_events_reached._value)
MAX_IMPACTS = 100  # a run has 4 MAX_IMPACTS + 16 events
DECIDED = np.radians(10.0)  # a coin within this of flat or of upright has its outcome
DAMPING_RATE = 2.0  # 1/s: the damping moment's c over the moment of inertia about a diameter


def side_uniform(ratio):
    """P(side) of a non-bouncing coin whose attitude is uniform on the sphere."""
    return ratio / np.sqrt(1.0 + ratio**2)


def side_flipped(ratio):
    """P(side) of a non-bouncing coin flipped about a diameter (axis uniform in a plane)."""
    return 2.0 / np.pi * np.arctan(ratio)


def make_throw(t_end):
    """One throw: (row) -> result code, |axis . e_z| at T, speed at T (m/s, rim included)."""
    ts = jnp.array([0.0, t_end])
    coin = jaxrb.Cylinder(DIAMETER / 2, 0.001)

    def throw(row):
        shape = eqx.tree_at(lambda s: s.half_height, coin, row["ratio"] * DIAMETER / 2)
        body = jaxrb.RigidBody(MASS, shape=shape)
        damping = jaxrb.DampingMoment(linear=DAMPING_RATE * body.inertia_matrix[0, 0])
        scene = jaxrb.Scene(
            body,
            (jaxrb.Gravity(), damping),
            floor=jaxrb.Floor(row["restitution"], row["friction"]),
        )
        state = row["state"]
        # start clear of the floor whatever the thickness
        lift = jnp.maximum(-shape.floor_distance(state.pos, state.quat), 0.0) + 1e-3
        state = eqx.tree_at(lambda s: s.pos, state, state.pos + jnp.array([0.0, 0.0, 1.0]) * lift)
        traj = jaxrb.simulate(
            scene, state, ts, max_impacts=MAX_IMPACTS, throw=False, rtol=1e-8, atol=1e-8
        )
        axis_z = jaxrb.quat_to_matrix(traj.states.quat[-1])[2, 2]
        return dict(
            code=traj.result._value,
            axis_z=jnp.abs(axis_z),
            speed=jnp.linalg.norm(traj.states.vel[-1])
            + DIAMETER / 2 * jnp.linalg.norm(traj.states.omega[-1]),
        )

    return throw


def outcome(out):
    """FACE, SIDE or UNSETTLED per throw (a failed run counts as unsettled)."""
    # a coin spinning down flat (a thick Euler's disk: its wobble, and the stick-slip of its
    # rim point, run ever faster as it comes down) may use up its events first: its run
    # stops there, with the outcome already decided
    ok = (out["code"] == 0) | (out["code"] == MAX_EVENTS)
    face = ok & (out["axis_z"] > np.cos(DECIDED))
    side = ok & (out["axis_z"] < np.sin(DECIDED))
    return np.where(face, FACE, np.where(side, SIDE, UNSETTLED))


def study_rows(ratios, n, seed=2):
    """The sweep's rows: the same `n` random throws for every thickness ratio."""
    state, restitution, friction = throws(n, seed, uniform_attitude=True)
    R = len(ratios)
    return dict(
        state=jax.tree.map(lambda x: jnp.concatenate([x] * R), state),
        restitution=jnp.tile(restitution, R),
        friction=jnp.tile(friction, R),
        ratio=jnp.repeat(jnp.asarray(ratios, float), n),
    )


def study(ratios, n, t_end, seed=2, chunk=1, rows_dir=None):
    R = len(ratios)
    rows = study_rows(ratios, n, seed)
    out = jaxrb.sweep(make_throw(t_end), rows, chunk_size=chunk, directory=rows_dir, progress=True)
    return {k: np.asarray(v).reshape((R, n) + v.shape[1:]) for k, v in out.items()}


def summary(ratios, out):
    """Per ratio: settled count, side count, side frequency among settled and its interval,
    and how many runs stopped at the event budget."""
    kind = outcome(out)
    settled = np.sum(kind != UNSETTLED, axis=1)
    side = np.sum(kind == SIDE, axis=1)
    freq = side / np.maximum(settled, 1)
    lo, hi = wilson(side, np.maximum(settled, 1))
    stopped = np.sum(out["code"] == MAX_EVENTS, axis=1)
    return settled, side, freq, lo, hi, stopped


def plot(ratios, freq, lo, hi, path):
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    fine = np.linspace(0.0, max(ratios) * 1.05, 200)
    ax.plot(
        fine, side_uniform(fine), "k--", lw=1, label="no bounce, random attitude: h / sqrt(h² + d²)"
    )
    ax.plot(fine, side_flipped(fine), "k:", lw=1, label="no bounce, flipped: (2/π) atan(h / d)")
    ax.errorbar(
        ratios,
        freq,
        yerr=[np.maximum(freq - lo, 0), np.maximum(hi - freq, 0)],
        fmt="o",
        color="C3",
        capsize=3,
        label="jaxrb: bouncing coin, 95 % interval",
    )
    ax.plot([0.092], [1 / 6000], "s", color="C0", label="Murray & Teare 1993: a nickel, 1/6000")
    ax.axhline(1 / 3, color="0.6", lw=0.8)
    ax.text(0.01, 1 / 3 + 0.01, "a third", color="0.4", fontsize=8)
    ax.set_xlabel("thickness / diameter  h / d")
    ax.set_ylabel("P(lands on its side)")
    ax.set_title("The thick coin: landing on the side")
    ax.set_xlim(0, max(ratios) * 1.05)
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=100, help="throws per thickness")
    p.add_argument("--ratios", default="0.1,0.2,0.3,0.4,0.5,0.6", help="h / d values")
    p.add_argument("--t-end", type=float, default=4.0, help="s, when the outcome is read")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="replace existing result files")
    p.add_argument("--chunk", type=int, default=1, help="throws per compiled (vmapped) call")
    p.add_argument("--rows", default=None, help="keep finished chunks here (a rerun resumes)")
    a = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    ratios = [float(x) for x in a.ratios.split(",")]
    names = ["thick_coin.md", "thick_coin.png", "thick_coin.npz"]
    paths = C.output_paths(p, a.out, names, a.force)
    t0 = time.perf_counter()
    out = study(ratios, a.n, a.t_end, chunk=a.chunk, rows_dir=a.rows)
    wall = time.perf_counter() - t0
    settled, side, freq, lo, hi, stopped = summary(ratios, out)
    np.savez(paths[2], ratios=ratios, **out)
    plot(np.asarray(ratios), freq, lo, hi, paths[1])
    lines = [
        f"Thick coin, {a.n} throws per thickness, T = {a.t_end} s, {wall:.0f} s wall on "
        f"{C.device_name()} ({wall / (a.n * len(ratios)):.2f} s per throw, compile included).",
        "",
        "| h / d | decided (stopped at the event budget) | on the side | P(side) [95 % interval] | no bounce, random attitude | no bounce, flipped |",
        "|---|---|---|---|---|---|",
    ]
    for k, r in enumerate(ratios):
        lines.append(
            f"| {r:.2f} | {settled[k]} / {a.n} ({stopped[k]}) | {side[k]} | {freq[k]:.3f} [{lo[k]:.3f}, {hi[k]:.3f}] "
            f"| {side_uniform(r):.3f} | {side_flipped(r):.3f} |"
        )
    text = "\n".join(lines) + "\n"
    with open(paths[0], "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
