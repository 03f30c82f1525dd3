# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 09 — Are the regular dice fair?
#
# A regular die is fair by symmetry: every face is like every other, so no face can be
# preferred. A simulated die is fair only if the simulation keeps that symmetry: its contact
# model, its integrator and its tolerances must not favour a face, a corner or a direction.
# Throwing the dice many times at random and counting the numbers is a test of the contact
# engine as much as of the dice.
#
# **The dice.** `jaxrb.dice` builds the five regular dice (Platonic solids) as convex
# polyhedra with their numbers: d4 (tetrahedron), d6 (cube), d8 (octahedron), d12
# (dodecahedron) and d20 (icosahedron), each with a common gaming die's edge by default.
# Opposite faces add up to n + 1 (d6, d8, d12, d20). A d4 has no face on top, so it is read by
# the face it lies on (a real d4 prints that number at its top corner). A die's shape goes into
# `RigidBody(mass, shape=die.shape)`, which gives it the inertia of the uniform solid: a die of
# uniform density. `Die.outcome(quat)` is the number shown at the attitude `quat`, and
# `Die.face_alignment(quat)` how squarely the die lies (1 on a face).
#
# **The throws** (`benchmarks/dice_fairness.py`, with the draws of
# `benchmarks/contact_throws.py`): each throw releases the die from a height drawn in
# [0.05, 0.3] m, with an attitude uniform over all rotations, a spin drawn in [-40, 40] rad/s
# about each body axis and a sideways speed drawn in [-0.5, 0.5] m/s along x and y, onto a
# floor of its own whose restitution and friction are each drawn in [0.2, 0.8]. Gravity and
# contact act, no air. The
# die bounces, rolls, rocks and slides until it rests (docs/contact.md); the number is read at
# T = 4 s. A throw counts if it succeeded and the die rests squarely on a face (alignment
# within 1e-9 of 1, speed below 1e-6 m/s); the others are counted and left out.
#
# **The statistics.** Of n counted throws, k show a given number: its frequency is k / n, with
# the 95 % **Wilson score interval** (better than k / n +- 1.96 sqrt(p (1 - p) / n) for small n
# and for frequencies near 0 or 1, and never outside [0, 1]):
#
#     centre = (p + z^2 / 2n) / (1 + z^2 / n),
#     half   = z sqrt(p (1 - p) / n + z^2 / 4n^2) / (1 + z^2 / n),   p = k / n, z = 1.96.
#
# **Pearson's chi-square test** asks whether all F numbers are equally likely: with counts O_i
# and the expected count E = n / F each, X^2 = sum (O_i - E)^2 / E follows (for large counts) a
# chi-square law with F - 1 degrees of freedom if the die is fair, and the p-value is the
# chance of an X^2 at least as large. A fair die gives p < 0.05 one time in twenty; a small p
# says the die (or the simulation) is not fair. The chi-square law is a good approximation only
# when every expected count is at least about 5.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path.cwd().resolve().parent))  # the repository root: `benchmarks`
# the sweep's progress bar falls back to text where ipywidgets is missing: no warning for that
warnings.filterwarnings("ignore", message="IProgress not found")

import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import chi2

import jaxrb
from benchmarks import dice_fairness, dice_outcomes
from benchmarks.contact_throws import throws

print(f"{'die':>4} {'faces':>5} {'edge (mm)':>9}  numbers in face order")
for name in dice_fairness.DICE:
    die = getattr(jaxrb.dice, name)()
    v = np.asarray(die.shape.vertices)
    dist = np.linalg.norm(v[:, None] - v[None], axis=-1)
    edge = dist[dist > 1e-12].min()  # the shortest distance between two corners
    print(f"{name:>4} {die.sides:5d} {edge * 1e3:9.1f}  {die.numbers}")
print(f"every die has the mass {dice_outcomes.MASS * 1e3} g in the benchmark")

# %% [markdown]
# Every die gets the same mass, 4.5 g, whatever its size. Only its uniform density matters:
# with gravity and contact only (no air), the equations of motion of a uniform body do not
# depend on its mass, since every force on it (its weight, the contact impulses, friction
# bounded by the normal force) and its inertia scale with it.
#
# How many throws does a test need? The Wilson interval of a fair d8's number (frequency 1/8)
# after n throws:

