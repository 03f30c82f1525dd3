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
# # 08 — The thick coin: how often does it land on its side?
#
# A thin coin lands on a face; a long cylinder (a tin can, a pencil) lands on its side. In
# between there is a thickness at which a tossed coin shows its side as often as one of its two
# faces, a third of the time. How thick is that coin, and how often does a real, thin coin land
# on its edge?
#
# - **Murray and Teare** (1993, Phys. Rev. E 48, 2547) simulated a coin that *bounces* on a hard
#   floor and found that an American nickel (thickness / diameter h / d = 0.092) lands on its
#   side about once in 6000 tosses.
# - **Yong and Mahadevan** (2011, Am. J. Phys. 79, 1195) took a coin that does *not* bounce: it
#   touches the floor with a point of its rim and then falls, without slipping, over the edge on
#   whose side its mass centre lies. That gives closed forms for the probability of the side.
#
# ## The closed forms of the non-bouncing coin
#
# Cut the coin through its axis: a rectangle, d wide and h high, touching the floor at a corner.
# The diagonal from that corner to the centre makes the angle atan(h / d) with the face. Let
# theta (in [0, pi]) be the angle between the coin's axis and the vertical: the face is tilted
# by theta from the floor (by pi - theta for the other face, when theta > pi / 2). The centre
# is straight above the corner when the diagonal is vertical, theta + atan(h / d) = 90 deg,
# i.e. cot theta = h / d. A coin tilted less falls onto its face, a coin tilted more onto its
# side, and the same holds for the other face with pi - theta, so
#
# **side if and only if |cot theta| < h / d.**
#
# - *Attitude uniform on the sphere* (the axis points anywhere with equal probability): u = |cos
#   theta| is uniform on [0, 1], and |cot theta| = u / sqrt(1 - u^2) < h / d exactly when
#   u < h / sqrt(h^2 + d^2). Hence **P(side) = h / sqrt(h^2 + d^2)**. It is a third when
#   9 h^2 = h^2 + d^2, at **h / d = 1 / sqrt(8) = 0.354**.
# - *Coin flipped about a diameter* (the axis turns in a vertical plane and theta is uniform on
#   [0, pi)): |cot theta| < h / d on an arc of length 2 atan(h / d) around theta = pi / 2, so
#   **P(side) = (2 / pi) atan(h / d)**, a third when atan(h / d) = pi / 6, at
#   **h / d = 1 / sqrt(3) = 0.577**.
#
# A real coin that bounces and rolls can still fall from its side onto a face: for a thin coin
# the side is then much rarer than the closed forms say (the nickel's 1 in 6000 against the
# values printed below). jaxrb's ideal sharp-edged cylinder does the opposite: it lands on its
# side *more* often than the closed forms say, because once it rolls upright on its band,
# held by both rims, nothing tips it over (docs/contact.md, section 10, "The thick coin").

# %%
import jax

jax.config.update("jax_enable_x64", True)
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd().resolve().parent))  # the repository root: `benchmarks`

import matplotlib.pyplot as plt
import numpy as np

import jaxrb
from benchmarks import thick_coin
from benchmarks.contact_throws import throws

NICKEL = 0.092  # h / d of an American nickel
print("the closed forms of the non-bouncing coin, P(side):")
print(f"{'h / d':>8} {'uniform attitude':>17} {'flipped':>9}")
for r in (NICKEL, 0.1, 1 / np.sqrt(8), 0.5, 1 / np.sqrt(3), 1.0):
    print(f"{r:8.3f} {thick_coin.side_uniform(r):17.4f} {thick_coin.side_flipped(r):9.4f}")
print(
    f"nickel: 1 in {1 / thick_coin.side_uniform(NICKEL):.0f} (uniform attitude), "
    f"1 in {1 / thick_coin.side_flipped(NICKEL):.0f} (flipped), "
    "against about 1 in 6000 for the bouncing coin of Murray & Teare"
)

