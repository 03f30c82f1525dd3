# ruff: noqa: E501  (table strings)
"""Which face comes up: a fair and a loaded d6 thrown at random, and the outcome of a d6
dropped with spin against its height (the contact engine, float64).

1. *Fairness.* `--n` random throws (the draws of `contact_throws.py`: heights U(0.05, 0.3) m,
   attitude uniform over all rotations, spin U(-40, 40) rad/s per axis, restitution and friction U(0.2, 0.8))
   of a 16 mm, 4.5 g d6 whose mass centre is moved from its centre towards the face
   numbered 2 by each of `--loads` (fractions of the half-edge; 0: the fair die). For each
   load: the frequency of every number with its 95 % Wilson interval, and of 5 (the face
   opposite the heavy side) plotted against the load.
2. *Outcome map.* The same d6 (fair) starts from rest in one tilted attitude and is dropped
   from heights h (its mass centre) with spin w about one fixed body axis
   (floor: restitution 0.5, friction 0.3); the number shown at rest is painted over the
   (h, w) plane: the bands show where a throw is predictable, the speckle where it is not
   (`--height-range`, `--spin-range`; the default range is where bands are still wide).

Each throw runs to T = 4 s (every die at rest) with `rtol = atol = 1e-8` and `max_impacts`
200, one throw per compiled call through `jaxrb.sweep` (a vmapped batch would wait for its
slowest member). A throw that does not succeed, or that is not at rest squarely on a face,
is counted and left out of the frequencies.

Writes `dice_outcomes.md`, `dice_fairness.png`, `dice_outcome_map.png` and
`dice_outcomes.npz` to `--out`; existing files are kept unless `--force`.

Run: python -m benchmarks.dice_outcomes --n 1000 --out bench_out
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
except ImportError:
    import _common as C  # type: ignore
    from contact_throws import throws  # type: ignore

EDGE, MASS, T_END = 0.016, 0.0045, 4.0
Z95 = 1.959963984540054


def wilson(count, n, z=Z95):
    """The Wilson score interval of the proportion count / n."""
    p = count / np.maximum(n, 1)
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def make_throw(die):
    """One throw of `die` with its shape's offset, the floor and the initial state traced:
    (row) -> result code, number shown, alignment with its face, speed at T."""
    ts = jnp.array([0.0, T_END])

    def throw(row):
        shape = eqx.tree_at(lambda s: s.offset, die.shape, row["offset"])
        scene = jaxrb.Scene(
            jaxrb.RigidBody(MASS, shape=shape),
            (jaxrb.Gravity(),),
            floor=jaxrb.Floor(row["restitution"], row["friction"]),
        )
        traj = jaxrb.simulate(
            scene, row["state"], ts, max_impacts=200, throw=False, rtol=1e-8, atol=1e-8
        )
        q = traj.states.quat[-1]
        return dict(
            code=traj.result._value,
            outcome=die.outcome(q),
            alignment=die.face_alignment(q),
            speed=jnp.linalg.norm(traj.states.vel[-1])
            + EDGE * jnp.linalg.norm(traj.states.omega[-1]),
        )

    return throw


def settled(out):
    """Throws that succeeded and rest squarely on a face."""
    return (out["code"] == 0) & (out["alignment"] > 1 - 1e-9) & (out["speed"] < 1e-6)


def fairness(die, n, loads):
    heavy = int(np.argmin(np.asarray(die.shape.face_normals())[:, 2]))  # the -z face
    state, restitution, friction = throws(n, seed=1, uniform_attitude=True)
    L = len(loads)
    rows = dict(
        state=jax.tree.map(lambda x: jnp.concatenate([x] * L), state),
        restitution=jnp.tile(restitution, L),
        friction=jnp.tile(friction, L),
        # the centroid relative to the mass centre: the mass centre moves towards -z
        offset=jnp.zeros((L * n, 3)).at[:, 2].set(jnp.repeat(jnp.asarray(loads), n) * EDGE / 2),
    )
    out = jaxrb.sweep(make_throw(die), rows, chunk_size=1, progress=True)
    out = {k: v.reshape((L, n) + v.shape[1:]) for k, v in out.items()}
    return out, die.numbers[heavy]


def outcome_map(die, heights, spins):
    axis = jnp.array([0.3, 1.0, 0.2]) / jnp.linalg.norm(jnp.array([0.3, 1.0, 0.2]))
    q = jaxrb.axis_angle_to_quat(jnp.array([1.0, 0.5, 0.0]) / jnp.sqrt(1.25), 0.7)
    h, w = np.meshgrid(heights, spins, indexing="ij")
    k = h.size
    state = jaxrb.make_state(
        pos=jnp.stack([jnp.zeros(k), jnp.zeros(k), jnp.asarray(h.ravel())], -1),
        quat=jnp.broadcast_to(q, (k, 4)),
        omega=jnp.asarray(w.ravel())[:, None] * axis,
    )
    rows = dict(
        state=state,
        restitution=jnp.full(k, 0.5),
        friction=jnp.full(k, 0.3),
        offset=jnp.zeros((k, 3)),
    )
    out = jaxrb.sweep(make_throw(die), rows, chunk_size=1, progress=True)
    return {key: v.reshape(h.shape) for key, v in out.items()}


def plot_fairness(loads, freq, lo, hi, shown, path):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    ax = axes[0]
    x = np.arange(1, 7)
    for j, load in enumerate(loads):
        ax.errorbar(
            x + 0.1 * (j - (len(loads) - 1) / 2),
            freq[j],
            yerr=np.maximum([freq[j] - lo[j], hi[j] - freq[j]], 0.0),
            fmt="o",
            ms=4,
            capsize=2,
            label=f"load {load:g}",
        )
    ax.axhline(1 / 6, color="k", lw=0.8, ls="--", label="1/6")
    ax.set(xlabel="number shown", ylabel="frequency (95 % Wilson interval)", title="d6 outcomes")
    ax.legend(fontsize=8, loc="upper left")
    ax = axes[1]
    j = shown - 1
    ax.errorbar(
        loads,
        freq[:, j],
        yerr=np.maximum([freq[:, j] - lo[:, j], hi[:, j] - freq[:, j]], 0.0),
        fmt="o-",
        capsize=3,
    )
    ax.axhline(1 / 6, color="k", lw=0.8, ls="--", label="1/6 (fair)")
    ax.set(
        xlabel="mass centre moved towards face 2 (fraction of the half-edge)",
        ylabel=f"frequency of {shown} (opposite the heavy side)",
        title="the loaded die's bias against its load",
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_map(heights, spins, shown, good, path):
    fig, ax = plt.subplots(figsize=(8, 5))
    cmap = matplotlib.colormaps["tab10"].resampled(6)
    image = np.where(good, shown, np.nan).T
    mesh = ax.pcolormesh(heights, spins, image, cmap=cmap, vmin=0.5, vmax=6.5, shading="nearest")
    bar = fig.colorbar(mesh, ax=ax, ticks=range(1, 7))
    bar.set_label("number shown at rest")
    ax.set(
        xlabel="drop height of the mass centre (m)",
        ylabel="initial spin (rad/s, about one fixed body axis)",
        title="d6 dropped with spin onto a table (e = 0.5, mu = 0.3): which face comes up",
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=1000, help="random throws per load")
    p.add_argument("--loads", default="0,0.1,0.2,0.3,0.5", help="fractions of the half-edge")
    p.add_argument("--heights", type=int, default=40, help="heights in the outcome map")
    p.add_argument("--spins", type=int, default=24, help="spins in the outcome map")
    p.add_argument(
        "--height-range", default="0.015,0.1", help="lowest,highest drop height (m) of the map"
    )
    p.add_argument("--spin-range", default="0,20", help="lowest,highest spin (rad/s) of the map")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="overwrite earlier results")
    a = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    loads = [float(x) for x in a.loads.split(",")]
    names = ("dice_outcomes.md", "dice_fairness.png", "dice_outcome_map.png", "dice_outcomes.npz")
    if min(float(x) for x in a.height_range.split(",")) < 0.014:
        p.error("--height-range: the die starts below the floor under 0.014 m")
    paths = C.output_paths(p, a.out, names, a.force)
    die = jaxrb.dice.d6(EDGE)
    device = C.device_name()

    t0 = time.perf_counter()
    out, heavy_number = fairness(die, a.n, loads)
    fair_s = time.perf_counter() - t0
    shown = 7 - heavy_number
    ok = settled(out)
    counts = np.stack(
        [np.bincount(out["outcome"][j][ok[j]], minlength=7)[1:] for j in range(len(loads))]
    )
    used = ok.sum(axis=1)
    freq = counts / used[:, None]
    lo, hi = wilson(counts, used[:, None])
    plot_fairness(np.array(loads), freq, lo, hi, shown, paths[1])

    heights = np.linspace(*(float(x) for x in a.height_range.split(",")), a.heights)
    spins = np.linspace(*(float(x) for x in a.spin_range.split(",")), a.spins)
    t0 = time.perf_counter()
    grid = outcome_map(die, heights, spins)
    map_s = time.perf_counter() - t0
    good = settled(grid)
    plot_map(heights, spins, grid["outcome"], good, paths[2])

    lines = [
        f"# Which face comes up ({device})\n",
        f"## A fair and a loaded d6, {a.n} random throws per load ({fair_s:.0f} s in all)\n",
        f"The mass centre is moved towards the face numbered {heavy_number} by the load "
        f"(fraction of the half-edge); {shown} is the number opposite. Frequencies with 95 % "
        "Wilson intervals, over the throws that ended at rest on a face.\n",
        "| load | settled | " + " | ".join(f"{k}" for k in range(1, 7)) + " |",
        "|---" * 8 + "|",
    ]
    for j, load in enumerate(loads):
        cells = " | ".join(f"{freq[j, k]:.3f} [{lo[j, k]:.3f}, {hi[j, k]:.3f}]" for k in range(6))
        lines.append(f"| {load:g} | {used[j]} / {a.n} | {cells} |")
    lines += [
        "",
        "![fairness](dice_fairness.png)",
        "",
        f"## Outcome map: {a.heights} heights x {a.spins} spins ({map_s:.0f} s)\n",
        f"Settled on a face: {good.sum()} of {good.size}.",
        "",
        "![outcome map](dice_outcome_map.png)",
        "",
    ]
    text = "\n".join(lines)
    with open(paths[0], "w") as f:
        f.write(text)
    np.savez(
        paths[3],
        loads=np.array(loads),
        counts=counts,
        settled=used,
        heights=heights,
        spins=spins,
        map_outcome=grid["outcome"],
        map_settled=good,
    )
    print(text)
    print("wrote", ", ".join(paths))


if __name__ == "__main__":
    main()