# %%
for n in (8, 100, 1000, 10000):
    lo, hi = dice_outcomes.wilson(n / 8, n)
    print(f"n = {n:5d}: 1/8 = 0.125 seen n/8 times -> 95 % interval [{lo:.3f}, {hi:.3f}]")

# %% [markdown]
# The throws' attitude: the study draws it uniformly over all rotations
# (`throws(..., uniform_attitude=True)`: a normalised 4-vector of standard normals, as
# `jaxrb sweep --random-attitude` draws it). The sanity study `contact_throws.py` turns the
# body instead by an angle uniform in [0, pi] about a uniform axis, which is not uniform over
# rotations (a uniform rotation's angle has the density (1 - cos angle) / pi): it stays
# nearer the identity, so the faces that look towards body +z start on top more often. The
# number on top at the *start* of 100000 draws each way, for the d6 and the d8:

# %%
uniform, _, _ = throws(100_000, 3, uniform_attitude=True)
tilted, _, _ = throws(100_000, 3)
for name in ("d6", "d8"):
    die = getattr(jaxrb.dice, name)()
    f_uniform = np.bincount(np.asarray(die.outcome(uniform.quat)), minlength=die.sides + 1)[1:]
    f_tilted = np.bincount(np.asarray(die.outcome(tilted.quat)), minlength=die.sides + 1)[1:]
    print(f"{name}: number on top at the start (fair: {1 / die.sides:.3f})")
    print("  number          " + " ".join(f"{k:6d}" for k in range(1, die.sides + 1)))
    print("  uniform         " + " ".join(f"{x:6.3f}" for x in f_uniform / 100_000))
    print("  angle U(0, pi)  " + " ".join(f"{x:6.3f}" for x in f_tilted / 100_000))

# %% [markdown]
# The die then spins in the air and bounces several times before it rests, which mixes its
# attitude; the studies start from the uniform draws all the same, so that no number is
# favoured at the start (for the d6 the angle-U(0, pi) draws favour 5 on top, the very number
# whose frequency measures the loaded d6's bias below).
#
# ## A small run: the d8, 8 throws
#
# `dice_fairness.throw_die("d8", 8)` throws the d8 8 times (the draws of seed 3): one
# compilation (about a minute), then a fraction of a second per throw.

# %%
t0 = time.perf_counter()
die, out = dice_fairness.throw_die("d8", 8)
print(f"8 throws of the d8 in {time.perf_counter() - t0:.0f} s (compilation included)")
ok = dice_outcomes.settled(out)
print(f"{'throw':>5} {'result':>7} {'alignment - 1':>13} {'speed (m/s)':>11} {'number':>6}")
for j in range(len(ok)):
    print(
        f"{j:5d} {int(out['code'][j]):7d} {out['alignment'][j] - 1:13.1e} "
        f"{out['speed'][j]:11.1e} {int(out['outcome'][j]):6d}"
    )

# %%
counts, freq, lo, hi, used, pvalue = dice_fairness.frequencies(die, out)
print(f"{used} of {len(ok)} throws rest squarely on a face")
print(f"{'number':>6} {'count':>5} {'frequency':>9}  95 % interval")
for k in range(die.sides):
    print(f"{k + 1:6d} {counts[k]:5d} {freq[k]:9.3f}  [{lo[k]:.3f}, {hi[k]:.3f}]")
expected = used / die.sides
x2 = float(np.sum((counts - expected) ** 2 / expected))
print(
    f"chi-square X^2 = {x2:.2f} with {die.sides - 1} degrees of freedom: p = {pvalue:.3f} "
    f"(by hand from the chi-square law: {chi2.sf(x2, die.sides - 1):.3f})"
)
print(f"expected count per number: {expected:.1f} (the chi-square law wants at least about 5)")

# %%
faces = np.arange(1, die.sides + 1)
fig, ax = plt.subplots(figsize=(6.5, 4))
ax.errorbar(
    faces,
    freq,
    yerr=[np.maximum(freq - lo, 0), np.maximum(hi - freq, 0)],
    fmt="o",
    capsize=3,
    label="frequency, 95 % Wilson interval",
)
ax.axhline(1 / die.sides, color="k", lw=0.8, ls="--", label=f"fair: 1/{die.sides}")
ax.set(
    xlabel="number",
    ylabel="frequency",
    xticks=faces,
    ylim=(0, 1),
    title=f"d8: {used} throws, chi-square p = {pvalue:.2f}",
)
ax.legend(fontsize=8)
ax.grid(alpha=0.3)
plt.tight_layout()
plt.show()

