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
# # 03 — Orientation: the 12 Euler sequences, gimbal lock, and why the state is a quaternion
#
# A sequence "abc" (1, 2, 3 = body axes xi, eta, zeta) with angles (phi1, phi2, phi3) means three
# successive rotations about the body-embedded (moving) axes (docs/theory.md, section 2 "Orientation"):
#
# R = R_a(phi1) R_b(phi2) R_c(phi3),  r_world = R r_body,
#
# with R_1(a) = [[1,0,0],[0,c,-s],[0,s,c]], R_2(a) = [[c,0,s],[0,1,0],[-s,0,c]],
# R_3(a) = [[c,-s,0],[s,c,0],[0,0,1]]. Six sequences are *proper* (a = c: 121 131 212 232 313 323;
# classical Euler angles psi, theta, phi are "313") and six are *Tait–Bryan* (123 132 213 231 312
# 321; "321" is yaw–pitch–roll).
#
# Every sequence has a **gimbal lock**: proper sequences at phi2 in {0, pi}, Tait–Bryan sequences at
# phi2 = +-pi/2. There the first and third axes coincide, only phi1 + phi3 or phi1 - phi3 is
# determined by R, and the angle rates needed for a given angular velocity are infinite.
# Euler parameters (unit quaternions, e0 = cos(phi/2), e = v sin(phi/2)) have no such point, which
# is why a jaxrb `State` carries a quaternion.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import diffrax as dfx
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb

SEQS = jaxrb.EULER_SEQUENCES
print(SEQS)

# %% [markdown]
# ## 1. The singular condition of each sequence, and round trips at and near it
# For each sequence we find (numerically, from `euler_to_matrix`) which combination of phi1 and phi3
# survives at the lock, and check three round trips against the exact matrices:
#
# - regular attitudes: angles -> R -> angles -> R (and the angles themselves come back);
# - exactly at the lock: `matrix_to_euler` returns phi3 = 0 and puts the determined combination into
#   phi1, so the angles still reproduce R; `is_euler_singular` says True;
# - 1e-9 rad from the lock: the angles reproduce R to round-off, `is_euler_singular(R, seq,
#   tol=1e-10)` is False, and `euler_singularity_distance` returns 1e-9 to a relative error of
#   ~eps / 1e-9 ~ 1e-7, which is the rounding of the input R itself.

# %%
key = jax.random.key(0)
k1, k2 = jax.random.split(key)
n = 200
a13 = jax.random.uniform(k1, (n, 2), minval=-3.0, maxval=3.0)  # phi1, phi3 well inside (-pi, pi]
u = jax.random.uniform(k2, (n,), minval=0.05, maxval=0.95)


def r_err(A, B):
    return float(jnp.max(jnp.abs(A - B)))


