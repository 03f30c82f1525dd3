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
# # 02 — Torque-free precession
#
# With no moment about the mass centre, the angular momentum K is constant in the world, and the
# body's angular velocity moves according to Euler's equations. We compare `jaxrb.simulate` with the
# exact solutions in `jaxrb.analytic`:
#
# 1. the symmetric top (omega and K, the angles gamma, alpha, beta);
# 2. the spherical top (no precession);
# 3. the asymmetric top: polhodes and a herpolhode;
# 4. the Dzhanibekov flip about the intermediate axis.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb
import jaxrb.plotting
from jaxrb.analytic import asymmetric_top, flip_half_period, symmetric_top


def free(inertia):
    return jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.asarray(inertia)))


# %% [markdown]
# ## 1. Symmetric top
# J1 = J2 = 1, J3 = 2 (oblate), omega0 = (0.4, 0, 1.0) in body axes. The body omega precesses about
# the symmetry axis at lambda = (J1 - J3) w3 / J1; in the world, the symmetry axis and omega both
# turn about the fixed K. gamma = angle(axis, K), alpha = angle(axis, omega), beta = alpha - gamma.

# %%
J1, J3 = 1.0, 2.0
omega0 = jnp.array([0.4, 0.0, 1.0])
scene = free([J1, J1, J3])
ts = jnp.linspace(0.0, 20.0, 401)
traj = jaxrb.simulate(scene, jaxrb.make_state(omega=omega0), ts, rtol=1e-10, atol=1e-10)
exact = symmetric_top(ts, J1, J3, omega0)
print("max |omega - exact|:", float(jnp.max(jnp.abs(traj.states.omega - exact.omega))))
assert jnp.allclose(traj.states.omega, exact.omega, atol=1e-7)

K = jaxrb.angular_momentum(scene, traj.states)  # world frame, constant
axis = jaxrb.quat_rotate(traj.states.quat, jnp.array([0.0, 0.0, 1.0]))
w_world = jaxrb.quat_rotate(traj.states.quat, traj.states.omega)
angle = lambda a, b: jnp.degrees(
    jnp.arccos(jnp.sum(a * b, -1) / jnp.linalg.norm(a, axis=-1) / jnp.linalg.norm(b, axis=-1))
)
w_tau = float(jnp.hypot(omega0[0], omega0[1]))
Kn = float(jnp.sqrt(J1**2 * w_tau**2 + J3**2 * omega0[2] ** 2))
wn = float(jnp.linalg.norm(omega0))
gamma = np.degrees(np.arccos(J3 * float(omega0[2]) / Kn))
alpha = np.degrees(np.arccos(float(omega0[2]) / wn))
print(
    f"K drift {float(jnp.max(jnp.abs(K - K[0]))):.1e}; lambda = {(J1 - J3) * float(omega0[2]) / J1:+.3f} rad/s"
)
print(f"gamma: formula {gamma:.6f} deg, simulated {float(angle(axis, K).mean()):.6f} deg")
print(f"alpha: formula {alpha:.6f} deg, simulated {float(angle(axis, w_world).mean()):.6f} deg")
print(
    f"beta = alpha - gamma = {alpha - gamma:.6f} deg, simulated {float(angle(w_world, K).mean()):.6f} deg"
)
assert np.allclose(angle(axis, K), gamma, atol=1e-6) and np.allclose(
    angle(axis, w_world), alpha, atol=1e-6
)
assert np.allclose(angle(w_world, K), abs(alpha - gamma), atol=1e-6)

# %%
fig = plt.figure(figsize=(11, 4.5))
ax = fig.add_subplot(1, 2, 1)
for k in range(3):
    ax.plot(ts, traj.states.omega[:, k], label=f"omega_{k + 1} (body)")
ax.plot(ts[::20], exact.omega[::20, 0], "k.", label="exact")
ax.plot(ts[::20], exact.omega[::20, 1], "k.")
ax.set_xlabel("t (s)")
ax.set_ylabel("rad/s")
ax.legend(fontsize="small")
ax3 = fig.add_subplot(1, 2, 2, projection="3d")
k_hat = K[0] / jnp.linalg.norm(K[0])
ax3.quiver(0, 0, 0, *k_hat, color="k", label="K (fixed)")
ax3.plot(*(axis.T), label="symmetry axis (space cone)")
ax3.plot(*((w_world / wn).T), label="omega / |omega|")
ax3.set_title("world frame: both turn about K")
ax3.legend(fontsize="small")
plt.show()