# %% [markdown]
# Eight throws cannot test fairness: the expected count is one per number, far below what the
# chi-square law needs, and each interval covers most of the range; every fair-looking or
# unfair-looking feature here is chance. The run shows the pipeline (throw, read, count,
# interval, test), not the answer.
#
# ## At full size
#
# All five dice, 1000 throws each (`--dice d4,d20` picks some), writing
# `dice_fairness_all.md` (the table: throws at rest, chi-square p, the lowest and highest
# frequency with their intervals), `dice_fairness_all.png` (one panel like the one above per
# die) and `dice_fairness_all.npz` to `bench_out/`:
#
# ```bash
# python -m benchmarks.dice_fairness --n 1000 --out bench_out
# ```
#
# ## A loaded d6
#
# `benchmarks/dice_outcomes.py` loads a 16 mm d6: its mass centre is moved from the cube's
# centre towards the face numbered 2 by a fraction of the half-edge (the *load*; 0 is the fair
# die). The heavy side prefers to end down, so 5, the number opposite 2, comes up more often.
# `fairness` throws it n times for each load (the same draws, seed 1, for every load) and
# returns the sweep's outputs with the shape (loads, n) and the number on the heavy face; not
# run here (it is another compilation, and 1000 throws per load take minutes):
#
# ```python
# die = jaxrb.dice.d6(0.016)
# out, heavy = dice_outcomes.fairness(die, 1000, [0, 0.1, 0.25, 0.5])
# ok = dice_outcomes.settled(out)  # (4, 1000): at rest squarely on a face
# for j, load in enumerate([0, 0.1, 0.25, 0.5]):
#     counts = np.bincount(out["outcome"][j][ok[j]], minlength=7)[1:]
#     lo, hi = dice_outcomes.wilson(counts, ok[j].sum())
#     print(load, counts / ok[j].sum(), "number opposite the load:", 7 - heavy)
# ```
#
# The whole study (the loaded d6 over `--loads`, and a map of the number shown against the
# drop height and spin) writes `dice_outcomes.md`, `dice_fairness.png`,
# `dice_outcome_map.png` and `dice_outcomes.npz`:
#
# ```bash
# python -m benchmarks.dice_outcomes --n 1000 --out bench_out
# ```
#
# The results at full size, and their discussion, are in docs/contact.md (section "Are the dice
# fair?" and "Which face comes up") and benchmarks/README.md.
#
# ## The same without Python: `jaxrb sweep`
#
# A scene file with a die shape (`type = "die"` and `sides`) and random draws does the same
# kind of study from the command line. A d20, `d20.toml`:
#
# ```toml
# title = "d20 thrown onto a table"
#
# [body]
# mass = 0.0045                         # kg
# [body.shape]
# type = "die"
# sides = 20                            # a regular d20 of jaxrb.dice (default edge)
#
# [initial]
# pos = [0.0, 0.0, 0.15]                # m; the sweep draws the height
# vel = [0.0, 0.0, 0.0]                 # m/s; the sweep draws the sideways speed
# omega = [20.0, -10.0, 5.0]            # rad/s, body frame; the sweep draws each component
#
# [[forces]]
# type = "gravity"
#
# [floor]
# restitution = 0.5
# friction = 0.3
#
# [simulation]
# t_end = 4.0                           # s: every die at rest
# num_saves = 2
# rtol = 1e-8
# atol = 1e-8
# max_impacts = 200
# ```
#
# and 1000 random throws (each `-r` path must exist in the file: hence the `vel` line):
#
# ```bash
# jaxrb sweep d20.toml -r initial.pos.2=0.05:0.3 -r initial.vel.0=-0.5:0.5 \
#   -r initial.vel.1=-0.5:0.5 -r initial.omega.0=-40:40 -r initial.omega.1=-40:40 \
#   -r initial.omega.2=-40:40 -r floor.restitution=0.2:0.8 -r floor.friction=0.2:0.8 \
#   --random-attitude --draws 1000 -o d20-sweep
# ```
#
# `d20-sweep/sweep.csv` has one row per throw with its draws, its `result` and, in the
# column `face_up`, the number the die shows (for a d4 the face it lies on); `--random-attitude`
# draws attitudes uniform over all rotations. The counts of `face_up` over the successful rows
# are the counts above.
