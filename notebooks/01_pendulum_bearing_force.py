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
# # 01 — The fixed-axis pendulum: bearing force, exact vs simulated
#
# The classical sample problem (docs/theory.md, section 6): a body of mass m = 7.5 kg turns about a fixed horizontal
# axis through O; its mass centre C is r = 0.25 m from O and its radius of gyration about the axis
# is k_O = 0.295 m. It is released from rest with OC horizontal (theta = 0, theta measured downward).
#
# - alpha = g r cos(theta) / k_O^2, w^2 = 2 g r sin(theta) / k_O^2
# - On = m g (1 + 2 r^2/k_O^2) sin(theta) (along the pendulum, towards O)
# - Ot = m g (1 - r^2/k_O^2) cos(theta), |O| = sqrt(On^2 + Ot^2)
#
# We simulate the same body with a `Hinge` joint (integrated in its one angle) and read the bearing
# force with `jaxrb.joint_reaction`.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb
from jaxrb.analytic import SAMPLE_PENDULUM, pendulum_bearing_force, pendulum_period

# %% [markdown]
# ## The scene
# Body axes: x from O towards C, y along the hinge axis. O is the body point (-r, 0, 0); the body
# starts at the identity attitude with C at (r, 0, 0), level with O at the world origin. A positive
# rotation about +y carries x towards -z, so theta is the hinge angle. The inertia about C is
# m (k_O^2 - r^2) (a spherical body keeps it simple; only the axis moment matters).

# %%
p = SAMPLE_PENDULUM
m, r, k_O, g = p.mass, p.r, p.k_O, p.g
J_C = m * (k_O**2 - r**2)
body = jaxrb.RigidBody(m, jnp.array([J_C, J_C, J_C]))
hinge = jaxrb.Hinge(point=(-r, 0.0, 0.0), axis=(0.0, 1.0, 0.0))
scene = jaxrb.Scene(body, forces=(jaxrb.Gravity((0.0, 0.0, -g)),), joint=hinge)
state0 = jaxrb.make_state(pos=(r, 0.0, 0.0))  # released from rest, O at the origin

half_period = float(pendulum_period(r, k_O, g)) / 2  # theta runs 0 -> 180 deg in half a period
ts = jnp.linspace(0.0, half_period, 181)
traj = jaxrb.simulate(scene, state0, ts, rtol=1e-11, atol=1e-11)
print(f"half period {half_period:.4f} s, {int(traj.num_steps)} solver steps")

# %%
# theta from the position of C relative to O; the bearing force from the joint
d = traj.states.pos  # O -> C (O is the origin), world frame
theta = jnp.unwrap(jnp.arctan2(-d[:, 2], d[:, 0]))
force = jax.vmap(lambda t, s: jaxrb.joint_reaction(scene, t, s))(traj.ts, traj.states)
e_n = -d / r  # from C towards O
e_t = jnp.stack(
    [-jnp.sin(theta), jnp.zeros_like(theta), -jnp.cos(theta)], axis=-1
)  # increasing theta
On_sim = jnp.sum(force * e_n, axis=-1)
Ot_sim = -jnp.sum(force * e_t, axis=-1)  # positive opposite to increasing theta
mag_sim = jnp.linalg.norm(force, axis=-1)

On, Ot, mag = pendulum_bearing_force(theta, m, r, k_O, g)
err = max(float(jnp.max(jnp.abs(a - b))) for a, b in ((On_sim, On), (Ot_sim, Ot), (mag_sim, mag)))
print(f"theta at the end: {np.degrees(float(theta[-1])):.6f} deg")
print(f"max |simulated - exact| bearing force: {err:.2e} N  (m g = {m * g:.2f} N)")
assert abs(np.degrees(float(theta[-1])) - 180.0) < 1e-5
assert err < 1e-7 * m * g

# %%
deg = np.degrees(np.asarray(theta))
fig, ax = plt.subplots(figsize=(8, 5))
for exact, sim, name in ((mag, mag_sim, "|O|"), (On, On_sim, "On"), (Ot, Ot_sim, "Ot")):
    (line,) = ax.plot(deg, exact, label=f"{name} exact")
    ax.plot(
        deg[::10],
        np.asarray(sim)[::10],
        "o",
        color=line.get_color(),
        ms=5,
        mfc="none",
        label=f"{name} simulated (Hinge)",
    )
ax.set_xlabel("theta (deg)")
ax.set_ylabel("bearing force (N)")
ax.set_xticks(range(0, 181, 30))
ax.set_title("Fixed-axis pendulum: bearing force at O")
ax.grid(alpha=0.3)
ax.legend(ncol=3, fontsize="small")
plt.show()

# %% [markdown]
# The maximum of |O| is at the bottom (theta = 90 deg): On = m g (1 + 2 r^2/k_O^2) and Ot = 0.
# Ot changes sign at 90 deg: the bearing holds the falling body back, then pulls it on.