rows, worst = [], 0.0
for seq in SEQS:
    proper = seq[0] == seq[2]
    lo, hi = (0.0, jnp.pi) if proper else (-jnp.pi / 2, jnp.pi / 2)
    phi2 = lo + u * (hi - lo)  # regular middle angles
    angles = jnp.stack([a13[:, 0], phi2, a13[:, 1]], -1)
    R = jaxrb.euler_to_matrix(angles, seq)
    back = jaxrb.matrix_to_euler(R, seq)
    e_reg = max(r_err(back, angles), r_err(jaxrb.euler_to_matrix(back, seq), R))
    e_quat = r_err(jaxrb.quat_to_matrix(jaxrb.euler_to_quat(angles, seq)), R)

    # at the lock (upper singular value: phi2 = pi, resp. +pi/2)
    s = jnp.pi if proper else jnp.pi / 2
    locked = angles.at[:, 1].set(s)
    R_lock = jaxrb.euler_to_matrix(locked, seq)
    b_lock = jaxrb.matrix_to_euler(R_lock, seq)
    e_lock = r_err(jaxrb.euler_to_matrix(b_lock, seq), R_lock)
    assert bool(jnp.all(jaxrb.is_euler_singular(R_lock, seq))) and r_err(b_lock[:, 2], 0.0) == 0.0
    # which combination survives: R(phi1, s, phi3) == R(phi1 + sign * phi3, s, 0)
    p1, p3 = 0.3, 0.5
    R_test = jaxrb.euler_to_matrix(jnp.array([p1, s, p3]), seq)
    sign = (
        +1
        if r_err(jaxrb.euler_to_matrix(jnp.array([p1 + p3, s, 0.0]), seq), R_test) < 1e-12
        else -1
    )
    assert r_err(jaxrb.euler_to_matrix(jnp.array([p1 + sign * p3, s, 0.0]), seq), R_test) < 1e-12

    # 1e-9 rad from the lock
    d = 1e-9
    near = angles.at[:, 1].set(s - d)
    R_near = jaxrb.euler_to_matrix(near, seq)
    e_near = r_err(jaxrb.euler_to_matrix(jaxrb.matrix_to_euler(R_near, seq), seq), R_near)
    e_dist = float(jnp.max(jnp.abs(jaxrb.euler_singularity_distance(R_near, seq) / d - 1)))
    assert e_dist < 1e-6
    assert not bool(jnp.any(jaxrb.is_euler_singular(R_near, seq, tol=1e-10)))

    worst = max(worst, e_reg, e_quat, e_lock, e_near)
    cond = "phi2 = 0 or pi" if proper else "phi2 = +-pi/2"
    comb = f"phi1 {'+' if sign > 0 else '-'} phi3 (at phi2 = {'pi' if proper else '+pi/2'})"
    rows.append(
        (seq, "proper" if proper else "Tait-Bryan", cond, comb, e_reg, e_lock, e_near, e_dist)
    )

print(
    f"{'seq':4} {'kind':10} {'singular where':15} {'determined at the lock':28} "
    f"{'round trip':>10} {'at lock':>9} {'1e-9 off':>9} {'distance/1e-9 - 1':>19}"
)
for r in rows:
    print(
        f"{r[0]:4} {r[1]:10} {r[2]:15} {r[3]:28} {r[4]:10.1e} {r[5]:9.1e} {r[6]:9.1e} {r[7]:19.1e}"
    )
print(f"worst matrix / angle error over all sequences: {worst:.1e}")
assert worst < 1e-13


# %% [markdown]
# ## 2. Why the half-angle method matters near the lock
# The textbook "321" extraction reads phi2 = asin(-R31), phi1 = atan2(R21, R11),
# phi3 = atan2(R32, R33). Near phi2 = pi/2 the arcsine has infinite slope: a rounding error eps in
# R31 becomes an angle error ~ eps / d at distance d from the lock, and the reconstructed R is off
# by as much. jaxrb reads the angles off the quaternion with half-angle atan2 forms
# (Bernardes & Viollet 2022), which stay at round-off arbitrarily close to the lock. (Within
# 64 ulps of the lock jaxrb snaps to phi3 = 0, which moves R by about twice that distance, ~1e-14.)


# %%
def textbook_321(R):
    phi2 = jnp.arcsin(jnp.clip(-R[..., 2, 0], -1.0, 1.0))
    phi1 = jnp.arctan2(R[..., 1, 0], R[..., 0, 0])
    phi3 = jnp.arctan2(R[..., 2, 1], R[..., 2, 2])
    return jnp.stack([phi1, phi2, phi3], -1)


dists = jnp.logspace(-15, 0, 61)
ang = jnp.stack([jnp.full_like(dists, 0.7), jnp.pi / 2 - dists, jnp.full_like(dists, -1.1)], -1)
R = jaxrb.euler_to_matrix(ang, "321")
err_tb = jnp.max(jnp.abs(jaxrb.euler_to_matrix(textbook_321(R), "321") - R), axis=(-2, -1))
err_jx = jnp.max(
    jnp.abs(jaxrb.euler_to_matrix(jaxrb.matrix_to_euler(R, "321"), "321") - R), axis=(-2, -1)
)
print(
    f"max reconstruction error: textbook {float(err_tb.max()):.1e}, jaxrb {float(err_jx.max()):.1e}"
)
assert float(err_jx.max()) < 3e-14 and float(err_tb.max()) > 1e-9

