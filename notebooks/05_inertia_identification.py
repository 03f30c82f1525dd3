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
# # 05 — Identifying a full inertia tensor from gyro data
#
# A body tumbles freely; a gyro records its body-frame angular velocity omega(t) with noise. Euler's
# equations with products of inertia (docs/theory.md, section 4.2),
#
# J w_dot + w x (J w) = M_C = 0,  J = [[J11, -J12, -J13], [-J12, J22, -J23], [-J13, -J23, J33]],
#
# predict omega(t) from J and omega(0). `jaxrb.fit.fit_inertia` fits J (and omega(0), a nuisance
# parameter) by Levenberg–Marquardt *through the differentiable simulation*; J is parameterised by
# the log-Cholesky factor of its pseudo-inertia, so every iterate is a physical tensor (symmetric,
# positive definite, triangle inequality). Uncertainties are Gauss–Newton:
# Cov = sigma^2 (J_r^T J_r)^-1 with the residual Jacobian J_r and sigma^2 = |r|^2 / (n - p).
#
# **Scale.** With no torque, J and c J give the same omega(t) for every c > 0 (divide Euler's
# equations by c). Torque-free data determine J only up to scale; `fit_inertia` fixes the trace to
# that of the initial guess (and says so), or gets the absolute scale from a known torque.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import diffrax as dfx
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb
import jaxrb.fit

# A fixed-step integrator for data and model: the fit then tests identification, not truncation
# error, and each simulation compiles quickly.
SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
J_TRUE = np.array([[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]])  # kg m^2, body axes
OMEGA0 = np.array([1.0, 0.5, 0.8])  # rad/s
TS = np.linspace(0.0, 4.0, 81)
SIGMA = 2e-3  # gyro noise, rad/s


def observe(J, omega0=OMEGA0):
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.asarray(J)))
    traj = jaxrb.simulate(
        scene, jaxrb.make_state(omega=jnp.asarray(omega0)), jnp.asarray(TS), **SIM
    )
    return np.asarray(traj.states.omega)


omega_clean = observe(J_TRUE)
omega_noisy = omega_clean + SIGMA * np.random.default_rng(0).standard_normal(omega_clean.shape)
J_START = J_TRUE * np.array(
    [[1.3, 0.7, 1.3], [0.7, 1.3, 0.7], [1.3, 0.7, 0.7]]
)  # 30 % off, entry by entry
print("initial guess:\n", J_START)

# %% [markdown]
# ## 1. Scale ambiguity of torque-free data
# The same start with J and 2.5 J gives the same omega(t) (to round-off):

# %%
diff = np.max(np.abs(observe(2.5 * J_TRUE) - omega_clean))
print(f"max |omega(2.5 J) - omega(J)| = {diff:.1e} rad/s")
assert diff < 1e-12

# %% [markdown]
# ## 2. Noise-free data: exact recovery (up to the scale)
# The oracle: J_TRUE rescaled to the trace of the guess.

# %%
res0 = jaxrb.fit.fit_inertia(TS, inertia0=J_START, omega=omega_clean, **SIM)
J_ref = J_TRUE * np.trace(J_START) / np.trace(J_TRUE)
rel = np.max(np.abs(res0.values["inertia"] - J_ref)) / np.max(np.abs(J_ref))
print(res0.warnings[0])
print(f"noise-free: {res0.num_steps} LM steps, max relative error of the tensor {rel:.1e}")
assert res0.converged and rel < 1e-6

# %% [markdown]
# ## 3. Noisy gyro data (sigma = 2e-3 rad/s)
# The fitted entries with their one-sigma errors against the truth. Six independent numbers define a
# tensor; with the trace fixed, five are free (the sixth follows).

# %%
res = jaxrb.fit.fit_inertia(TS, inertia0=J_START, omega=omega_noisy, **SIM)
print(res.report())
J_fit, J_std = res.values["inertia"], res.std["inertia"]
idx = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
names = ["J11", "J22", "J33", "J12 (= -J[0,1])", "J13 (= -J[0,2])", "J23 (= -J[1,2])"]
sign = [1, 1, 1, -1, -1, -1]  # products of inertia are minus the off-diagonal entries
print(f"\n{'entry':16} {'true (scaled)':>14} {'fitted':>10} {'1 sigma':>9} {'z':>6}")
z = []
for (i, j), nm, s in zip(idx, names, sign, strict=True):
    z.append(s * (J_fit[i, j] - J_ref[i, j]) / J_std[i, j])
    print(
        f"{nm:16} {s * J_ref[i, j]:14.5f} {s * J_fit[i, j]:10.5f} {J_std[i, j]:9.1e} {z[-1]:6.2f}"
    )
sigma_hat = np.sqrt(res.sigma2)
print(f"noise estimated from the residuals: {sigma_hat:.2e} rad/s (true {SIGMA:.0e})")
assert res.converged
assert np.all(np.abs(z) < 4)  # the truth lies inside the reported uncertainty
assert abs(sigma_hat / SIGMA - 1) < 0.2

# %%
fig, ax = plt.subplots(figsize=(8, 3.8))
x = np.arange(6)
ax.errorbar(
    x,
    [s * (J_fit[i, j] - J_ref[i, j]) for (i, j), s in zip(idx, sign, strict=True)],
    yerr=[2 * J_std[i, j] for i, j in idx],
    fmt="o",
    capsize=4,
    label="fitted - true, +- 2 sigma",
)
ax.axhline(0.0, color="k", lw=0.8)
ax.set_xticks(x, [n.split()[0] for n in names])
ax.set_ylabel("kg m^2")
ax.set_title("Inertia entries from noisy gyro data: error and reported uncertainty")
ax.legend()
plt.show()

# %% [markdown]
# ## 4. Data, fitted model and residuals
# The residuals (model - data) should look like the white noise that was added: no trend, no
# oscillation left over, spread sigma.

# %%
model = observe(J_fit, res.values["omega0"])  # the fitted model at the sample times
r = res.residuals.reshape(TS.size, 3)  # omega residuals, (T, 3), rad/s (omega_noise = 1)

fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(14, 4), gridspec_kw=dict(width_ratios=[2, 2, 1]))
for k in range(3):
    (line,) = ax1.plot(TS, model[:, k], label=f"omega_{k + 1} fitted model")
    ax1.plot(TS, omega_noisy[:, k], ".", color=line.get_color(), ms=4)
    ax2.plot(TS, r[:, k] * 1e3, ".-", lw=0.5, color=line.get_color(), label=f"omega_{k + 1}")
ax1.set_xlabel("t (s)")
ax1.set_ylabel("rad/s")
ax1.set_title("gyro data (dots) and fitted model")
ax1.legend(fontsize="small")
ax2.axhspan(-1e3 * SIGMA, 1e3 * SIGMA, color="gray", alpha=0.2, label="+- sigma")
ax2.set_xlabel("t (s)")
ax2.set_ylabel("residual (mrad/s)")
ax2.set_title("residuals")
ax2.legend(fontsize="small", ncol=2)
u = np.linspace(-4, 4, 200)
ax3.hist(r.ravel() / SIGMA, bins=20, density=True, alpha=0.6)
ax3.plot(u, np.exp(-(u**2) / 2) / np.sqrt(2 * np.pi), "k")
ax3.set_xlabel("residual / sigma")
ax3.set_title("vs N(0, 1)")
plt.tight_layout()
plt.show()
