# ruff: noqa: E501  (table strings)
"""Are the regular dice fair? d4, d6, d8, d12 and d20 thrown at random (the contact engine,
float64).

Each die of `jaxrb.dice` (its default edge, uniform density, 4.5 g: the motion under
gravity and contact does not depend on the mass) is thrown `--n` times with the
random throws of `contact_throws.py` (height U(0.05, 0.3) m, attitude uniform over all
rotations,
spin U(-40, 40) rad/s about each axis, sideways speed U(-0.5, 0.5) m/s; restitution and
friction U(0.2, 0.8)) and read at T = 4 s (`Die.outcome`: the face up, the face down for a
d4). Over the throws that end at rest squarely on a face: each number's frequency with its
95 % Wilson interval, and Pearson's chi-square test of equal frequencies (its p-value; a fair
die gives p below 0.05 one time in twenty).

One throw per compiled call through `jaxrb.sweep` (`rtol = atol = 1e-8`, `max_impacts`
200), or with `--lanes L` all throws of a die through `jaxrb.simulate_throws` in L lanes
(the same trajectories, to roundoff; the way to run 10^4 throws, on a GPU above all). A
loaded d6 (its mass centre moved off centre) is `dice_outcomes.py`.

Writes `dice_fairness_all.md`, `dice_fairness_all.png` and `dice_fairness_all.npz` to
`--out`; existing files are kept unless `--force`.

Run: python -m benchmarks.dice_fairness --n 1000 --out bench_out
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
from scipy.stats import chisquare  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C
    from .contact_throws import throws
    from .dice_outcomes import EDGE, MASS, T_END, make_throw, settled, wilson
except ImportError:
    import _common as C  # type: ignore
    from contact_throws import throws  # type: ignore
    from dice_outcomes import EDGE, MASS, T_END, make_throw, settled, wilson  # type: ignore

DICE = ("d4", "d6", "d8", "d12", "d20")


def throw_die(name, n, seed=3):
    """`n` random throws of the fair die `name`: the sweep's outputs (numpy)."""
    die = getattr(jaxrb.dice, name)()
    state, restitution, friction = throws(n, seed, uniform_attitude=True)
    rows = dict(state=state, restitution=restitution, friction=friction, offset=jnp.zeros((n, 3)))
    out = jaxrb.sweep(make_throw(die), rows, chunk_size=1, progress=True)
    return die, {k: np.asarray(v) for k, v in out.items()}


def throw_die_in_lanes(name, n, lanes, seed=3):
    """The throws of `throw_die`, all at once through `jaxrb.simulate_throws` in `lanes`
    lanes (one scene per throw: its floor's restitution and friction)."""
    die = getattr(jaxrb.dice, name)()
    state, restitution, friction = throws(n, seed, uniform_attitude=True)
    scene = eqx.filter_vmap(  # every array of the scene gets a leading axis n
        lambda e, mu: jaxrb.Scene(
            jaxrb.RigidBody(MASS, shape=die.shape), (jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu)
        )
    )(restitution, friction)
    traj = jaxrb.simulate_throws(
        scene,
        state,
        jnp.array([0.0, T_END]),
        lanes=lanes,
        batched_scene=True,
        max_impacts=200,
        rtol=1e-8,
        atol=1e-8,
    )
    q = traj.states.quat[:, -1]
    out = dict(
        code=traj.result._value,
        outcome=jax.vmap(die.outcome)(q),
        alignment=jax.vmap(die.face_alignment)(q),
        speed=jnp.linalg.norm(traj.states.vel[:, -1], axis=-1)
        + EDGE * jnp.linalg.norm(traj.states.omega[:, -1], axis=-1),
    )
    return die, {k: np.asarray(v) for k, v in out.items()}


def frequencies(die, out):
    """Per number 1..F: count, frequency, Wilson interval; the throws used; the chi-square
    p-value of equal frequencies."""
    ok = settled(out)
    counts = np.bincount(out["outcome"][ok], minlength=die.sides + 1)[1:]
    used = int(ok.sum())
    lo, hi = wilson(counts, used)
    return counts, counts / max(used, 1), lo, hi, used, float(chisquare(counts).pvalue)


def plot(results, path):
    fig, axes = plt.subplots(1, len(results), figsize=(3.4 * len(results), 3.6), squeeze=False)
    for ax, (name, (counts, freq, lo, hi, used, p)) in zip(axes[0], results.items(), strict=True):
        faces = np.arange(1, len(counts) + 1)
        ax.errorbar(
            faces,
            freq,
            yerr=[np.maximum(freq - lo, 0), np.maximum(hi - freq, 0)],
            fmt="o",
            ms=3,
            capsize=2,
        )
        ax.axhline(1 / len(counts), color="k", lw=0.8, ls="--")
        ax.set_title(f"{name}: {used} throws, chi² p = {p:.2f}", fontsize=9)
        ax.set_xlabel("number")
        ax.set_xticks(faces if len(faces) <= 8 else faces[:: 2 if len(faces) <= 12 else 4])
    axes[0, 0].set_ylabel("frequency (95 % interval); dashed: fair")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=1000, help="random throws per die")
    p.add_argument("--dice", default=",".join(DICE), help="which dice, e.g. d4,d20")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="overwrite earlier results")
    p.add_argument(
        "--lanes",
        type=int,
        default=None,
        help="run each die's throws through jaxrb.simulate_throws in this many lanes "
        "(default: one throw per call through jaxrb.sweep)",
    )
    a = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    names = ("dice_fairness_all.md", "dice_fairness_all.png", "dice_fairness_all.npz")
    paths = C.output_paths(p, a.out, names, a.force)
    results, seconds, saved = {}, {}, {}
    for name in a.dice.split(","):
        t0 = time.perf_counter()
        if a.lanes is None:
            die, out = throw_die(name, a.n)
        else:
            die, out = throw_die_in_lanes(name, a.n, a.lanes)
        seconds[name] = time.perf_counter() - t0
        results[name] = frequencies(die, out)
        saved.update({f"{name}_{k}": v for k, v in out.items()})
        saved[f"{name}_seconds"] = np.asarray(seconds[name])
        write(a, paths, results, seconds, saved)  # after each die: a long run keeps its dice


def write(a, paths, results, seconds, saved):
    plot(results, paths[1])
    lines = [
        f"# Are the regular dice fair? {a.n} random throws each ({C.device_name()}; "
        + ("one throw per call" if a.lanes is None else f"{a.lanes} lanes")
        + ")\n",
        "| die | at rest on a face | chi² p (equal frequencies) | lowest and highest frequency [95 % interval] | fair value | wall (s, compile included) |",
        "|---|---|---|---|---|---|",
    ]
    for name, (counts, freq, lo, hi, used, pvalue) in results.items():
        i, j = int(np.argmin(freq)), int(np.argmax(freq))
        lines.append(
            f"| {name} | {used} / {a.n} | {pvalue:.2f} | {i + 1}: {freq[i]:.3f} [{lo[i]:.3f}, {hi[i]:.3f}]; "
            f"{j + 1}: {freq[j]:.3f} [{lo[j]:.3f}, {hi[j]:.3f}] | {1 / len(counts):.3f} | {seconds[name]:.0f} |"
        )
    lines += ["", "![dice fairness](dice_fairness_all.png)", ""]
    text = "\n".join(lines)
    with open(paths[0], "w") as f:
        f.write(text)
    np.savez(paths[2], **saved)
    print(text, flush=True)


if __name__ == "__main__":
    main()