fig, ax = plt.subplots(figsize=(7, 4))
ax.loglog(dists, jnp.maximum(err_tb, 1e-18), "o-", ms=3, label="textbook asin / atan2")
ax.loglog(dists, jnp.maximum(err_jx, 1e-18), "s-", ms=3, label="jaxrb.matrix_to_euler")
ax.set_xlabel("distance of phi2 from the lock pi/2 (rad)")
ax.set_ylabel("max |R(angles(R)) - R|")
ax.set_title('"321" round trip near gimbal lock (zeros drawn at 1e-18)')
ax.grid(alpha=0.3, which="both")
ax.legend()
plt.show()


# %% [markdown]
# ## 3. Integrating attitude through gimbal lock: Euler-angle rates vs quaternions
# A spherical body (no torque) spins with constant body angular velocity omega, so the exact attitude
# is q(t) = q0 (x) exp(omega t / 2), with exp(omega t/2) = (cos(|omega| t/2), sin(|omega| t/2) omega/|omega|).
# We choose q0 so that at t* = 2 s the body passes at distance delta from the "321" lock
# (phi2 = pi/2 - delta).
#
# **(a) Euler angles.** For "321", R = R_3(phi1) R_2(phi2) R_1(phi3) and omega = R^T R_dot gives
# w1 = phi3' - phi1' sin(phi2), w2 = phi1' cos(phi2) sin(phi3) + phi2' cos(phi3),
# w3 = phi1' cos(phi2) cos(phi3) - phi2' sin(phi3); solved for the rates:
#
# - phi1' = (w2 sin(phi3) + w3 cos(phi3)) / cos(phi2)
# - phi2' = w2 cos(phi3) - w3 sin(phi3)
# - phi3' = w1 + phi1' sin(phi2)
#
# phi1' and phi3' grow like |omega| / delta near the lock.
#
# **(b) Quaternions.** q' = 1/2 q (x) (0, omega) (`jaxrb.quat_rate`): linear in q, bounded, no lock.
#
# Both are integrated with the *same* integrator: Tsit5 with a fixed step of 0.01 s (what a
# real-time loop would do), and the error is the geodesic angle to the exact attitude.


# %%
def euler321_rates(angles, w):
    """Euler-angle rates of the "321" sequence for body angular velocity w (singular at phi2 = +-pi/2)."""
    phi2, phi3 = angles[..., 1], angles[..., 2]
    s3, c3 = jnp.sin(phi3), jnp.cos(phi3)
    d1 = (w[..., 1] * s3 + w[..., 2] * c3) / jnp.cos(phi2)
    d2 = w[..., 1] * c3 - w[..., 2] * s3
    d3 = w[..., 0] + d1 * jnp.sin(phi2)
    return jnp.stack([d1, d2, d3], -1)


omega = jnp.array([0.3, 1.0, 0.5])  # rad/s, body frame
t_star, T, dt = 2.0, 4.0, 0.01
ts = jnp.linspace(0.0, T, 801)


def exp_half(t):  # exp(omega t / 2) as a unit quaternion
    return jaxrb.axis_angle_to_quat(omega, jnp.linalg.norm(omega) * t)


def start_for(delta):
    """q0 such that the attitude at t* is (0.4, pi/2 - delta, -0.2) in "321"."""
    q_pass = jaxrb.euler_to_quat(jnp.array([0.4, jnp.pi / 2 - delta, -0.2]), "321")
    return jaxrb.quat_multiply(q_pass, jaxrb.quat_conjugate(exp_half(t_star)))


