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
# # 06 — Fitting restitution and air drag
#
# **Restitution (Newton's hypothesis).** At an impact the normal velocity of the contact point
# reverses and shrinks: v' = -e v, 0 <= e <= 1. A ball dropped from rest at height h0 (docs/theory.md, section 8.2):
#
# - first impact t_1 = sqrt(2 h0 / g), then t_(k+1) - t_k = 2 e^k sqrt(2 g h0) / g;
# - apex after bounce k: e^(2k) h0; all bounces end at the Zeno time t_1 (1 + e) / (1 - e).
#
# `jaxrb.fit.fit_restitution` fits e (and h0 if unknown) to impact times and/or apex heights.
#
# **Drag.** A quadratic drag force F = -k |v| v (k = rho C_D A / 2) on a falling ball gives, for a
# vertical drop from rest, the exact terminal-velocity solution with v_t = sqrt(m g / k):
#
# v(t) = -v_t tanh(g t / v_t),  z(t) = z0 - (v_t^2 / g) ln cosh(g t / v_t).
#
# `jaxrb.fit.fit_drag` fits k (and the initial position and velocity) to tracked positions through
# the differentiable simulation.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import diffrax as dfx
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb
import jaxrb.fit
from jaxrb.analytic import ball_apex_heights, ball_height, ball_impact_times, ball_rest_time

rng = np.random.default_rng(0)
E_TRUE, H0_TRUE, G = 0.7, 1.2, 9.81

# %% [markdown]
# ## 1. Restitution from bounce times
# Noise-free times first (the oracle: e and h0 must come back exactly), then six impact times with
# 2 ms timing noise, e.g. from the sound of the bounces.

# %%
times = np.asarray(ball_impact_times(H0_TRUE, E_TRUE, 6))
exact_fit = jaxrb.fit.fit_restitution(impact_times=times, restitution0=0.5)
print(f"noise-free: e = {exact_fit.values['restitution']:.10f}, h0 = {exact_fit.values['h0']:.10f}")
assert (
    abs(exact_fit.values["restitution"] / E_TRUE - 1) < 1e-8
    and abs(exact_fit.values["h0"] / H0_TRUE - 1) < 1e-8
)

times_noisy = times + 2e-3 * rng.standard_normal(times.size)
fit_t = jaxrb.fit.fit_restitution(impact_times=times_noisy, restitution0=0.5)
e_t, se_t = fit_t.values["restitution"], fit_t.std["restitution"]
print(
    f"from noisy times: e = {e_t:.4f} +- {se_t:.4f}, h0 = {fit_t.values['h0']:.4f} +- {fit_t.std['h0']:.4f} m"
)
assert abs(e_t - E_TRUE) < 4 * se_t

# %% [markdown]
# ## 2. Restitution from apex heights (known drop height)
# Four apex heights measured with 5 mm noise, h0 known:

# %%
heights = np.asarray(ball_apex_heights(H0_TRUE, E_TRUE, 4)) + 5e-3 * rng.standard_normal(4)
fit_h = jaxrb.fit.fit_restitution(apex_heights=heights, h0=H0_TRUE, restitution0=0.5)
e_h, se_h = fit_h.values["restitution"], fit_h.std["restitution"]
print(f"from apex heights: e = {e_h:.4f} +- {se_h:.4f}")
assert abs(e_h - E_TRUE) < 4 * se_h

t = jnp.linspace(0.0, 4.0, 2000)
fig, ax = plt.subplots(figsize=(9, 4))
ax.plot(t, ball_height(t, H0_TRUE, E_TRUE), "k", lw=1, label=f"truth, e = {E_TRUE}")
ax.plot(t, ball_height(t, fit_t.values["h0"], e_t), "--", label=f"fitted to times, e = {e_t:.3f}")
ax.plot(t, ball_height(t, H0_TRUE, e_h), ":", label=f"fitted to apexes, e = {e_h:.3f}")
ax.plot(times_noisy, np.zeros_like(times_noisy), "v", ms=8, label="measured impact times")
apex_t = times[:4] + E_TRUE ** np.arange(1, 5) * np.sqrt(2 * G * H0_TRUE) / G  # apex after bounce k
ax.plot(apex_t, heights, "o", label="measured apex heights")
ax.axvline(float(ball_rest_time(H0_TRUE, E_TRUE)), color="gray", ls=":", label="Zeno rest time")
ax.set_xlabel("t (s)")
ax.set_ylabel("height of the lowest point (m)")
ax.legend(fontsize="small")
plt.show()

