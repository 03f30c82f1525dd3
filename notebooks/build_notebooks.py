"""Build the example notebooks notebooks/0*.ipynb from the cell lists below.

Run `python notebooks/build_notebooks.py` (writes next to this file) or
`python notebooks/build_notebooks.py OUT_DIR`. Notebooks are stored without outputs;
`tests/test_notebooks.py` executes them. Cell ids are derived from the notebook name and cell
index, so rebuilding gives byte-identical files.
"""

import sys
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

# ruff: noqa: E501

SETUP = """import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxrb"""

NB01 = [
    (
        "md",
        """# 01 — The fixed-axis pendulum: bearing force, exact vs simulated

The classical sample problem (docs/theory.md, section 6): a body of mass m = 7.5 kg turns about a fixed horizontal
axis through O; its mass centre C is r = 0.25 m from O and its radius of gyration about the axis
is k_O = 0.295 m. It is released from rest with OC horizontal (theta = 0, theta measured downward).

- alpha = g r cos(theta) / k_O^2, w^2 = 2 g r sin(theta) / k_O^2
- On = m g (1 + 2 r^2/k_O^2) sin(theta) (along the pendulum, towards O)
- Ot = m g (1 - r^2/k_O^2) cos(theta), |O| = sqrt(On^2 + Ot^2)

We simulate the same body with a `Hinge` joint (integrated in its one angle) and read the bearing
force with `jaxrb.joint_reaction`.""",
    ),
    (
        "code",
        SETUP
        + """
from jaxrb.analytic import SAMPLE_PENDULUM, pendulum_bearing_force, pendulum_period""",
    ),
    (
        "md",
        """## The scene
Body axes: x from O towards C, y along the hinge axis. O is the body point (-r, 0, 0); the body
starts at the identity attitude with C at (r, 0, 0), level with O at the world origin. A positive
rotation about +y carries x towards -z, so theta is the hinge angle. The inertia about C is
m (k_O^2 - r^2) (a spherical body keeps it simple; only the axis moment matters).""",
    ),
    (
        "code",
        """p = SAMPLE_PENDULUM
m, r, k_O, g = p.mass, p.r, p.k_O, p.g
J_C = m * (k_O**2 - r**2)
body = jaxrb.RigidBody(m, jnp.array([J_C, J_C, J_C]))
hinge = jaxrb.Hinge(point=(-r, 0.0, 0.0), axis=(0.0, 1.0, 0.0))
scene = jaxrb.Scene(body, forces=(jaxrb.Gravity((0.0, 0.0, -g)),), joint=hinge)
state0 = jaxrb.make_state(pos=(r, 0.0, 0.0))  # released from rest, O at the origin

half_period = float(pendulum_period(r, k_O, g)) / 2  # theta runs 0 -> 180 deg in half a period
ts = jnp.linspace(0.0, half_period, 181)
traj = jaxrb.simulate(scene, state0, ts, rtol=1e-11, atol=1e-11)
print(f"half period {half_period:.4f} s, {int(traj.num_steps)} solver steps")""",
    ),
    (
        "code",
        """# theta from the position of C relative to O; the bearing force from the joint
d = traj.states.pos  # O -> C (O is the origin), world frame
theta = jnp.unwrap(jnp.arctan2(-d[:, 2], d[:, 0]))
force = jax.vmap(lambda t, s: jaxrb.joint_reaction(scene, t, s))(traj.ts, traj.states)
e_n = -d / r  # from C towards O
e_t = jnp.stack([-jnp.sin(theta), jnp.zeros_like(theta), -jnp.cos(theta)], axis=-1)  # increasing theta
On_sim = jnp.sum(force * e_n, axis=-1)
Ot_sim = -jnp.sum(force * e_t, axis=-1)  # positive opposite to increasing theta
mag_sim = jnp.linalg.norm(force, axis=-1)

On, Ot, mag = pendulum_bearing_force(theta, m, r, k_O, g)
err = max(float(jnp.max(jnp.abs(a - b))) for a, b in ((On_sim, On), (Ot_sim, Ot), (mag_sim, mag)))
print(f"theta at the end: {np.degrees(float(theta[-1])):.6f} deg")
print(f"max |simulated - exact| bearing force: {err:.2e} N  (m g = {m * g:.2f} N)")
assert abs(np.degrees(float(theta[-1])) - 180.0) < 1e-5
assert err < 1e-7 * m * g""",
    ),
    (
        "code",
        """deg = np.degrees(np.asarray(theta))
fig, ax = plt.subplots(figsize=(8, 5))
for exact, sim, name in ((mag, mag_sim, "|O|"), (On, On_sim, "On"), (Ot, Ot_sim, "Ot")):
    (line,) = ax.plot(deg, exact, label=f"{name} exact")
    ax.plot(deg[::10], np.asarray(sim)[::10], "o", color=line.get_color(), ms=5, mfc="none",
            label=f"{name} simulated (Hinge)")
ax.set_xlabel("theta (deg)")
ax.set_ylabel("bearing force (N)")
ax.set_xticks(range(0, 181, 30))
ax.set_title("Fixed-axis pendulum: bearing force at O")
ax.grid(alpha=0.3)
ax.legend(ncol=3, fontsize="small")
plt.show()""",
    ),
    (
        "md",
        """The maximum of |O| is at the bottom (theta = 90 deg): On = m g (1 + 2 r^2/k_O^2) and Ot = 0.
Ot changes sign at 90 deg: the bearing holds the falling body back, then pulls it on.""",
    ),
]

NB02 = [
    (
        "md",
        """# 02 — Torque-free precession

With no moment about the mass centre, the angular momentum K is constant in the world, and the
body's angular velocity moves according to Euler's equations. We compare `jaxrb.simulate` with the
exact solutions in `jaxrb.analytic`:

1. the symmetric top (omega and K, the angles gamma, alpha, beta);
2. the spherical top (no precession);
3. the asymmetric top: polhodes and a herpolhode;
4. the Dzhanibekov flip about the intermediate axis.""",
    ),
    (
        "code",
        SETUP
        + """
import jaxrb.plotting
from jaxrb.analytic import asymmetric_top, flip_half_period, symmetric_top


def free(inertia):
    return jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.asarray(inertia)))""",
    ),
    (
        "md",
        """## 1. Symmetric top
J1 = J2 = 1, J3 = 2 (oblate), omega0 = (0.4, 0, 1.0) in body axes. The body omega precesses about
the symmetry axis at lambda = (J1 - J3) w3 / J1; in the world, the symmetry axis and omega both
turn about the fixed K. gamma = angle(axis, K), alpha = angle(axis, omega), beta = alpha - gamma.""",
    ),
    (
        "code",
        """J1, J3 = 1.0, 2.0
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
angle = lambda a, b: jnp.degrees(jnp.arccos(jnp.sum(a * b, -1) / jnp.linalg.norm(a, axis=-1) / jnp.linalg.norm(b, axis=-1)))
w_tau = float(jnp.hypot(omega0[0], omega0[1]))
Kn = float(jnp.sqrt(J1**2 * w_tau**2 + J3**2 * omega0[2] ** 2))
wn = float(jnp.linalg.norm(omega0))
gamma = np.degrees(np.arccos(J3 * float(omega0[2]) / Kn))
alpha = np.degrees(np.arccos(float(omega0[2]) / wn))
print(f"K drift {float(jnp.max(jnp.abs(K - K[0]))):.1e}; lambda = {(J1 - J3) * float(omega0[2]) / J1:+.3f} rad/s")
print(f"gamma: formula {gamma:.6f} deg, simulated {float(angle(axis, K).mean()):.6f} deg")
print(f"alpha: formula {alpha:.6f} deg, simulated {float(angle(axis, w_world).mean()):.6f} deg")
print(f"beta = alpha - gamma = {alpha - gamma:.6f} deg, simulated {float(angle(w_world, K).mean()):.6f} deg")
assert np.allclose(angle(axis, K), gamma, atol=1e-6) and np.allclose(angle(axis, w_world), alpha, atol=1e-6)
assert np.allclose(angle(w_world, K), abs(alpha - gamma), atol=1e-6)""",
    ),
    (
        "code",
        """fig = plt.figure(figsize=(11, 4.5))
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
plt.show()""",
    ),
    (
        "md",
        "## 2. Spherical top\nJ = 1.5 * identity: omega is constant in the body and in the world.",
    ),
    (
        "code",
        """scene = free([1.5, 1.5, 1.5])
omega0 = jnp.array([0.3, -0.7, 1.1])
traj = jaxrb.simulate(scene, jaxrb.make_state(omega=omega0), jnp.linspace(0.0, 10.0, 401), rtol=1e-10, atol=1e-10)
w_world = jaxrb.quat_rotate(traj.states.quat, traj.states.omega)
print("body drift", float(jnp.max(jnp.abs(traj.states.omega - omega0))),
      "world drift", float(jnp.max(jnp.abs(w_world - omega0))))
assert jnp.allclose(traj.states.omega, omega0, atol=1e-10) and jnp.allclose(w_world, omega0, atol=1e-6)""",
    ),
    (
        "md",
        """## 3. Asymmetric top: polhodes and herpolhode
I = (1, 2, 3). Polhodes are the curves omega(t) (body frame) on the energy ellipsoid: closed
loops about the axes of least and greatest inertia, separated by the separatrix through the
intermediate axis. The exact elliptic-function solution draws them cheaply; the herpolhode (omega in
the world, on the invariable plane perpendicular to K) needs the attitude, so we simulate one.""",
    ),
    (
        "code",
        """inertia = jnp.array([1.0, 2.0, 3.0])
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
traj = jaxrb.simulate(scene, jaxrb.make_state(omega=w0), jnp.linspace(0.0, 60.0, 401), rtol=1e-10, atol=1e-10)
err = float(jnp.max(jnp.abs(traj.states.omega - asymmetric_top(traj.ts, inertia, w0))))
print(f"max |omega_sim - omega_exact| = {err:.1e} rad/s")
assert err < 1e-7
jaxrb.plotting.plot_polhode_herpolhode(traj, scene)
plt.show()""",
    ),
    (
        "md",
        """## 4. The Dzhanibekov flip
Spin about the intermediate axis is unstable: a tiny perturbation makes omega_2 flip sign
periodically. The exact half-period between flips is 2 K(m) / |omega_p| (`flip_half_period`).""",
    ),
    (
        "code",
        """omega0 = jnp.array([1e-3, 2.0, 1e-3])
half = float(flip_half_period(inertia, omega0))
ts = jnp.linspace(0.0, 2.2 * half, 401)
traj = jaxrb.simulate(free(inertia), jaxrb.make_state(omega=omega0), ts, rtol=1e-10, atol=1e-10)
w2 = np.asarray(traj.states.omega[:, 1])
crossings = np.asarray(ts)[1:][np.sign(w2[1:]) != np.sign(w2[:-1])]
print(f"exact flip half-period {half:.4f} s; simulated sign changes of omega_2 at {np.round(crossings, 3)} s")
assert len(crossings) >= 2 and abs((crossings[1] - crossings[0]) - half) < 2 * float(ts[1] - ts[0])
fig, ax = plt.subplots(figsize=(8, 4))
for k in range(3):
    ax.plot(ts, traj.states.omega[:, k], label=f"omega_{k + 1}")
ax.plot(ts[::12], asymmetric_top(ts, inertia, omega0)[::12, 1], "k.", label="omega_2 exact")
ax.set_xlabel("t (s)")
ax.set_ylabel("body angular velocity (rad/s)")
ax.set_title(f"Dzhanibekov flip, I = (1, 2, 3): half-period {half:.2f} s")
ax.legend(fontsize="small")
plt.show()""",
    ),
]