# %% [markdown]
# ## 2. Spherical top
# J = 1.5 * identity: omega is constant in the body and in the world.

# %%
scene = free([1.5, 1.5, 1.5])
omega0 = jnp.array([0.3, -0.7, 1.1])
traj = jaxrb.simulate(
    scene, jaxrb.make_state(omega=omega0), jnp.linspace(0.0, 10.0, 401), rtol=1e-10, atol=1e-10
)
w_world = jaxrb.quat_rotate(traj.states.quat, traj.states.omega)
print(
    "body drift",
    float(jnp.max(jnp.abs(traj.states.omega - omega0))),
    "world drift",
    float(jnp.max(jnp.abs(w_world - omega0))),
)
assert jnp.allclose(traj.states.omega, omega0, atol=1e-10) and jnp.allclose(
    w_world, omega0, atol=1e-6
)

# %% [markdown]
# ## 3. Asymmetric top: polhodes and herpolhode
# I = (1, 2, 3). Polhodes are the curves omega(t) (body frame) on the energy ellipsoid: closed
# loops about the axes of least and greatest inertia, separated by the separatrix through the
# intermediate axis. The exact elliptic-function solution draws them cheaply; the herpolhode (omega in
# the world, on the invariable plane perpendicular to K) needs the attitude, so we simulate one.

# %%
inertia = jnp.array([1.0, 2.0, 3.0])
t = jnp.linspace(0.0, 30.0, 1200)
starts = [(1.0, 0.1, 0.05), (1.0, 0.4, 0.1), (0.15, 0.3, 0.55), (0.05, 0.3, 0.56), (0.3, 0.1, 0.55)]
curves = []
for w0 in starts:
    w0 = jnp.asarray(w0)
    w0 = w0 * jnp.sqrt(1.0 / jnp.sum(inertia * w0**2))  # all on the ellipsoid 2E = 1
    curves.append(asymmetric_top(t, inertia, w0))
jaxrb.plotting.plot_polhode(inertia, curves, labels=[f"start {s}" for s in starts])
plt.show()

scene = free(inertia)
w0 = jnp.array([0.3, 0.1, 0.55])
traj = jaxrb.simulate(
    scene, jaxrb.make_state(omega=w0), jnp.linspace(0.0, 60.0, 401), rtol=1e-10, atol=1e-10
)
err = float(jnp.max(jnp.abs(traj.states.omega - asymmetric_top(traj.ts, inertia, w0))))
print(f"max |omega_sim - omega_exact| = {err:.1e} rad/s")
assert err < 1e-7
jaxrb.plotting.plot_polhode_herpolhode(traj, scene)
plt.show()

# %% [markdown]
# ## 4. The Dzhanibekov flip
# Spin about the intermediate axis is unstable: a tiny perturbation makes omega_2 flip sign
# periodically. The exact half-period between flips is 2 K(m) / |omega_p| (`flip_half_period`).

# %%
omega0 = jnp.array([1e-3, 2.0, 1e-3])
half = float(flip_half_period(inertia, omega0))
ts = jnp.linspace(0.0, 2.2 * half, 401)
traj = jaxrb.simulate(free(inertia), jaxrb.make_state(omega=omega0), ts, rtol=1e-10, atol=1e-10)
w2 = np.asarray(traj.states.omega[:, 1])
crossings = np.asarray(ts)[1:][np.sign(w2[1:]) != np.sign(w2[:-1])]
print(
    f"exact flip half-period {half:.4f} s; simulated sign changes of omega_2 at {np.round(crossings, 3)} s"
)
assert len(crossings) >= 2 and abs((crossings[1] - crossings[0]) - half) < 2 * float(ts[1] - ts[0])
fig, ax = plt.subplots(figsize=(8, 4))
for k in range(3):
    ax.plot(ts, traj.states.omega[:, k], label=f"omega_{k + 1}")
ax.plot(ts[::12], asymmetric_top(ts, inertia, omega0)[::12, 1], "k.", label="omega_2 exact")
ax.set_xlabel("t (s)")
ax.set_ylabel("body angular velocity (rad/s)")
ax.set_title(f"Dzhanibekov flip, I = (1, 2, 3): half-period {half:.2f} s")
ax.legend(fontsize="small")
plt.show()