# %% [markdown]
# ## 3. A simulated ball on a `jaxrb.Floor` against the exact bounce
# `jaxrb.simulate` locates each impact as an event and applies Newton's restitution at the touching
# point (the contact engine `jaxrb.contact`, docs/contact.md); its height must follow
# `jaxrb.analytic.ball_height`, and its impact times fed to `fit_restitution` must give e back.
# Once a bounce leaves the floor slower than `rest_speed` (default 1 cm/s) the remaining infinite
# series of micro-bounces is replaced by its limit, a *Zeno merge* (`traj.contact.zeno_merges`):
# the ball then stays on the floor in persistent contact, and `traj.impacts.rest_time` records the
# time the series would have ended (for a point on a flat floor, exactly the Zeno time). From then
# on the height may differ from the exact one by at most rest_speed^2 / (2 g) = 5 um.

# %%
R_BALL = 0.05
ball = jaxrb.Scene(
    jaxrb.RigidBody(0.1, shape=jaxrb.Sphere(R_BALL)),
    forces=(jaxrb.Gravity((0.0, 0.0, -G)),),
    floor=jaxrb.Floor(E_TRUE),
)
ts = jnp.linspace(0.0, 4.0, 801)
traj = jaxrb.simulate(
    ball, jaxrb.make_state(pos=(0.0, 0.0, H0_TRUE + R_BALL)), ts, rtol=1e-10, atol=1e-10
)
z = traj.states.pos[:, 2] - R_BALL
dz = jnp.abs(z - ball_height(ts, H0_TRUE, E_TRUE))
n_imp = int(traj.impacts.count)
sim_times = np.asarray(traj.impacts.time[:n_imp])
t_err = np.max(np.abs(sim_times[:6] - times))
err_bounces = float(jnp.max(jnp.where(ts < sim_times[-1], dz, 0.0)))
bound = 0.01**2 / (2 * G)  # rest_speed = 1 cm/s: the merged micro-bounces are lower than this
print(f"{n_imp} impacts recorded; first 6 impact times off by {t_err:.1e} s")
print(
    f"max |z_sim - z_exact| up to the last impact {err_bounces:.1e} m, overall {float(dz.max()):.1e} m (bound {bound:.1e} m)"
)
print(
    f"rest time: simulated {float(traj.impacts.rest_time):.6f} s, exact {float(ball_rest_time(H0_TRUE, E_TRUE)):.6f} s"
)
print(
    f"bounce series merged: {int(traj.contact.zeno_merges)}; contact mode at the end: "
    f"{jaxrb.contact.KIND_NAMES[int(traj.contact.kind[-1])]}"
)
assert t_err < 1e-9 and err_bounces < 1e-8 and float(dz.max()) <= bound
assert abs(float(traj.impacts.rest_time) - float(ball_rest_time(H0_TRUE, E_TRUE))) < 1e-8
e_sim = jaxrb.fit.fit_restitution(impact_times=sim_times[:6], restitution0=0.5).values[
    "restitution"
]
print(f"e fitted to the simulated impact times: {e_sim:.10f}")
assert abs(e_sim - E_TRUE) < 1e-8

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
ax1.plot(ts, ball_height(ts, H0_TRUE, E_TRUE), "k", lw=3, alpha=0.3, label="exact ball_height")
ax1.plot(ts, z, "C0", lw=1, label="jaxrb.simulate with Floor(0.7)")
ax1.set_xlabel("t (s)")
ax1.set_ylabel("height (m)")
ax1.legend()
ax2.semilogy(ts, jnp.maximum(dz, 1e-17))
ax2.axvline(float(traj.impacts.rest_time), color="gray", ls=":", label="rest time")
ax2.axhline(bound, color="r", ls="--", label="rest_speed^2 / 2g")
ax2.legend()
ax2.set_xlabel("t (s)")
ax2.set_ylabel("|z_sim - z_exact| (m)")
ax2.set_title("simulated vs exact bounce (zeros drawn at 1e-17)")
plt.show()