@jax.jit
def both(q0):
    exact = jaxrb.quat_multiply(q0, jax.vmap(exp_half)(ts))
    kw = dict(
        saveat=dfx.SaveAt(ts=ts),
        stepsize_controller=dfx.ConstantStepSize(),
        max_steps=1000,
        throw=False,
    )
    eul = dfx.diffeqsolve(
        dfx.ODETerm(lambda t, y, _: euler321_rates(y, omega)),
        dfx.Tsit5(),
        0.0,
        T,
        dt,
        jaxrb.quat_to_euler(q0, "321"),
        **kw,
    )
    qua = dfx.diffeqsolve(
        dfx.ODETerm(lambda t, q, _: jaxrb.quat_rate(q, omega)), dfx.Tsit5(), 0.0, T, dt, q0, **kw
    )
    err_euler = jaxrb.quat_geodesic_angle(jaxrb.euler_to_quat(eul.ys, "321"), exact)
    err_quat = jaxrb.quat_geodesic_angle(qua.ys, exact)
    rates = jnp.linalg.norm(euler321_rates(jaxrb.quat_to_euler(exact, "321"), omega), axis=-1)
    return err_euler, err_quat, rates


deltas = [1e-1, 1e-2, 1e-4, 0.0]
results = {d: both(start_for(d)) for d in deltas}
before = ts < t_star - 0.1
for d, (ee, eq, rates) in results.items():
    print(
        f"delta = {d:7.0e}: Euler error before {float(ee[before].max()):.1e}, after {float(ee[-1]):.1e} rad;"
        f" quaternion max error {float(eq.max()):.1e} rad; max |Euler rates| on the exact path {float(rates.max()):.1e} rad/s"
    )
    assert float(eq.max()) < 1e-12  # quaternions: round-off, whatever delta
    assert float(ee[before].max()) < 1e-9  # Euler angles are fine away from the lock ...
    if d <= 1e-2:
        assert float(ee[-1]) > 1e-3  # ... and are ruined by passing within 0.01 rad of it

# %%
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
running_max = lambda e: np.maximum.accumulate(np.maximum(np.asarray(e), 1e-17))  # noqa: E731
for d, (ee, _eq, rates) in results.items():
    (line,) = ax1.semilogy(ts, running_max(ee), label=f"Euler 321 rates, delta = {d:.0e}")
    ax2.semilogy(ts, rates, color=line.get_color(), label=f"delta = {d:.0e}")
ax1.semilogy(ts, running_max(results[0.0][1]), "k", lw=2, label="quaternion (any delta)")
ax1.axvline(t_star, color="gray", ls=":")
ax1.set_xlabel("t (s)")
ax1.set_ylabel("max attitude error so far (rad, geodesic)")
ax1.set_title("same integrator (Tsit5, dt = 0.01 s)")
ax1.legend(fontsize="small", loc="upper left")
ax2.axvline(t_star, color="gray", ls=":")
ax2.set_xlabel("t (s)")
ax2.set_ylabel("|(phi1', phi2', phi3')| (rad/s)")
ax2.set_xlim(1.5, 2.5)
ax2.set_title("Euler-angle rates along the exact motion (zoom)")
ax2.legend(fontsize="small")
plt.show()

# %% [markdown]
# The Euler-angle rates peak at about |omega| / delta: no fixed step resolves a passage closer than
# ~ |omega| dt, and exactly at the lock they are infinite. An adaptive integrator survives by taking
# ever smaller steps there. The quaternion equation is linear with a bounded coefficient, so its
# error is set by the integrator alone.
#
# Finally, `jaxrb.simulate` of the torque-free spherical body (quaternion attitude; with no
# force on it, only the rotation is integrated) through the exact lock, with Tsit5 as above (at
# this tolerance `simulate` would pick Dopri8 by default, whose error at equal tolerance is
# larger here: 2.3e-10 rad):

# %%
q0 = start_for(0.0)
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([0.5, 0.5, 0.5])))
state0 = jaxrb.make_state(quat=q0, omega=omega)
traj = jaxrb.simulate(scene, state0, ts, solver=dfx.Tsit5(), rtol=1e-12, atol=1e-12)
exact = jaxrb.quat_multiply(q0, jax.vmap(exp_half)(ts))
err = float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, exact)))
lock = jaxrb.euler_singularity_distance(jaxrb.quat_to_matrix(traj.states.quat), "321")
print(
    f"jaxrb.simulate: max attitude error {err:.1e} rad; closest approach to the 321 lock {float(lock.min()):.1e} rad"
)
assert err < 1e-10