# %% [markdown]
# ## What jaxrb simulates
#
# `benchmarks/thick_coin.py` throws coins of diameter d = 24 mm and mass 7.5 g, with thickness
# h = (h / d) d, with the contact engine (`jaxrb.contact`: impacts with restitution and Coulomb
# friction, rolling, sliding and resting contact; docs/contact.md):
#
# - **the throws** are those of `benchmarks/contact_throws.py`, the same draws for every
#   thickness: released from a height drawn in [0.05, 0.3] m, with an attitude uniform over
#   all rotations, a spin drawn in [-40, 40] rad/s about each body axis and a sideways speed
#   drawn in [-0.5, 0.5] m/s along x and y; each throw lands on its own floor, with
#   restitution and friction each
#   drawn in [0.2, 0.8]. A thick coin that would start through the floor is lifted clear of
#   it by 1 mm. The coin does bounce: this is the Murray–Teare problem, not the non-bouncing
#   one of the closed forms.
# - **air resistance on the rotation**: a damping moment M = -c w, with c equal to 2 /s times
#   the coin's moment of inertia about a diameter. The model has no rolling resistance for a
#   cylinder, so without it a thin coin that ends up rolling upright on its rim would roll for
#   ever and never show a face; with it the rolling slows down and the coin comes down.
# - **the outcome** is read from the tilt of the coin's axis at the end time T: within 10 deg
#   of vertical it shows a face (it may still spin or wobble on it, but it cannot stand up
#   again), within 10 deg of horizontal it shows its side (it may still roll on it), anything
#   in between is *unsettled*: counted, and left out of the frequencies.
# - **Euler's disk.** A thick coin that comes down onto a face while spinning wobbles faster
#   and faster as it settles, and the point of its rim that touches the table alternates
#   between sticking and slipping ever more often. Each of those changes is a contact event,
#   and a run has a budget of 4 x 100 + 16 events (`max_impacts` = 100). Such a run can stop
#   at the budget before T (result `max_events_reached`); its coin is already lying almost
#   flat, so its outcome is decided and is read where it stopped, and the table counts how
#   many runs did so.
#
# One throw is one compiled call of `jaxrb.sweep` (`chunk_size=1`, tolerances 1e-8): a batch
# would wait for its slowest coin.
#
# A note on "random attitude": the study draws the starting attitude uniformly over all
# rotations (`throws(..., uniform_attitude=True)`: a normalised 4-vector of standard normals).
# The sanity study `contact_throws.py` turns the body instead by an angle uniform in [0, pi]
# about a uniform axis, which is not uniform over rotations (the angle of a uniform rotation
# has the density (1 - cos angle) / pi) and puts the coin's axis near vertical too often. For
# a uniform attitude the axis's |cos| from vertical is uniform on [0, 1]:

# %%
for uniform in (True, False):
    start, _, _ = throws(100_000, 2, uniform_attitude=uniform)
    axis_z = np.abs(np.asarray(jax.vmap(jaxrb.quat_to_matrix)(start.quat))[:, 2, 2])
    name = "uniform over rotations" if uniform else "angle U(0, pi)        "
    shares = [np.mean(axis_z > c) for c in (np.cos(np.radians(10)), np.cos(np.radians(45)))]
    print(
        f"{name}: axis within 10 / 45 deg of vertical at the start: "
        f"{shares[0]:.3f} / {shares[1]:.3f} (uniform: {1 - np.cos(np.radians(10)):.3f} / "
        f"{1 - np.cos(np.radians(45)):.3f})"
    )

# %% [markdown]
# The coin then spins at up to 40 rad/s about each axis for the 0.1 s or more of its flight and
# bounces, so its attitude when it lands is no longer the one it started with: the closed form
# for a uniform attitude without bouncing is a reference curve, not the law these throws
# should follow.
#
# ## A small study
#
# Full size (below) is 100 throws or more per thickness. Here: the thicknesses h / d = 0.1 and
# 0.5, 3 throws each, read at T = 3 s. This is `thick_coin.study(RATIOS, N, T_END, seed=2)`
# split into two cells: the first compiles the throw (about a minute) and runs the first
# coin, the second runs the other five with the same compiled function.

# %%
RATIOS, N, T_END, SEED = (0.1, 0.5), 3, 3.0, 2

# the rows `thick_coin.study` sweeps: the same N draws for every thickness
rows = thick_coin.study_rows(RATIOS, N, SEED)
R = len(RATIOS)
state = jax.tree.map(lambda x: x[:N], rows["state"])
restitution, friction = rows["restitution"][:N], rows["friction"][:N]
throw = thick_coin.make_throw(T_END)
t0 = time.perf_counter()
first = jaxrb.sweep(throw, jax.tree.map(lambda x: x[:1], rows), chunk_size=1, progress=False)
print(f"compiled and ran the first throw in {time.perf_counter() - t0:.0f} s")

# %%
t0 = time.perf_counter()
rest = jaxrb.sweep(throw, jax.tree.map(lambda x: x[1:], rows), chunk_size=1, progress=False)
print(f"the other {R * N - 1} throws: {time.perf_counter() - t0:.1f} s")
out = {k: np.concatenate([first[k], rest[k]]).reshape((R, N)) for k in first}

NAMES = {thick_coin.FACE: "face", thick_coin.SIDE: "side", thick_coin.UNSETTLED: "unsettled"}
kind = thick_coin.outcome(out)
height = np.asarray(state.pos[:, 2])
print(
    f"{'h / d':>6} {'throw':>5} {'height m':>8} {'e':>5} {'mu':>5} "
    f"{'tilt at T (deg)':>15} {'speed at T (m/s)':>16} {'result':>18} {'outcome':>9}"
)
for i, r in enumerate(RATIOS):
    for j in range(N):
        code = int(out["code"][i, j])
        result = {0: "success", thick_coin.MAX_EVENTS: "event budget"}.get(code, f"code {code}")
        print(
            f"{r:6.2f} {j:5d} {height[j]:8.3f} {float(restitution[j]):5.2f} {float(friction[j]):5.2f} "
            f"{np.degrees(np.arccos(min(out['axis_z'][i, j], 1.0))):15.1f} "
            f"{out['speed'][i, j]:16.3g} {result:>18} {NAMES[int(kind[i, j])]:>9}"
        )