# %% [markdown]
# ## 4. Quadratic drag from a tracked drop
# A tennis ball (m = 57 g, d = 6.6 cm, C_D = 0.55 in air of 1.2 kg/m^3: k = rho C_D A / 2) dropped from
# rest, tracked at 10 Hz for 3 s with 2 cm position noise. The data come from the exact tanh /
# log-cosh solution, not from the simulator.

# %%
MASS = 0.057
K_TRUE = float(
    jaxrb.QuadraticDrag.from_air(rho=1.2, drag_coefficient=0.55, area=np.pi * 0.033**2).coefficient
)
v_t = np.sqrt(MASS * G / K_TRUE)
t_obs = np.linspace(0.0, 3.0, 31)
z_exact = 50.0 - v_t**2 / G * np.log(np.cosh(G * t_obs / v_t))
pos_exact = np.stack([np.zeros_like(t_obs), np.zeros_like(t_obs), z_exact], -1)
pos_noisy = pos_exact + 0.02 * rng.standard_normal(pos_exact.shape)
print(f"k = {1e3 * K_TRUE:.4f} g/m, terminal speed {v_t:.1f} m/s")

SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
fit0 = jaxrb.fit.fit_drag(t_obs, pos_exact, mass=MASS, drag0=0.5 * K_TRUE, g=(0.0, 0.0, -G), **SIM)
print(
    f"noise-free: k = {fit0.values['drag']:.8f} (relative error {fit0.values['drag'] / K_TRUE - 1:.1e})"
)
assert abs(fit0.values["drag"] / K_TRUE - 1) < 1e-6
fit_k = jaxrb.fit.fit_drag(t_obs, pos_noisy, mass=MASS, drag0=0.5 * K_TRUE, g=(0.0, 0.0, -G), **SIM)
k_fit, k_std = fit_k.values["drag"], fit_k.std["drag"]
print(
    f"noisy: k = {1e3 * k_fit:.4f} +- {1e3 * k_std:.4f} g/m (true {1e3 * K_TRUE:.4f}); C_D = {k_fit / K_TRUE * 0.55:.3f} +- {k_std / K_TRUE * 0.55:.3f}"
)
assert abs(k_fit - K_TRUE) < 4 * k_std

# %%
tt = np.linspace(0.0, 3.0, 301)
v_fit = np.sqrt(MASS * G / k_fit)
vz0 = fit_k.values["vel0"][2]
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
ax1.plot(t_obs, pos_noisy[:, 2], "o", ms=4, label="tracked (2 cm noise)")
ax1.plot(tt, 50.0 - v_t**2 / G * np.log(np.cosh(G * tt / v_t)), "k", lw=1, label="exact, true k")
ax1.plot(
    tt,
    fit_k.values["pos0"][2] - v_fit**2 / G * np.log(np.cosh(G * tt / v_fit)),
    "--",
    label=f"fitted k = {1e3 * k_fit:.4f} g/m",
)
ax1.plot(tt, 50.0 - G * tt**2 / 2, ":", label="no drag")
ax1.set_xlabel("t (s)")
ax1.set_ylabel("z (m)")
ax1.legend(fontsize="small")
res_z = fit_k.residuals.reshape(-1, 3)[:, 2]  # model - data, z component (m)
ax2.plot(t_obs, 100 * res_z, "o-", ms=4)
ax2.axhspan(-2, 2, color="gray", alpha=0.2, label="+- noise sigma")
ax2.set_xlabel("t (s)")
ax2.set_ylabel("residual z (cm)")
ax2.set_title(f"residuals of the drag fit (fitted v_z(0) = {vz0:+.3f} m/s)")
ax2.legend()
plt.show()
