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
# # 10 — Roulette: where does the ball leave the wall?
#
# A croupier launches the ball along the outer wall of the wheel's stator. It runs round
# pressed against the wall, slowed by the air and by rolling resistance, until it is too slow
# for the wall to be needed; then it leaves the wall, runs down the inclined track and, in a
# real wheel, hits the deflectors and the rotor. Small and Tse (2012, Chaos 22, 033150)
# showed that the moment and place where the ball leaves the wall can be predicted from its
# first revolutions, well enough to beat the house edge: the motion on the wall is
# deterministic and simple.
#
# In jaxrb the stator is a `jaxrb.Wheel`: the track is the inside of an upright cone rising
# outwards at the inclination d, the wall the inside of a vertical cylinder of radius R. A
# ball in the corner touches both at once, a **two-point contact**: it rolls on the track and
# slides along the smooth wall (docs/contact.md, section 11, says why the wall is smooth). Its
# centre runs on the circle rho = R - r, and the wall pushes with
#
# N_wall = m ((7/5) v^2 / rho - g tan d),
#
# so the ball leaves the wall when **v^2 = (5/7) g rho tan d**. (A point mass would leave at
# v^2 = g rho tan d; the rolling ball's spin changes the balance: it is the speed at which the
# ball would roll round the cone alone on that circle.) With quadratic drag -k |v| v and
# rolling resistance mu_r, the speed on the wall obeys v' = -(A + B v^2) with
# A = (5/7) mu_r g / cos d and B = (5/7) (k / m - (2/5) mu_r sin d / rho), which has closed
# forms for the leaving time t* and the azimuth phi* the ball has turned through by then.
#
# That holds while the track's friction keeps the ball rolling. Rolling round the wall needs
# a friction force up the slope of (2/5) m (v^2 / rho) cos d, and the track pushes with
# N_track = m (g / cos d - (2/5) (v^2 / rho) sin d), so a ball launched faster than
# v_roll, with v_roll^2 = rho mu g / ((2/5) cos d (cos d + mu sin d)), **slides** on the track
# at first. The closed forms are then only what would have happened had it rolled.
#
# The scene is the shipped example `roulette` (`jaxrb run roulette` runs it): a 21 mm, 5.5 g
# ball launched at 1.9 m/s along a wall of radius 0.41 m, track inclination 0.3 rad, track
# friction 0.4, air drag of a sphere (C_D = 0.5) and rolling resistance 0.01.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd().resolve().parent))  # the repository root: `benchmarks`

import matplotlib.pyplot as plt
import numpy as np

from benchmarks import roulette

ex = roulette.example()  # the shipped scene and its numbers
t_cf, phi_cf, v_leave = roulette.closed_form(ex.v0)
print(f"ball: r = {ex.r_ball * 1e3:g} mm, m = {ex.mass * 1e3:g} g; centre radius")
print(f"rho = {ex.rho:g} m, track inclination {ex.d:g} rad")
print(f"drag k = {ex.k:.4g} kg/m, rolling resistance {ex.mu_r:g}")
print(f"launched at {ex.v0:g} m/s it leaves the wall at v* = {v_leave:.4f} m/s,")
print(f"after t* = {t_cf:.4f} s and {phi_cf / (2 * np.pi):.2f} turns (closed form)")
print(
    f"the track's friction keeps it rolling for launches up to {roulette.rolling_limit():.3f} m/s"
)

# %% [markdown]
# ## Launch speed against where the ball leaves
#
# Three launch speeds, two below v_roll and one above, each simulated to its lift-off event
# (the wall's normal force reaching zero ends the two-point contact), then again to that time
# to read the ball's azimuth there. All three run in one vmapped, compiled call.

# %%
start = time.perf_counter()
speeds = np.array([1.5, 1.9, 2.5])
t, phi, t_cf, phi_cf = roulette.sweep(speeds)
print(f"3 launches in {time.perf_counter() - start:.0f} s (compilation included)")
print(f"{'v0 (m/s)':>8} {'t* jaxrb':>10} {'t* closed':>10} {'phi* jaxrb':>11} {'phi* closed':>11}")
for row in zip(speeds, t, t_cf, phi, phi_cf, strict=True):
    print("{:8.2f} {:10.5f} {:10.5f} {:11.5f} {:11.5f}".format(*row))