# %% [markdown]
# `thick_coin.summary` counts, per thickness, the decided throws (a face or the side), those on
# the side, the side frequency among the decided ones with its 95 % Wilson score interval, and
# the runs that stopped at the event budget:

# %%
settled, side, freq, lo, hi, stopped = thick_coin.summary(RATIOS, out)
print(
    f"{'h / d':>6} {'decided':>8} {'at budget':>9} {'side':>5} {'P(side)':>8} "
    f"{'95 % interval':>16} {'uniform':>8} {'flipped':>8}"
)
for k, r in enumerate(RATIOS):
    print(
        f"{r:6.2f} {settled[k]:>4d} / {N} {stopped[k]:9d} {side[k]:5d} {freq[k]:8.3f} "
        f"  [{lo[k]:.3f}, {hi[k]:.3f}] {thick_coin.side_uniform(r):8.3f} "
        f"{thick_coin.side_flipped(r):8.3f}"
    )

# %%
fig, ax = plt.subplots(figsize=(7.5, 4.6))
fine = np.linspace(0.0, 0.7, 200)
ax.plot(fine, thick_coin.side_uniform(fine), "k--", lw=1, label="no bounce, uniform attitude")
ax.plot(fine, thick_coin.side_flipped(fine), "k:", lw=1, label="no bounce, flipped")
ax.errorbar(
    RATIOS,
    freq,
    yerr=[np.maximum(freq - lo, 0), np.maximum(hi - freq, 0)],
    fmt="o",
    color="C3",
    capsize=3,
    label=f"jaxrb, {N} throws each: 95 % interval",
)
ax.plot([NICKEL], [1 / 6000], "s", color="C0", label="Murray & Teare 1993: a nickel, 1/6000")
ax.axhline(1 / 3, color="0.6", lw=0.8)
for r in (1 / np.sqrt(8), 1 / np.sqrt(3)):
    ax.axvline(r, color="0.6", lw=0.8, ls="-.")
ax.text(0.01, 1 / 3 + 0.01, "a third", color="0.4", fontsize=8)
ax.set(
    xlabel="thickness / diameter  h / d",
    ylabel="P(lands on its side)",
    title="The thick coin (a small sample)",
    xlim=(0, 0.7),
    ylim=(0, 1),
)
ax.legend(fontsize=8, loc="upper left")
ax.grid(alpha=0.3)
plt.tight_layout()
plt.show()

# %% [markdown]
# With three throws per thickness the Wilson intervals span most of [0, 1]: this run shows the
# pipeline (the throws, the outcome, the table, the picture), not the answer. The dash-dotted
# lines mark the thicknesses at which the closed forms reach a third.
#
# ## At full size
#
# The full study, 100 throws for each of h / d = 0.1, 0.2, ..., 0.6, read at T = 4 s, writes
# `thick_coin.md` (the table), `thick_coin.png` (the picture above, with all the points) and
# `thick_coin.npz` (every throw's outputs) to `bench_out/`:
#
# ```bash
# python -m benchmarks.thick_coin --n 100 --out bench_out
# ```
#
# (`--ratios 0.1,0.3,0.5` picks other thicknesses, `--t-end` another reading time.) Its results
# and their discussion are in docs/contact.md, section "The thick coin", and in
# benchmarks/README.md.
#
# The same kind of study runs from the shipped scene file `thick_coin` (a 24 mm, 7.5 g coin,
# h / d = 0.3, with a damping moment), without Python, by `jaxrb sweep`; this is the command in
# the comment at the top of `jaxrb/scenes/thick_coin.toml`:
#
# ```bash
# jaxrb sweep thick_coin -p body.shape.half_height=0.0012,0.0036,0.0072 \
#   -r initial.pos.2=0.05:0.3 -r initial.omega.0=-40:40 -r initial.omega.1=-40:40 \
#   -r initial.omega.2=-40:40 -r floor.restitution=0.2:0.8 -r floor.friction=0.2:0.8 \
#   --random-attitude --draws 1000 -o thick-coin-sweep
# ```
#
# It runs 1000 random throws at each of h / d = 0.1, 0.3 and 0.6 and writes one row per run to
# `thick-coin-sweep/sweep.csv`. `up_axis` is the body axis (+x ... -z) nearest the world's up
# and `tilt_deg` the angle between the two: a coin that ended on a face has `up_axis` +z or -z
# (its own axis, the cylinder's, is body z) with a small `tilt_deg`; a coin on its side has
# `up_axis` one of +x, -x, +y, -y (the up direction then lies in the coin's plane, and
# `tilt_deg` is up to 45 deg, depending on how the coin is turned about its axis).
#
# The sweep is close to the benchmark but not the same: `--random-attitude` draws attitudes
# uniform over all rotations; the sideways velocity (0.2 m/s along x) and the damping moment's
# coefficient stay those of the scene file (the latter is not scaled with the thickness); the
# scene allows 200 impacts and saves 401 times up to T = 4 s.