NB03 = [
    (
        "md",
        """# 03 — Orientation: the 12 Euler sequences, gimbal lock, and why the state is a quaternion

A sequence "abc" (1, 2, 3 = body axes xi, eta, zeta) with angles (phi1, phi2, phi3) means three
successive rotations about the body-embedded (moving) axes (docs/theory.md, section 2 "Orientation"):

R = R_a(phi1) R_b(phi2) R_c(phi3),  r_world = R r_body,

with R_1(a) = [[1,0,0],[0,c,-s],[0,s,c]], R_2(a) = [[c,0,s],[0,1,0],[-s,0,c]],
R_3(a) = [[c,-s,0],[s,c,0],[0,0,1]]. Six sequences are *proper* (a = c: 121 131 212 232 313 323;
classical Euler angles psi, theta, phi are "313") and six are *Tait–Bryan* (123 132 213 231 312
321; "321" is yaw–pitch–roll).

Every sequence has a **gimbal lock**: proper sequences at phi2 in {0, pi}, Tait–Bryan sequences at
phi2 = +-pi/2. There the first and third axes coincide, only phi1 + phi3 or phi1 - phi3 is
determined by R, and the angle rates needed for a given angular velocity are infinite.
Euler parameters (unit quaternions, e0 = cos(phi/2), e = v sin(phi/2)) have no such point, which
is why a jaxrb `State` carries a quaternion.""",
    ),
    (
        "code",
        SETUP
        + """
import diffrax as dfx

SEQS = jaxrb.EULER_SEQUENCES
print(SEQS)""",
    ),
    (
        "md",
        """## 1. The singular condition of each sequence, and round trips at and near it
For each sequence we find (numerically, from `euler_to_matrix`) which combination of phi1 and phi3
survives at the lock, and check three round trips against the exact matrices:

- regular attitudes: angles -> R -> angles -> R (and the angles themselves come back);
- exactly at the lock: `matrix_to_euler` returns phi3 = 0 and puts the determined combination into
  phi1, so the angles still reproduce R; `is_euler_singular` says True;
- 1e-9 rad from the lock: the angles reproduce R to round-off, `is_euler_singular(R, seq,
  tol=1e-10)` is False, and `euler_singularity_distance` returns 1e-9 to a relative error of
  ~eps / 1e-9 ~ 1e-7, which is the rounding of the input R itself.""",
    ),
    (
        "code",
        """key = jax.random.key(0)
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
    sign = +1 if r_err(jaxrb.euler_to_matrix(jnp.array([p1 + p3, s, 0.0]), seq), R_test) < 1e-12 else -1
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
    rows.append((seq, "proper" if proper else "Tait-Bryan", cond, comb, e_reg, e_lock, e_near, e_dist))

print(f"{'seq':4} {'kind':10} {'singular where':15} {'determined at the lock':28} "
      f"{'round trip':>10} {'at lock':>9} {'1e-9 off':>9} {'distance/1e-9 - 1':>19}")
for r in rows:
    print(f"{r[0]:4} {r[1]:10} {r[2]:15} {r[3]:28} {r[4]:10.1e} {r[5]:9.1e} {r[6]:9.1e} {r[7]:19.1e}")
print(f"worst matrix / angle error over all sequences: {worst:.1e}")
assert worst < 1e-13""",
    ),
    (
        "md",
        """## 2. Why the half-angle method matters near the lock
The textbook "321" extraction reads phi2 = asin(-R31), phi1 = atan2(R21, R11),
phi3 = atan2(R32, R33). Near phi2 = pi/2 the arcsine has infinite slope: a rounding error eps in
R31 becomes an angle error ~ eps / d at distance d from the lock, and the reconstructed R is off
by as much. jaxrb reads the angles off the quaternion with half-angle atan2 forms
(Bernardes & Viollet 2022), which stay at round-off arbitrarily close to the lock. (Within
64 ulps of the lock jaxrb snaps to phi3 = 0, which moves R by about twice that distance, ~1e-14.)""",
    ),
    (
        "code",
        """def textbook_321(R):
    phi2 = jnp.arcsin(jnp.clip(-R[..., 2, 0], -1.0, 1.0))
    phi1 = jnp.arctan2(R[..., 1, 0], R[..., 0, 0])
    phi3 = jnp.arctan2(R[..., 2, 1], R[..., 2, 2])
    return jnp.stack([phi1, phi2, phi3], -1)


dists = jnp.logspace(-15, 0, 61)
ang = jnp.stack([jnp.full_like(dists, 0.7), jnp.pi / 2 - dists, jnp.full_like(dists, -1.1)], -1)
R = jaxrb.euler_to_matrix(ang, "321")
err_tb = jnp.max(jnp.abs(jaxrb.euler_to_matrix(textbook_321(R), "321") - R), axis=(-2, -1))
err_jx = jnp.max(jnp.abs(jaxrb.euler_to_matrix(jaxrb.matrix_to_euler(R, "321"), "321") - R), axis=(-2, -1))
print(f"max reconstruction error: textbook {float(err_tb.max()):.1e}, jaxrb {float(err_jx.max()):.1e}")
assert float(err_jx.max()) < 3e-14 and float(err_tb.max()) > 1e-9

fig, ax = plt.subplots(figsize=(7, 4))
ax.loglog(dists, jnp.maximum(err_tb, 1e-18), "o-", ms=3, label="textbook asin / atan2")
ax.loglog(dists, jnp.maximum(err_jx, 1e-18), "s-", ms=3, label="jaxrb.matrix_to_euler")
ax.set_xlabel("distance of phi2 from the lock pi/2 (rad)")
ax.set_ylabel("max |R(angles(R)) - R|")
ax.set_title('"321" round trip near gimbal lock (zeros drawn at 1e-18)')
ax.grid(alpha=0.3, which="both")
ax.legend()
plt.show()""",
    ),
    (
        "md",
        """## 3. Integrating attitude through gimbal lock: Euler-angle rates vs quaternions
A spherical body (no torque) spins with constant body angular velocity omega, so the exact attitude
is q(t) = q0 (x) exp(omega t / 2), with exp(omega t/2) = (cos(|omega| t/2), sin(|omega| t/2) omega/|omega|).
We choose q0 so that at t* = 2 s the body passes at distance delta from the "321" lock
(phi2 = pi/2 - delta).

**(a) Euler angles.** For "321", R = R_3(phi1) R_2(phi2) R_1(phi3) and omega = R^T R_dot gives
w1 = phi3' - phi1' sin(phi2), w2 = phi1' cos(phi2) sin(phi3) + phi2' cos(phi3),
w3 = phi1' cos(phi2) cos(phi3) - phi2' sin(phi3); solved for the rates:

- phi1' = (w2 sin(phi3) + w3 cos(phi3)) / cos(phi2)
- phi2' = w2 cos(phi3) - w3 sin(phi3)
- phi3' = w1 + phi1' sin(phi2)

phi1' and phi3' grow like |omega| / delta near the lock.

**(b) Quaternions.** q' = 1/2 q (x) (0, omega) (`jaxrb.quat_rate`): linear in q, bounded, no lock.

Both are integrated with the *same* integrator: Tsit5 with a fixed step of 0.01 s (what a
real-time loop would do), and the error is the geodesic angle to the exact attitude.""",
    ),
    (
        "code",
        '''def euler321_rates(angles, w):
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
    kw = dict(saveat=dfx.SaveAt(ts=ts), stepsize_controller=dfx.ConstantStepSize(), max_steps=1000, throw=False)
    eul = dfx.diffeqsolve(dfx.ODETerm(lambda t, y, _: euler321_rates(y, omega)), dfx.Tsit5(), 0.0, T, dt,
                          jaxrb.quat_to_euler(q0, "321"), **kw)
    qua = dfx.diffeqsolve(dfx.ODETerm(lambda t, q, _: jaxrb.quat_rate(q, omega)), dfx.Tsit5(), 0.0, T, dt, q0, **kw)
    err_euler = jaxrb.quat_geodesic_angle(jaxrb.euler_to_quat(eul.ys, "321"), exact)
    err_quat = jaxrb.quat_geodesic_angle(qua.ys, exact)
    rates = jnp.linalg.norm(euler321_rates(jaxrb.quat_to_euler(exact, "321"), omega), axis=-1)
    return err_euler, err_quat, rates


deltas = [1e-1, 1e-2, 1e-4, 0.0]
results = {d: both(start_for(d)) for d in deltas}
before = ts < t_star - 0.1
for d, (ee, eq, rates) in results.items():
    print(f"delta = {d:7.0e}: Euler error before {float(ee[before].max()):.1e}, after {float(ee[-1]):.1e} rad;"
          f" quaternion max error {float(eq.max()):.1e} rad; max |Euler rates| on the exact path {float(rates.max()):.1e} rad/s")
    assert float(eq.max()) < 1e-12  # quaternions: round-off, whatever delta
    assert float(ee[before].max()) < 1e-9  # Euler angles are fine away from the lock ...
    if d <= 1e-2:
        assert float(ee[-1]) > 1e-3  # ... and are ruined by passing within 0.01 rad of it''',
    ),
    (
        "code",
        """fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
running_max = lambda e: np.maximum.accumulate(np.maximum(np.asarray(e), 1e-17))  # noqa: E731
for d, (ee, eq, rates) in results.items():
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
plt.show()""",
    ),
    (
        "md",
        """The Euler-angle rates peak at about |omega| / delta: no fixed step resolves a passage closer than
~ |omega| dt, and exactly at the lock they are infinite. An adaptive integrator survives by taking
ever smaller steps there. The quaternion equation is linear with a bounded coefficient, so its
error is set by the integrator alone.

Finally, `jaxrb.simulate` of the torque-free spherical body (13 states, quaternion attitude)
through the exact lock:""",
    ),
    (
        "code",
        """q0 = start_for(0.0)
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([0.5, 0.5, 0.5])))
traj = jaxrb.simulate(scene, jaxrb.make_state(quat=q0, omega=omega), ts, rtol=1e-12, atol=1e-12)
exact = jaxrb.quat_multiply(q0, jax.vmap(exp_half)(ts))
err = float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, exact)))
lock = jaxrb.euler_singularity_distance(jaxrb.quat_to_matrix(traj.states.quat), "321")
print(f"jaxrb.simulate: max attitude error {err:.1e} rad; closest approach to the 321 lock {float(lock.min()):.1e} rad")
assert err < 1e-10""",
    ),
]
NB04 = [
    (
        "md",
        """# 04 — A die and a coin: air resistance, bounces, rolling, rocking, and the face they settle on

The default scene of `jaxrb run` (`jaxrb/scenes/default.toml`): a 16 mm plastic die thrown with
spin onto a table. In flight it obeys the Newton–Euler equations with gravity, quadratic air drag
F = -k |v| v (k = rho C_D A / 2) and an aerodynamic damping moment M = -(c_1 + c_2 |w|) w (body
frame). At the table the contact engine `jaxrb.contact` takes over (formulation: docs/contact.md):

- **impacts**: when a corner (or a rim point, or a sphere) reaches the floor, the impulses at
  *all* touching points are found together, by Newton's restitution (a point that approached
  leaves at e times its approach speed) with Coulomb friction (|j_t| <= mu j_n);
- **persistent contact**: between impacts the body may stay on the floor on one point (a
  corner, a rim point), a pair of points (an edge, a coin's side line) or a face, and each
  contact sticks (rolling, rocking, pivoting) or slides under Coulomb friction; the
  constrained Newton–Euler equations of that *mode* are integrated;
- **events**: every mode change ends a smooth segment and is located as an event: a touch, a
  lift-off, a face tipping over an edge, friction reaching its cone (slip starts), a slip
  passing zero (slip stops), a coin's face coming down (flat);
- a series of ever smaller bounces or rocks whose points leave slower than `rest_speed`
  (1 cm/s) is replaced by its limit (a *Zeno merge*, counted in `traj.contact.zeno_merges`).

**No rule lays a body flat.** A die comes to rest on a face only by the dynamics: it hops and
rocks over its corners and edges, loses energy at every impact and to friction, lands on a face,
slides and sticks. A coin, with no rolling resistance in the model, may keep rolling on its rim.

`traj.impacts` records each impact's `time`, `point`, `impulse`, `energy_lost` (J) and the
impact `count`; `traj.contact` records the contact mode at each save (`kind`: 0 flight, 1 point,
2 pair, 3 face, named by `jaxrb.contact.KIND_NAMES`; `sliding`), and each event's time, cause and
the mode after it. We look at height, energy and contact mode, the events, the face the die
settles on, what air drag changes, two tossed coins, and an animation.""",
    ),
    (
        "code",
        SETUP
        + """
import tempfile
import time
from pathlib import Path

import equinox as eqx
from IPython.display import Image, display

import jaxrb.plotting
from jaxrb._scene_file import default_scene_path, load_scene
from jaxrb.contact import KIND_NAMES
from jaxrb.contact._record import CAUSES  # what ended each segment: traj.contact.event_cause

spec = load_scene(default_scene_path())
scene, state0 = spec.scene, spec.state0
ts = jnp.linspace(0.0, 1.0, 301)  # the scene file saves to 0.6 s; 1 s also shows the die at rest
OPTS = dict(rtol=spec.options["rtol"], atol=spec.options["atol"], max_steps=spec.options["max_steps"])
print(f"{spec.title}: {spec.description}")
print(f"mass {float(scene.body.mass) * 1e3:.1f} g, half edge {float(scene.body.shape.half_extents[0]) * 1e3:.0f} mm; "
      f"restitution {float(scene.floor.restitution)}, friction {float(scene.floor.friction)}; "
      f"k = {float(scene.forces[1].coefficient):.3e} kg/m; {ts.size} saves over {float(ts[-1])} s")


def mode_name(kind, sliding):
    name = KIND_NAMES[int(kind)]
    return name if name == "flight" else f"{name}, {'sliding' if sliding else 'sticking'}"


def event_table(log, first=15):
    \"\"\"Print the first events of a ContactLog: time, cause, mode after (slot 0 is the start).\"\"\"
    times = np.asarray(log.event_time)
    used = np.flatnonzero(np.isfinite(times))
    row = lambda i: (f"{i:4d} {times[i]:10.6f}  {CAUSES[int(log.event_cause[i])]:12} "  # noqa: E731
                     f"{mode_name(log.event_kind[i], log.event_sliding[i])}")
    print(f"{'#':>4} {'t (s)':>10}  {'cause':12} mode after")
    for i in used[:first]:
        print(row(i))
    if used.size > first:
        print(f"   ... {used.size - first} more; the last:")
        print(row(used[-1]))


def plot_mode(ax, t, log):
    \"\"\"Contact mode at each save (step line) with the saves where the contact slides shaded.\"\"\"
    kind, sliding = np.asarray(log.kind), np.asarray(log.sliding)
    ax.step(t, kind, where="post", color="k", lw=1, label="contact mode")
    ax.fill_between(t, 0, kind, where=sliding, step="post", color="C1", alpha=0.5, label="sliding")
    ax.set_yticks(range(len(KIND_NAMES)), KIND_NAMES)
    ax.set_ylim(-0.2, len(KIND_NAMES) - 0.5)


t0 = time.perf_counter()
traj = jaxrb.simulate(scene, state0, ts, **OPTS)  # compiles once for this scene structure
print(f"simulate (compile + run): {time.perf_counter() - t0:.1f} s")
assert traj.result == jaxrb.RESULTS.successful
imp, log = traj.impacts, traj.contact
n = int(imp.count)
t_imp, lost = np.asarray(imp.time[:n]), np.asarray(imp.energy_lost[:n])
a = jaxrb.plotting.trajectory_arrays(traj, scene)
t, E = a["t"], a["energy"]

# at rest: the first save from which the die sticks on a face and no longer moves
kind, sliding = np.asarray(log.kind), np.asarray(log.sliding)
still = (kind == 3) & ~sliding & (np.linalg.norm(a["vel"], axis=-1) < 1e-6) & (np.linalg.norm(a["omega"], axis=-1) < 1e-4)
assert still[-1]
i_rest = len(still) - int(np.argmin(still[::-1])) if not still.all() else 0  # start of the final run of still saves
t_rest = float(t[i_rest])
ev_t = np.asarray(log.event_time)
last = int(np.flatnonzero(np.isfinite(ev_t))[-1])
print(f"{n} impacts, {int(log.events)} events, {int(log.zeno_merges)} bounce/rock series merged; "
      f"last event at t = {ev_t[last]:.4f} s ({CAUSES[int(log.event_cause[last])]} -> "
      f"{mode_name(log.event_kind[last], log.event_sliding[last])}); at rest on a face from the save at t = {t_rest:.3f} s")
print(f"energy guards {int(log.energy_guards)}, inconsistent modes {int(log.inconsistent)}, "
      f"largest energy rise at an event {float(log.max_energy_rise):.1e} J, deepest penetration at an event "
      f"{float(log.max_penetration):.1e} m, lowest corner at a save {float(a['lowest_z'].min()):.1e} m")
assert float(log.max_energy_rise) <= 1e-9 * E[0] and float(log.max_penetration) < 1e-6""",
    ),
    (
        "md",
        """## 1. Height, energy and contact mode
Energy E = m g z + m v^2 / 2 + w . J w / 2 can only fall: air drag and the damping moment take
power P_air = k |v|^3 + (c_1 + c_2 |w|) |w|^2 in flight, each impact removes `energy_lost`, and
Coulomb friction takes energy whenever a contact slides (a sticking contact, rolling or pivoting,
takes none). Before the first impact only air acts, so E(0) - E(t) must equal the integral of
P_air (computed here from the saved states). The third panel is the contact mode at each save,
shaded where the contact slides.""",
    ),
    (
        "code",
        """k = float(scene.forces[1].coefficient)
c1, c2 = float(scene.forces[2].linear), float(scene.forces[2].quadratic)


def air_power(arrays):
    v, w = np.linalg.norm(arrays["vel"], axis=-1), np.linalg.norm(arrays["omega"], axis=-1)
    return k * v**3 + (c1 + c2 * w) * w**2


P = air_power(a)
flight = t < t_imp[0]
air_flight = np.trapezoid(P[flight], t[flight])
drop_flight = E[0] - E[flight][-1]
air_total = np.trapezoid(P, t)
print(f"before the first impact: E(0) - E(t) = {drop_flight:.6e} J, integral of P_air = {air_flight:.6e} J "
      f"(relative difference {drop_flight / air_flight - 1:.1e})")
print(f"E(0) = {E[0] * 1e3:.4f} mJ, E(end) = {E[-1] * 1e3:.4f} mJ; lost at the {n} impacts "
      f"{lost.sum() * 1e3:.4f} mJ, to the air {air_total * 1e3:.4f} mJ, "
      f"to sliding friction (the rest) {(E[0] - E[-1] - lost.sum() - air_total) * 1e3:.4f} mJ")
assert np.all(np.diff(E) <= 1e-9 * E[0])  # never gains energy
assert abs(drop_flight / air_flight - 1) < 1e-3
assert np.all(lost >= 0) and lost.sum() + air_total < E[0] - E[-1] + 1e-9

fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
ax1.plot(t, a["pos"][:, 2] * 1e3, label="mass centre")
ax1.plot(t, a["lowest_z"] * 1e3, lw=1, label="lowest corner")
ax2.plot(t, E * 1e3, "k", label="total energy E")
ax2.plot(t, (E[0] - np.concatenate([[0.0], np.cumsum((P[1:] + P[:-1]) / 2 * np.diff(t))])) * 1e3, "C2--",
         lw=1, label="E(0) minus air losses only")
plot_mode(ax3, t, log)
for ax, where in ((ax1, "upper right"), (ax2, "center right"), (ax3, "center right")):
    for i, ti in enumerate(t_imp):
        ax.axvline(ti, color="C3", lw=0.6, alpha=0.4, label="impact" if i == 0 else None)
    ax.axvline(t_rest, color="k", ls=":", label="at rest on a face")
    ax.legend(fontsize="small", ncol=2, loc=where)
ax1.set_ylabel("height z (mm)")
ax2.set_ylabel("energy (mJ)")
ax3.set_ylabel("contact mode")
ax3.set_xlabel("t (s)")
plt.tight_layout()
plt.show()

fig, ax = plt.subplots(figsize=(9, 3))
ax.bar(np.arange(1, n + 1), lost * 1e3, color="C3")
ax.set_yscale("log")
ax.set_xlabel("impact number")
ax.set_ylabel("energy lost (mJ)")
plt.show()""",
    ),
    (
        "md",
        """The first impact takes most of the energy. The later ones are corner and edge hits as the die
hops and rocks: between them it pivots on a corner (point) or rolls over an edge (pair), and a
rocking series that dies out below `rest_speed` is replaced by its limit. It reaches a face
sliding, and friction stops it. The events, each with what ended the segment before it and the
mode after it:""",
    ),
    (
        "code",
        """event_table(log, first=15)
causes, counts = np.unique(np.asarray(log.event_cause)[np.isfinite(ev_t)], return_counts=True)
print("events by cause:", ", ".join(f"{CAUSES[int(c)]} {m}" for c, m in zip(causes, counts)))""",
    ),
    (
        "md",
        """## 2. Which face is up?
Row 3 of R(q) is the world vertical in body coordinates; the body axis closest to it is the one
pointing up. Faces are numbered so that opposite faces add up to 7: +x 1, +y 2, +z 3, -z 4,
-y 5, -x 6.""",
    ),
    (
        "code",
        """FACES = {(0, 1): 1, (1, 1): 2, (2, 1): 3, (2, -1): 4, (1, -1): 5, (0, -1): 6}


def face_up(quat):
    up = np.asarray(jaxrb.quat_to_matrix(quat))[2]  # world +z in body coordinates
    i = int(np.argmax(np.abs(up)))
    return FACES[(i, int(np.sign(up[i])))], float(np.degrees(np.arccos(min(1.0, abs(up[i])))))


face, tilt = face_up(traj.states.quat[-1])
half = float(scene.body.shape.half_extents[0])
z_end, v_end = float(traj.states.pos[-1, 2]), float(jnp.linalg.norm(traj.states.vel[-1]))
w_end = float(jnp.linalg.norm(traj.states.omega[-1]))
print(f"the die settles with face {face} up (tilt {tilt:.1e} deg); centre at z = {z_end * 1e3:.4f} mm "
      f"(half edge {half * 1e3:.1f} mm), |v| = {v_end:.1e} m/s, |w| = {w_end:.1e} rad/s; "
      f"final mode: {mode_name(log.kind[-1], log.sliding[-1])}")
assert tilt < 0.5 and abs(z_end - half) < 1e-5 and v_end < 1e-3 and w_end < 1e-2
assert int(log.kind[-1]) == 3 and not bool(log.sliding[-1])
fig = jaxrb.plotting.plot_height_attitude(traj, scene, title="die: height and attitude")
plt.show()""",
    ),
    (
        "md",
        """## 3. What air drag changes: the same throw without drag
Setting the drag coefficient and the damping moment to zero keeps the scene's structure (only
array values change), so the compiled simulation is reused: no second compilation. We compare
the flight and the first bounces (t <= 0.3 s, the same number of saves). Without air, energy is
conserved in flight (to the solver's tolerance); with air it falls by the integral of P_air.""",
    ),
    (
        "code",
        """air = lambda s: (s.forces[1].coefficient, s.forces[2].linear, s.forces[2].quadratic)  # noqa: E731
no_air = eqx.tree_at(air, scene, tuple(jnp.zeros_like(x) for x in air(scene)))
ts_short = jnp.linspace(0.0, 0.3, ts.size)  # same shape: same compiled function
runs = {}
for name, sc in (("with air drag", scene), ("without air drag", no_air)):
    t0 = time.perf_counter()
    tr = jaxrb.simulate(sc, state0, ts_short, **OPTS)
    assert tr.result == jaxrb.RESULTS.successful
    runs[name] = (tr, jaxrb.plotting.trajectory_arrays(tr, sc), time.perf_counter() - t0)

for name, (tr, arr, wall) in runs.items():
    first = float(tr.impacts.time[0])
    before = arr["t"] < first
    p = np.asarray(tr.impacts.point[0]) * 1e3
    print(f"{name:17}: {wall:.2f} s; first impact at t = {first:.5f} s, at x, y = ({p[0]:.2f}, {p[1]:.2f}) mm, "
          f"energy lost in flight {(arr['energy'][0] - arr['energy'][before][-1]) * 1e3:.5f} mJ, "
          f"{int(tr.impacts.count)} impacts by t = 0.3 s")
tr_0, arr_0, _ = runs["without air drag"]
before0 = arr_0["t"] < float(tr_0.impacts.time[0])
assert abs(arr_0["energy"][before0][-1] / arr_0["energy"][0] - 1) < 1e-9  # no air: conserved

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4))
for name, (_, arr, _) in runs.items():
    ax1.plot(arr["t"], arr["pos"][:, 2] * 1e3, label=name)
    ax2.plot(arr["t"], arr["energy"] * 1e3, label=name)
ax1.set_ylabel("mass centre height (mm)")
ax2.set_ylabel("energy (mJ)")
for ax in (ax1, ax2):
    ax.set_xlabel("t (s)")
    ax.legend()
plt.show()""",
    ),
    (
        "md",
        """Air drag on a 4.5 g die in a 0.2 s throw is a small force (k |v|^2 / (m g) is about 1 %):
it takes under 1 % of the energy before the first impact and moves the landing point by a few
millimetres. After the first impacts the two runs drift apart: small differences in the landing
attitude change which corner hits next, so the face a thrown die ends on is sensitive to
everything, air included.

## 4. Two coin tosses: a face coming down, and a coin rolling on its rim
A coin is a short cylinder, `jaxrb.Cylinder(radius, half_height)`, its axis along body z (heads
= +z up). Its contact model (docs/contact.md) has, per cap, the lowest and the highest rim point,
the side line, and the two caps as faces. On its rim it is in *point* mode (rolling where the
contact sticks, sliding where it slips); its face comes down when the highest rim point reaches
the floor (the *flat* event), and that is the only way it gets onto a face: no rule lays it flat.
Rolling resistance is not modelled, so nothing but sliding friction and air takes energy from a
coin rolling on its rim.

A 5.67 g coin of 24.26 mm diameter and 1.75 mm thickness, with air drag and a small aerodynamic
damping moment, lands on a table with restitution 0.3 and friction 0.3. Both tosses use the same
compiled simulation (same scene structure, same number of saves):

- **flip**: from 10 cm with 1.5 m/s upwards, spinning at 40 rad/s about a diameter;
- **spin**: tilted by 34 deg, 1 m/s upwards, turning at 25 rad/s about a diameter and at
  60 rad/s about its own axis.

The lean angle is the angle between the coin's axis (body z) and the vertical, folded into
0–90 deg (0: flat on either face, 90: standing on its rim).""",
    ),
    (
        "code",
        """RADIUS, HALF, MASS = 0.01213, 0.000875, 0.00567
coin = jaxrb.RigidBody(MASS, shape=jaxrb.Cylinder(RADIUS, HALF))
coin_air = jaxrb.QuadraticDrag.from_air(rho=1.225, drag_coefficient=1.1, area=np.pi * RADIUS**2)
coin_scene = jaxrb.Scene(coin, forces=(jaxrb.Gravity(), coin_air, jaxrb.DampingMoment(quadratic=1e-9)),
                         floor=jaxrb.Floor(0.3, friction=0.3))
x_axis = jnp.array([1.0, 0.0, 0.0])
tosses = {
    "flip": jaxrb.make_state(pos=(0.0, 0.0, 0.1), quat=jaxrb.axis_angle_to_quat(x_axis, jnp.asarray(0.02)),
                             vel=(0.0, 0.0, 1.5), omega=(40.0, 0.0, 0.0)),
    "spin": jaxrb.make_state(pos=(0.0, 0.0, 0.1), quat=jaxrb.axis_angle_to_quat(x_axis, jnp.asarray(0.6)),
                             vel=(0.2, 0.0, 1.0), omega=(25.0, 0.0, 60.0)),
}
cts = jnp.linspace(0.0, 1.5, 301)
coins = {}
for name, s0 in tosses.items():
    t0 = time.perf_counter()
    ctraj = jaxrb.simulate(coin_scene, s0, cts, rtol=1e-6, atol=1e-6)
    assert ctraj.result == jaxrb.RESULTS.successful
    R = jax.vmap(jaxrb.quat_to_matrix)(ctraj.states.quat)
    lean = np.degrees(np.arccos(np.clip(np.abs(np.asarray(R[:, 2, 2])), 0.0, 1.0)))
    ca = jaxrb.plotting.trajectory_arrays(ctraj, coin_scene)
    coins[name] = (ctraj, lean, ca)
    clog = ctraj.contact
    c_t = np.asarray(clog.event_time)
    c_used = np.isfinite(c_t)
    causes, counts = np.unique(np.asarray(clog.event_cause)[c_used], return_counts=True)
    side = "heads" if float(R[-1, 2, 2]) > 0 else "tails"
    print(f"{name}: simulate {time.perf_counter() - t0:.1f} s (the first run compiles); {int(ctraj.impacts.count)} impacts, "
          f"first at t = {float(ctraj.impacts.time[0]):.3f} s; {int(clog.events)} events "
          f"({', '.join(f'{CAUSES[int(c)]} {m}' for c, m in zip(causes, counts))})")
    print(f"      at t = {float(cts[-1])} s: {mode_name(clog.kind[-1], clog.sliding[-1])}, lean {lean[-1]:.1f} deg, "
          f"{side} up, centre at z = {float(ctraj.states.pos[-1, 2]) * 1e3:.4f} mm, "
          f"|v| = {float(jnp.linalg.norm(ctraj.states.vel[-1])):.1e} m/s, E = {ca['energy'][-1] * 1e3:.4f} mJ "
          f"(from {ca['energy'][0] * 1e3:.4f} mJ)")
    assert np.all(np.diff(ca["energy"]) <= 1e-9 * ca["energy"][0])  # never gains energy

flip, flip_lean, _ = coins["flip"]
flat = np.flatnonzero(np.asarray(flip.contact.event_cause) == CAUSES.index("flat"))
print(f"flip: the face came down (flat event) at t = {float(flip.contact.event_time[flat[0]]):.4f} s")
assert flat.size >= 1 and int(flip.contact.kind[-1]) == 3 and flip_lean[-1] < 1e-4
assert abs(float(flip.states.pos[-1, 2]) - HALF) < 1e-6
spin, spin_lean, _ = coins["spin"]
assert int(spin.contact.kind[-1]) == 1 and spin_lean[-1] > 1.0  # still on its rim at the end""",
    ),
    (
        "code",
        """fig, axes = plt.subplots(3, 2, figsize=(13, 8), sharex=True)
for col, (name, (ctraj, lean, ca)) in enumerate(coins.items()):
    ax1, ax2, ax3 = axes[:, col]
    ax1.plot(ca["t"], ca["pos"][:, 2] * 1e3, label="centre")
    ax1.plot(ca["t"], ca["lowest_z"] * 1e3, lw=1, label="lowest rim point")
    ax1.set_ylabel("height (mm)")
    ax1.set_title(f"coin toss: {name}")
    ax2.plot(ca["t"], lean, "C2")
    ax2.set_ylabel("lean: axis to vertical (deg)")
    ax2.set_yticks([0, 30, 60, 90])
    plot_mode(ax3, ca["t"], ctraj.contact)
    ax3.set_ylabel("contact mode")
    ax3.set_xlabel("t (s)")
    for ax in (ax1, ax2, ax3):
        for i, ti in enumerate(np.asarray(ctraj.impacts.time[: int(ctraj.impacts.count)])):
            ax.axvline(ti, color="C3", lw=0.6, alpha=0.4, label="impact" if i == 0 else None)
    ax1.legend(fontsize="small")
    ax3.legend(fontsize="small", loc="upper left")
plt.tight_layout()
plt.show()
print("spin toss, events:")
event_table(spin.contact, first=12)""",
    ),
    (
        "md",
        """The flipped coin bounces, rocks for a moment on its rim, and its face slaps down: a flat
event, then it slides on its face until friction stops it. The spinning coin bounces a few
times and then stays on its rim: it rolls, slips and wobbles (the lean angle swings while the
contact point runs round the rim), losing energy only to sliding friction and air. It is still
on its rim when the run ends; a real coin would come down sooner, by rolling resistance and air
flow under it (Euler's disk), which the model does not have.

## 5. The animation
`jaxrb.plotting.animate` draws the body at R(q) x + pos for each frame (world frame, z up) and
saves a GIF; here into a temporary directory, shown inline.""",
    ),
    (
        "code",
        """with tempfile.TemporaryDirectory() as tmp:
    gif = Path(tmp) / "die.gif"
    anim = jaxrb.plotting.animate(traj, scene, path=gif, max_frames=30, fps=15, title="die thrown onto a table")
    plt.close()  # the animation's figure: shown below as the GIF instead
    data = gif.read_bytes()
print(f"{len(data) / 1e6:.1f} MB GIF")
display(Image(data=data, format="gif"))""",
    ),
]
NB05 = [
    (
        "md",
        """# 05 — Identifying a full inertia tensor from gyro data

A body tumbles freely; a gyro records its body-frame angular velocity omega(t) with noise. Euler's
equations with products of inertia (docs/theory.md, section 4.2),

J w_dot + w x (J w) = M_C = 0,  J = [[J11, -J12, -J13], [-J12, J22, -J23], [-J13, -J23, J33]],

predict omega(t) from J and omega(0). `jaxrb.fit.fit_inertia` fits J (and omega(0), a nuisance
parameter) by Levenberg–Marquardt *through the differentiable simulation*; J is parameterised by
the log-Cholesky factor of its pseudo-inertia, so every iterate is a physical tensor (symmetric,
positive definite, triangle inequality). Uncertainties are Gauss–Newton:
Cov = sigma^2 (J_r^T J_r)^-1 with the residual Jacobian J_r and sigma^2 = |r|^2 / (n - p).

**Scale.** With no torque, J and c J give the same omega(t) for every c > 0 (divide Euler's
equations by c). Torque-free data determine J only up to scale; `fit_inertia` fixes the trace to
that of the initial guess (and says so), or gets the absolute scale from a known torque.""",
    ),
    (
        "code",
        SETUP
        + """
import diffrax as dfx
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
    traj = jaxrb.simulate(scene, jaxrb.make_state(omega=jnp.asarray(omega0)), jnp.asarray(TS), **SIM)
    return np.asarray(traj.states.omega)


omega_clean = observe(J_TRUE)
omega_noisy = omega_clean + SIGMA * np.random.default_rng(0).standard_normal(omega_clean.shape)
J_START = J_TRUE * np.array([[1.3, 0.7, 1.3], [0.7, 1.3, 0.7], [1.3, 0.7, 0.7]])  # 30 % off, entry by entry
print("initial guess:\\n", J_START)""",
    ),
    (
        "md",
        """## 1. Scale ambiguity of torque-free data
The same start with J and 2.5 J gives the same omega(t) (to round-off):""",
    ),
    (
        "code",
        """diff = np.max(np.abs(observe(2.5 * J_TRUE) - omega_clean))
print(f"max |omega(2.5 J) - omega(J)| = {diff:.1e} rad/s")
assert diff < 1e-12""",
    ),
    (
        "md",
        """## 2. Noise-free data: exact recovery (up to the scale)
The oracle: J_TRUE rescaled to the trace of the guess.""",
    ),
    (
        "code",
        """res0 = jaxrb.fit.fit_inertia(TS, inertia0=J_START, omega=omega_clean, **SIM)
J_ref = J_TRUE * np.trace(J_START) / np.trace(J_TRUE)
rel = np.max(np.abs(res0.values["inertia"] - J_ref)) / np.max(np.abs(J_ref))
print(res0.warnings[0])
print(f"noise-free: {res0.num_steps} LM steps, max relative error of the tensor {rel:.1e}")
assert res0.converged and rel < 1e-6""",
    ),
    (
        "md",
        """## 3. Noisy gyro data (sigma = 2e-3 rad/s)
The fitted entries with their one-sigma errors against the truth. Six independent numbers define a
tensor; with the trace fixed, five are free (the sixth follows).""",
    ),
    (
        "code",
        """res = jaxrb.fit.fit_inertia(TS, inertia0=J_START, omega=omega_noisy, **SIM)
print(res.report())
J_fit, J_std = res.values["inertia"], res.std["inertia"]
idx = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
names = ["J11", "J22", "J33", "J12 (= -J[0,1])", "J13 (= -J[0,2])", "J23 (= -J[1,2])"]
sign = [1, 1, 1, -1, -1, -1]  # products of inertia are minus the off-diagonal entries
print(f"\\n{'entry':16} {'true (scaled)':>14} {'fitted':>10} {'1 sigma':>9} {'z':>6}")
z = []
for (i, j), nm, s in zip(idx, names, sign):
    z.append(s * (J_fit[i, j] - J_ref[i, j]) / J_std[i, j])
    print(f"{nm:16} {s * J_ref[i, j]:14.5f} {s * J_fit[i, j]:10.5f} {J_std[i, j]:9.1e} {z[-1]:6.2f}")
sigma_hat = np.sqrt(res.sigma2)
print(f"noise estimated from the residuals: {sigma_hat:.2e} rad/s (true {SIGMA:.0e})")
assert res.converged
assert np.all(np.abs(z) < 4)  # the truth lies inside the reported uncertainty
assert abs(sigma_hat / SIGMA - 1) < 0.2""",
    ),
    (
        "code",
        """fig, ax = plt.subplots(figsize=(8, 3.8))
x = np.arange(6)
ax.errorbar(x, [s * (J_fit[i, j] - J_ref[i, j]) for (i, j), s in zip(idx, sign)],
            yerr=[2 * J_std[i, j] for i, j in idx], fmt="o", capsize=4, label="fitted - true, +- 2 sigma")
ax.axhline(0.0, color="k", lw=0.8)
ax.set_xticks(x, [n.split()[0] for n in names])
ax.set_ylabel("kg m^2")
ax.set_title("Inertia entries from noisy gyro data: error and reported uncertainty")
ax.legend()
plt.show()""",
    ),
    (
        "md",
        """## 4. Data, fitted model and residuals
The residuals (model - data) should look like the white noise that was added: no trend, no
oscillation left over, spread sigma.""",
    ),
    (
        "code",
        """model = observe(J_fit, res.values["omega0"])  # the fitted model at the sample times
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
ax3.plot(u, np.exp(-u**2 / 2) / np.sqrt(2 * np.pi), "k")
ax3.set_xlabel("residual / sigma")
ax3.set_title("vs N(0, 1)")
plt.tight_layout()
plt.show()""",
    ),
]
NB06 = [
    (
        "md",
        """# 06 — Fitting restitution and air drag

**Restitution (Newton's hypothesis).** At an impact the normal velocity of the contact point
reverses and shrinks: v' = -e v, 0 <= e <= 1. A ball dropped from rest at height h0 (docs/theory.md, section 8.2):

- first impact t_1 = sqrt(2 h0 / g), then t_(k+1) - t_k = 2 e^k sqrt(2 g h0) / g;
- apex after bounce k: e^(2k) h0; all bounces end at the Zeno time t_1 (1 + e) / (1 - e).

`jaxrb.fit.fit_restitution` fits e (and h0 if unknown) to impact times and/or apex heights.

**Drag.** A quadratic drag force F = -k |v| v (k = rho C_D A / 2) on a falling ball gives, for a
vertical drop from rest, the exact terminal-velocity solution with v_t = sqrt(m g / k):

v(t) = -v_t tanh(g t / v_t),  z(t) = z0 - (v_t^2 / g) ln cosh(g t / v_t).

`jaxrb.fit.fit_drag` fits k (and the initial position and velocity) to tracked positions through
the differentiable simulation.""",
    ),
    (
        "code",
        SETUP
        + """
import diffrax as dfx
import jaxrb.fit
from jaxrb.analytic import ball_apex_heights, ball_height, ball_impact_times, ball_rest_time

rng = np.random.default_rng(0)
E_TRUE, H0_TRUE, G = 0.7, 1.2, 9.81""",
    ),
    (
        "md",
        """## 1. Restitution from bounce times
Noise-free times first (the oracle: e and h0 must come back exactly), then six impact times with
2 ms timing noise, e.g. from the sound of the bounces.""",
    ),
    (
        "code",
        """times = np.asarray(ball_impact_times(H0_TRUE, E_TRUE, 6))
exact_fit = jaxrb.fit.fit_restitution(impact_times=times, restitution0=0.5)
print(f"noise-free: e = {exact_fit.values['restitution']:.10f}, h0 = {exact_fit.values['h0']:.10f}")
assert abs(exact_fit.values["restitution"] / E_TRUE - 1) < 1e-8 and abs(exact_fit.values["h0"] / H0_TRUE - 1) < 1e-8

times_noisy = times + 2e-3 * rng.standard_normal(times.size)
fit_t = jaxrb.fit.fit_restitution(impact_times=times_noisy, restitution0=0.5)
e_t, se_t = fit_t.values["restitution"], fit_t.std["restitution"]
print(f"from noisy times: e = {e_t:.4f} +- {se_t:.4f}, h0 = {fit_t.values['h0']:.4f} +- {fit_t.std['h0']:.4f} m")
assert abs(e_t - E_TRUE) < 4 * se_t""",
    ),
    (
        "md",
        """## 2. Restitution from apex heights (known drop height)
Four apex heights measured with 5 mm noise, h0 known:""",
    ),
    (
        "code",
        """heights = np.asarray(ball_apex_heights(H0_TRUE, E_TRUE, 4)) + 5e-3 * rng.standard_normal(4)
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
plt.show()""",
    ),
    (
        "md",
        """## 3. A simulated ball on a `jaxrb.Floor` against the exact bounce
`jaxrb.simulate` locates each impact as an event and applies Newton's restitution at the touching
point (the contact engine `jaxrb.contact`, docs/contact.md); its height must follow
`jaxrb.analytic.ball_height`, and its impact times fed to `fit_restitution` must give e back.
Once a bounce leaves the floor slower than `rest_speed` (default 1 cm/s) the remaining infinite
series of micro-bounces is replaced by its limit, a *Zeno merge* (`traj.contact.zeno_merges`):
the ball then stays on the floor in persistent contact, and `traj.impacts.rest_time` records the
time the series would have ended (for a point on a flat floor, exactly the Zeno time). From then
on the height may differ from the exact one by at most rest_speed^2 / (2 g) = 5 um.""",
    ),
    (
        "code",
        """R_BALL = 0.05
ball = jaxrb.Scene(jaxrb.RigidBody(0.1, shape=jaxrb.Sphere(R_BALL)), forces=(jaxrb.Gravity((0.0, 0.0, -G)),),
                   floor=jaxrb.Floor(E_TRUE))
ts = jnp.linspace(0.0, 4.0, 801)
traj = jaxrb.simulate(ball, jaxrb.make_state(pos=(0.0, 0.0, H0_TRUE + R_BALL)), ts, rtol=1e-10, atol=1e-10)
z = traj.states.pos[:, 2] - R_BALL
dz = jnp.abs(z - ball_height(ts, H0_TRUE, E_TRUE))
n_imp = int(traj.impacts.count)
sim_times = np.asarray(traj.impacts.time[:n_imp])
t_err = np.max(np.abs(sim_times[:6] - times))
err_bounces = float(jnp.max(jnp.where(ts < sim_times[-1], dz, 0.0)))
bound = 0.01**2 / (2 * G)  # rest_speed = 1 cm/s: the merged micro-bounces are lower than this
print(f"{n_imp} impacts recorded; first 6 impact times off by {t_err:.1e} s")
print(f"max |z_sim - z_exact| up to the last impact {err_bounces:.1e} m, overall {float(dz.max()):.1e} m (bound {bound:.1e} m)")
print(f"rest time: simulated {float(traj.impacts.rest_time):.6f} s, exact {float(ball_rest_time(H0_TRUE, E_TRUE)):.6f} s")
print(f"bounce series merged: {int(traj.contact.zeno_merges)}; contact mode at the end: "
      f"{jaxrb.contact.KIND_NAMES[int(traj.contact.kind[-1])]}")
assert t_err < 1e-9 and err_bounces < 1e-8 and float(dz.max()) <= bound
assert abs(float(traj.impacts.rest_time) - float(ball_rest_time(H0_TRUE, E_TRUE))) < 1e-8
e_sim = jaxrb.fit.fit_restitution(impact_times=sim_times[:6], restitution0=0.5).values["restitution"]
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
plt.show()""",
    ),
    (
        "md",
        """## 4. Quadratic drag from a tracked drop
A tennis ball (m = 57 g, d = 6.6 cm, C_D = 0.55 in air of 1.2 kg/m^3: k = rho C_D A / 2) dropped from
rest, tracked at 10 Hz for 3 s with 2 cm position noise. The data come from the exact tanh /
log-cosh solution, not from the simulator.""",
    ),
    (
        "code",
        """MASS = 0.057
K_TRUE = float(jaxrb.QuadraticDrag.from_air(rho=1.2, drag_coefficient=0.55, area=np.pi * 0.033**2).coefficient)
v_t = np.sqrt(MASS * G / K_TRUE)
t_obs = np.linspace(0.0, 3.0, 31)
z_exact = 50.0 - v_t**2 / G * np.log(np.cosh(G * t_obs / v_t))
pos_exact = np.stack([np.zeros_like(t_obs), np.zeros_like(t_obs), z_exact], -1)
pos_noisy = pos_exact + 0.02 * rng.standard_normal(pos_exact.shape)
print(f"k = {1e3 * K_TRUE:.4f} g/m, terminal speed {v_t:.1f} m/s")

SIM = dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01)
fit0 = jaxrb.fit.fit_drag(t_obs, pos_exact, mass=MASS, drag0=0.5 * K_TRUE, g=(0.0, 0.0, -G), **SIM)
print(f"noise-free: k = {fit0.values['drag']:.8f} (relative error {fit0.values['drag'] / K_TRUE - 1:.1e})")
assert abs(fit0.values["drag"] / K_TRUE - 1) < 1e-6
fit_k = jaxrb.fit.fit_drag(t_obs, pos_noisy, mass=MASS, drag0=0.5 * K_TRUE, g=(0.0, 0.0, -G), **SIM)
k_fit, k_std = fit_k.values["drag"], fit_k.std["drag"]
print(f"noisy: k = {1e3 * k_fit:.4f} +- {1e3 * k_std:.4f} g/m (true {1e3 * K_TRUE:.4f}); C_D = {k_fit / K_TRUE * 0.55:.3f} +- {k_std / K_TRUE * 0.55:.3f}")
assert abs(k_fit - K_TRUE) < 4 * k_std""",
    ),
    (
        "code",
        """tt = np.linspace(0.0, 3.0, 301)
v_fit = np.sqrt(MASS * G / k_fit)
vz0 = fit_k.values["vel0"][2]
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
ax1.plot(t_obs, pos_noisy[:, 2], "o", ms=4, label="tracked (2 cm noise)")
ax1.plot(tt, 50.0 - v_t**2 / G * np.log(np.cosh(G * tt / v_t)), "k", lw=1, label="exact, true k")
ax1.plot(tt, fit_k.values["pos0"][2] - v_fit**2 / G * np.log(np.cosh(G * tt / v_fit)), "--", label=f"fitted k = {1e3 * k_fit:.4f} g/m")
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
plt.show()""",
    ),
]
NB07 = [
    (
        "md",
        """# 07 — Speed against error: a small work-precision study of B1

**The timings in this notebook are illustrative only**: a small batch, few repeats, on whatever
machine runs the notebook (often a shared CPU). The real numbers, with compile time separated,
larger batches, float32, more methods and peers (MuJoCo), come from `benchmarks/`
(`python -m benchmarks.b1_torque_free --n 1000 --dtype both --out bench_out`).

Problem B1 (benchmarks/README.md): a torque-free asymmetric body, I = (1, 2, 3), omega0 = (a, 0, c) with
a ~ U(0.5, 1.5), c ~ U(1, 2), q0 = identity, T = 20 s. Error = worst body's
max(|omega(T) - omega_exact(T)| / |omega0|, geodesic angle of q(T) vs a reference), with the exact
elliptic-function omega (`jaxrb.analytic.asymmetric_top`) and a tolerance-1e-13 float64 reference
attitude. Cost = steady-state wall time per body (compilation excluded: one warm-up call first).

Methods, each at a few tolerances:
- `jax.vmap(jaxrb.simulate)` (diffrax Tsit5 with a PID controller, per-body steps);
- the lean batched DOP853 `jaxrb._batched.simulate_batch` (one batch-wide step-size loop);
- scipy `solve_ivp(method="DOP853")` with a NumPy right-hand side, body by body.""",
    ),
    (
        "code",
        SETUP
        + """
import time

import scipy.integrate
from jaxrb.analytic import asymmetric_top

try:
    from jaxrb._batched import simulate_batch
except ImportError:  # the fast batched path is optional
    simulate_batch = None

dev = jax.devices()[0]
print(f"device: {dev.platform}:{getattr(dev, 'device_kind', '?')}, jax {jax.__version__}, float64")

N, T_END = 64, 20.0
INERTIA = jnp.array([1.0, 2.0, 3.0])
k1, k2 = jax.random.split(jax.random.key(0))
omega0 = jnp.stack([jax.random.uniform(k1, (N,), minval=0.5, maxval=1.5), jnp.zeros(N),
                    jax.random.uniform(k2, (N,), minval=1.0, maxval=2.0)], -1)
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
states0 = jaxrb.State(jnp.zeros((N, 3)), jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (N, 1)), jnp.zeros((N, 3)), omega0)
ts = jnp.array([0.0, T_END])


def best_time(fn, *args, repeat=3):
    jax.block_until_ready(fn(*args))  # warm-up (compiles on the first tolerance only)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return best""",
    ),
    (
        "md",
        """## Reference and error measure
omega(T) is exact (Jacobi elliptic functions). The reference attitude is the batched DOP853 at
rtol = atol = 1e-13; its omega agrees with the exact one to ~1e-12, which bounds how far it can be
trusted.""",
    ),
    (
        "code",
        """w_exact = jax.vmap(lambda w: asymmetric_top(T_END, INERTIA, w))(omega0)


@jax.jit
def run_vmap(tol):
    sim = lambda s: jaxrb.simulate(scene, s, ts, rtol=tol, atol=tol, max_steps=200_000)  # noqa: E731
    tr = jax.vmap(sim)(states0)
    return tr.states.omega[:, -1], tr.states.quat[:, -1]


if simulate_batch is not None:
    @jax.jit
    def run_batch(tol):
        tr = simulate_batch(scene, states0, ts, rtol=tol, atol=tol, throw=False)
        return tr.states.omega[:, -1], tr.states.quat[:, -1]

    w_ref, q_ref = run_batch(jnp.asarray(1e-13))
else:
    w_ref, q_ref = run_vmap(jnp.asarray(1e-13))
ref_err = float(jnp.max(jnp.linalg.norm(w_ref - w_exact, axis=-1)))
print(f"reference omega vs exact: {ref_err:.1e} rad/s")
assert ref_err < 1e-10
w0n = jnp.linalg.norm(omega0, axis=-1)


def b1_error(w_T, q_T):
    w_T, q_T = jnp.asarray(w_T), jnp.asarray(q_T)
    e_w = jnp.linalg.norm(w_T - w_exact, axis=-1) / w0n
    e_q = jaxrb.quat_geodesic_angle(q_T / jnp.linalg.norm(q_T, axis=-1, keepdims=True), q_ref)
    return float(jnp.max(jnp.maximum(e_w, e_q)))""",
    ),
    ("md", "## The sweep"),
    (
        "code",
        """results = {}
tols = [1e-5, 1e-7, 1e-9, 1e-11]
results["vmap(jaxrb.simulate), Tsit5"] = [
    (best_time(run_vmap, jnp.asarray(tol)) / N, b1_error(*run_vmap(jnp.asarray(tol))), tol) for tol in tols]
if simulate_batch is not None:
    results["simulate_batch (lean DOP853)"] = [
        (best_time(run_batch, jnp.asarray(tol)) / N, b1_error(*run_batch(jnp.asarray(tol))), tol) for tol in tols]


def rhs_np(t, y, I=np.asarray(INERTIA)):
    q, w = y[:4], y[4:]
    w_dot = np.array([(I[1] - I[2]) * w[1] * w[2] / I[0], (I[2] - I[0]) * w[2] * w[0] / I[1],
                      (I[0] - I[1]) * w[0] * w[1] / I[2]])
    q_dot = 0.5 * np.array([-q[1:] @ w, q[0] * w[0] + q[2] * w[2] - q[3] * w[1],
                            q[0] * w[1] + q[3] * w[0] - q[1] * w[2], q[0] * w[2] + q[1] * w[1] - q[2] * w[0]])
    return np.concatenate([q_dot, w_dot])


n_py = 4  # scipy runs body by body in Python: a few bodies suffice for the time per body
rows = []
scipy.integrate.solve_ivp(rhs_np, (0.0, 1.0), np.r_[1.0, 0, 0, 0, 1.0, 0, 1.0], method="DOP853")  # warm-up
for tol in tols:
    t0 = time.perf_counter()
    ys = [scipy.integrate.solve_ivp(rhs_np, (0.0, T_END), np.r_[1.0, 0, 0, 0, np.asarray(omega0[i])],
                                    method="DOP853", rtol=tol, atol=tol).y[:, -1] for i in range(n_py)]
    per_body = (time.perf_counter() - t0) / n_py
    ys = np.array(ys)
    e_w = np.linalg.norm(ys[:, 4:] - np.asarray(w_exact[:n_py]), axis=-1) / np.asarray(w0n[:n_py])
    e_q = np.asarray(jaxrb.quat_geodesic_angle(jnp.asarray(ys[:, :4] / np.linalg.norm(ys[:, :4], axis=-1, keepdims=True)), q_ref[:n_py]))
    rows.append((per_body, float(np.max(np.maximum(e_w, e_q))), tol))
results[f"scipy DOP853 ({n_py} bodies, NumPy rhs)"] = rows

print(f"{'method':42} {'tol':>7} {'error':>9} {'time/body':>11}")
for name, rs in results.items():
    for t_body, err, tol in rs:
        print(f"{name:42} {tol:7.0e} {err:9.1e} {1e6 * t_body:9.1f} us")""",
    ),
    (
        "code",
        """fig, ax = plt.subplots(figsize=(8, 5))
for (name, rs), m in zip(results.items(), "os^"):
    t_body, err, tol = map(np.array, zip(*rs))
    ax.loglog(t_body, err, m + "-", label=name)
    for x, y, tl in zip(t_body, err, tol):
        ax.annotate(f"{tl:.0e}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
ax.set_xlabel("wall time per body (s)  [illustrative: see benchmarks/]")
ax.set_ylabel("B1 error (worst body)")
ax.set_title(f"B1 work-precision, N = {N}, T = {T_END:g} s, on {dev.platform}")
ax.grid(alpha=0.3, which="both")
ax.legend(fontsize="small", loc="upper center")
plt.show()

# Accuracy claims are checked against the exact oracle; timings are not asserted (machine-dependent).
for name, rs in results.items():
    errs = [err for _, err, _ in rs]
    assert errs[-1] < 1e-8, (name, errs)  # tight tolerance: accurate against the exact solution
    assert errs[0] > 10 * errs[-1], (name, errs)  # and the tolerance controls the error""",
    ),
]


def build(cells, path):
    nb = new_notebook()
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nb.cells = [
        new_markdown_cell(src) if kind == "md" else new_code_cell(src) for kind, src in cells
    ]
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"{Path(path).stem[:2]}-{i:02d}"
    nbformat.validate(nb)
    nbformat.write(nb, path)


NOTEBOOKS = {
    "01_pendulum_bearing_force": NB01,
    "02_torque_free_precession": NB02,
    "03_orientation": NB03,
    "04_coin_and_die": NB04,
    "05_inertia_identification": NB05,
    "06_restitution_and_drag_fitting": NB06,
    "07_speed_against_error": NB07,
}

if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    only = sys.argv[2:]  # optional notebook-name prefixes, e.g. 03 05
    for name, cells in NOTEBOOKS.items():
        if not only or any(name.startswith(o) for o in only):
            build(cells, out / f"{name}.ipynb")