rolls = speeds <= roulette.rolling_limit()
print(
    f"rolling launches: largest relative difference of t* {np.max(np.abs(t - t_cf)[rolls] / t_cf[rolls]):.1e}"
)

# %% [markdown]
# Below v_roll jaxrb and the closed forms agree to the solver's tolerance. Above it the ball
# leaves the wall much sooner than it would rolling: while it slides, the friction turns it
# about the track's normal (that axis turns with the ball's azimuth), and that spin, kept
# once it rolls again, changes the balance of forces against the wall (docs/contact.md,
# section 11). The angle it turns through before leaving grows by about a turn for every few
# cm/s of launch speed: **where** the ball leaves the wall (the azimuth mod 360 deg) is the
# sensitive quantity, which is why a prediction needs good estimates of the launch speed and
# of the two resistances.
#
# ## Identify drag and rolling resistance from the first revolutions
#
# The data: the ball's azimuth at 25 times over its first 4 s on the wall (launched at 1.9 m/s,
# it leaves at 10 s), from the true run
# plus Gaussian noise of 0.005 rad (2 mm at the wall; a camera's tracking). Levenberg-Marquardt
# fits k and mu_r (as logarithms, so they stay positive) through the simulation's
# forward-mode derivatives, starting from twice the true drag and half the true rolling
# resistance. The fit reports standard errors from its Jacobian.

# %%
start = time.perf_counter()
fit, ts, data, truth = roulette.identify(track=4.0, noise=0.005)
print(f"fit in {time.perf_counter() - start:.0f} s (compilation included)")
print(fit.report())
print(f"true values: drag {ex.k:.5g}, rolling_resistance {ex.mu_r:g}")

# %% [markdown]
# ## Predict where it leaves
#
# Parameter sets drawn from the fit's covariance, each run to its lift-off: their spread is
# the prediction's uncertainty (3 draws here, far too few for a spread; the benchmark takes
# 32, with 6 s of tracking).

# %%
start = time.perf_counter()
params, t_pred, phi_pred = roulette.predict(fit, 3)
(t_true,), (phi_true,) = roulette.leaving(np.array([ex.v0]), np.array([ex.k]), np.array([ex.mu_r]))
print(f"3 predictions in {time.perf_counter() - start:.0f} s")
print(f"predicted: leaves at {np.mean(t_pred):.3f} +- {np.std(t_pred):.3f} s (true {t_true:.3f} s)")
print(
    f"azimuth {np.degrees(np.mean(phi_pred)):.1f} +- {np.degrees(np.std(phi_pred)):.1f} deg "
    f"(true {np.degrees(phi_true):.1f} deg)"
)

fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
axes[0].plot(ts, np.degrees(data - truth), "o", ms=4, label="tracked - true")
axes[0].plot(ts, np.degrees(fit.residuals + data - truth), "-", label="fitted - true")
axes[0].set_xlabel("t (s)")
axes[0].set_ylabel("azimuth (deg)")
axes[0].legend()
axes[0].set_title("The tracked azimuth and the fit")
axes[1].plot(speeds, np.degrees(np.mod(phi, 2 * np.pi)), "o", label="jaxrb")
axes[1].plot(speeds[rolls], np.degrees(np.mod(phi_cf[rolls], 2 * np.pi)), "x", label="closed form")
axes[1].set_xlabel("launch speed (m/s)")
axes[1].set_ylabel("azimuth where it leaves (deg, mod 360)")
axes[1].legend()
fig.tight_layout()
plt.show()

# %% [markdown]
# ## At full size
#
# 29 launch speeds in [1.2, 4] m/s and 32 prediction draws (329 s on a 2-core CPU), writing `roulette.md` (the table and the fit),
# `roulette.png` and `roulette.npz` to `bench_out/`:
#
# ```bash
# python -m benchmarks.roulette --speeds 29 --draws 32 --out bench_out
# ```
#
# Its results and run time are in benchmarks/README.md (section "Roulette") and
# docs/contact.md (section 11).
