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
# # 04 — A die and a coin: air resistance, bounces, rolling, rocking, and the face they settle on
#
# The default scene of `jaxrb run` (`jaxrb/scenes/default.toml`): a 16 mm plastic die thrown with
# spin onto a table. In flight it obeys the Newton–Euler equations with gravity, quadratic air drag
# F = -k |v| v (k = rho C_D A / 2) and an aerodynamic damping moment M = -(c_1 + c_2 |w|) w (body
# frame). At the table the contact engine `jaxrb.contact` takes over (formulation: docs/contact.md):
#
# - **impacts**: when a corner (or a rim point, or a sphere) reaches the floor, the impulses at
#   *all* touching points are found together, by Newton's restitution (a point that approached
#   leaves at e times its approach speed) with Coulomb friction (|j_t| <= mu j_n);
# - **persistent contact**: between impacts the body may stay on the floor on one point (a
#   corner, a rim point), a pair of points (an edge, a coin's side line) or a face, and each
#   contact sticks (rolling, rocking, pivoting) or slides under Coulomb friction; the
#   constrained Newton–Euler equations of that *mode* are integrated;
# - **events**: every mode change ends a smooth segment and is located as an event: a touch, a
#   lift-off, a face tipping over an edge, friction reaching its cone (slip starts), a slip
#   passing zero (slip stops), a coin's face coming down (flat);
# - a series of ever smaller bounces or rocks whose points leave slower than `rest_speed`
#   (1 cm/s) is replaced by its limit (a *Zeno merge*, counted in `traj.contact.zeno_merges`).
#
# **No rule lays a body flat.** A die comes to rest on a face only by the dynamics: it hops and
# rocks over its corners and edges, loses energy at every impact and to friction, lands on a face,
# slides and sticks. A coin, with no rolling resistance in the model, may keep rolling on its rim.
#
# `traj.impacts` records each impact's `time`, `point`, `impulse`, `energy_lost` (J) and the
# impact `count`; `traj.contact` records the contact mode at each save (`kind`: 0 flight, 1 point,
# 2 pair, 3 face, named by `jaxrb.contact.KIND_NAMES`; `sliding`), and each event's time, cause and
# the mode after it. We look at height, energy and contact mode, the events, the face the die
# settles on, what air drag changes, two tossed coins, and an animation.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, display

import jaxrb
import jaxrb.plotting
from jaxrb._scene_file import default_scene_path, load_scene
from jaxrb.contact import KIND_NAMES
from jaxrb.contact._record import CAUSES  # what ended each segment: traj.contact.event_cause

spec = load_scene(default_scene_path())
scene, state0 = spec.scene, spec.state0
ts = jnp.linspace(0.0, 1.0, 301)  # the scene file saves to 0.6 s; 1 s also shows the die at rest
OPTS = dict(
    rtol=spec.options["rtol"], atol=spec.options["atol"], max_steps=spec.options["max_steps"]
)
print(f"{spec.title}: {spec.description}")
print(
    f"mass {float(scene.body.mass) * 1e3:.1f} g, half edge {float(scene.body.shape.half_extents[0]) * 1e3:.0f} mm; "
    f"restitution {float(scene.floor.restitution)}, friction {float(scene.floor.friction)}; "
    f"k = {float(scene.forces[1].coefficient):.3e} kg/m; {ts.size} saves over {float(ts[-1])} s"
)


def mode_name(kind, sliding):
    name = KIND_NAMES[int(kind)]
    return name if name == "flight" else f"{name}, {'sliding' if sliding else 'sticking'}"


def event_table(log, first=15):
    """Print the first events of a ContactLog: time, cause, mode after (slot 0 is the start)."""
    times = np.asarray(log.event_time)
    used = np.flatnonzero(np.isfinite(times))
    row = lambda i: (
        f"{i:4d} {times[i]:10.6f}  {CAUSES[int(log.event_cause[i])]:12} "  # noqa: E731
        f"{mode_name(log.event_kind[i], log.event_sliding[i])}"
    )
    print(f"{'#':>4} {'t (s)':>10}  {'cause':12} mode after")
    for i in used[:first]:
        print(row(i))
    if used.size > first:
        print(f"   ... {used.size - first} more; the last:")
        print(row(used[-1]))


def plot_mode(ax, t, log):
    """Contact mode at each save (step line) with the saves where the contact slides shaded."""
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
still = (
    (kind == 3)
    & ~sliding
    & (np.linalg.norm(a["vel"], axis=-1) < 1e-6)
    & (np.linalg.norm(a["omega"], axis=-1) < 1e-4)
)
assert still[-1]
i_rest = (
    len(still) - int(np.argmin(still[::-1])) if not still.all() else 0
)  # start of the final run of still saves
t_rest = float(t[i_rest])
ev_t = np.asarray(log.event_time)
last = int(np.flatnonzero(np.isfinite(ev_t))[-1])
print(
    f"{n} impacts, {int(log.events)} events, {int(log.zeno_merges)} bounce/rock series merged; "
    f"last event at t = {ev_t[last]:.4f} s ({CAUSES[int(log.event_cause[last])]} -> "
    f"{mode_name(log.event_kind[last], log.event_sliding[last])}); at rest on a face from the save at t = {t_rest:.3f} s"
)
print(
    f"energy guards {int(log.energy_guards)}, inconsistent modes {int(log.inconsistent)}, "
    f"largest energy rise at an event {float(log.max_energy_rise):.1e} J, deepest penetration at an event "
    f"{float(log.max_penetration):.1e} m, lowest corner at a save {float(a['lowest_z'].min()):.1e} m"
)
assert float(log.max_energy_rise) <= 1e-9 * E[0] and float(log.max_penetration) < 1e-6

# %% [markdown]
# ## 1. Height, energy and contact mode
# Energy E = m g z + m v^2 / 2 + w . J w / 2 can only fall: air drag and the damping moment take
# power P_air = k |v|^3 + (c_1 + c_2 |w|) |w|^2 in flight, each impact removes `energy_lost`, and
# Coulomb friction takes energy whenever a contact slides (a sticking contact, rolling or pivoting,
# takes none). Before the first impact only air acts, so E(0) - E(t) must equal the integral of
# P_air (computed here from the saved states). The third panel is the contact mode at each save,
# shaded where the contact slides.

# %%
k = float(scene.forces[1].coefficient)
c1, c2 = float(scene.forces[2].linear), float(scene.forces[2].quadratic)


def air_power(arrays):
    v, w = np.linalg.norm(arrays["vel"], axis=-1), np.linalg.norm(arrays["omega"], axis=-1)
    return k * v**3 + (c1 + c2 * w) * w**2


P = air_power(a)
flight = t < t_imp[0]
air_flight = np.trapezoid(P[flight], t[flight])
drop_flight = E[0] - E[flight][-1]
air_total = np.trapezoid(P, t)
print(
    f"before the first impact: E(0) - E(t) = {drop_flight:.6e} J, integral of P_air = {air_flight:.6e} J "
    f"(relative difference {drop_flight / air_flight - 1:.1e})"
)
print(
    f"E(0) = {E[0] * 1e3:.4f} mJ, E(end) = {E[-1] * 1e3:.4f} mJ; lost at the {n} impacts "
    f"{lost.sum() * 1e3:.4f} mJ, to the air {air_total * 1e3:.4f} mJ, "
    f"to sliding friction (the rest) {(E[0] - E[-1] - lost.sum() - air_total) * 1e3:.4f} mJ"
)
assert np.all(np.diff(E) <= 1e-9 * E[0])  # never gains energy
assert abs(drop_flight / air_flight - 1) < 1e-3
assert np.all(lost >= 0) and lost.sum() + air_total < E[0] - E[-1] + 1e-9

fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
ax1.plot(t, a["pos"][:, 2] * 1e3, label="mass centre")
ax1.plot(t, a["lowest_z"] * 1e3, lw=1, label="lowest corner")
ax2.plot(t, E * 1e3, "k", label="total energy E")
ax2.plot(
    t,
    (E[0] - np.concatenate([[0.0], np.cumsum((P[1:] + P[:-1]) / 2 * np.diff(t))])) * 1e3,
    "C2--",
    lw=1,
    label="E(0) minus air losses only",
)
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
plt.show()

# %% [markdown]
# The first impact takes most of the energy. The later ones are corner and edge hits as the die
# hops and rocks: between them it pivots on a corner (point) or rolls over an edge (pair), and a
# rocking series that dies out below `rest_speed` is replaced by its limit. It reaches a face
# sliding, and friction stops it. The events, each with what ended the segment before it and the
# mode after it:

# %%
event_table(log, first=15)
causes, counts = np.unique(np.asarray(log.event_cause)[np.isfinite(ev_t)], return_counts=True)
print(
    "events by cause:",
    ", ".join(f"{CAUSES[int(c)]} {m}" for c, m in zip(causes, counts, strict=True)),
)

# %% [markdown]
# ## 2. Which face is up?
# Row 3 of R(q) is the world vertical in body coordinates; the body axis closest to it is the one
# pointing up. Faces are numbered so that opposite faces add up to 7: +x 1, +y 2, +z 3, -z 4,
# -y 5, -x 6.

# %%
FACES = {(0, 1): 1, (1, 1): 2, (2, 1): 3, (2, -1): 4, (1, -1): 5, (0, -1): 6}


def face_up(quat):
    up = np.asarray(jaxrb.quat_to_matrix(quat))[2]  # world +z in body coordinates
    i = int(np.argmax(np.abs(up)))
    return FACES[(i, int(np.sign(up[i])))], float(np.degrees(np.arccos(min(1.0, abs(up[i])))))


face, tilt = face_up(traj.states.quat[-1])
half = float(scene.body.shape.half_extents[0])
z_end, v_end = float(traj.states.pos[-1, 2]), float(jnp.linalg.norm(traj.states.vel[-1]))
w_end = float(jnp.linalg.norm(traj.states.omega[-1]))
print(
    f"the die settles with face {face} up (tilt {tilt:.1e} deg); centre at z = {z_end * 1e3:.4f} mm "
    f"(half edge {half * 1e3:.1f} mm), |v| = {v_end:.1e} m/s, |w| = {w_end:.1e} rad/s; "
    f"final mode: {mode_name(log.kind[-1], log.sliding[-1])}"
)
assert tilt < 0.5 and abs(z_end - half) < 1e-5 and v_end < 1e-3 and w_end < 1e-2
assert int(log.kind[-1]) == 3 and not bool(log.sliding[-1])
fig = jaxrb.plotting.plot_height_attitude(traj, scene, title="die: height and attitude")
plt.show()

# %% [markdown]
# ## 3. What air drag changes: the same throw without drag
# Setting the drag coefficient and the damping moment to zero keeps the scene's structure (only
# array values change), so the compiled simulation is reused: no second compilation. We compare
# the flight and the first bounces (t <= 0.3 s, the same number of saves). Without air, energy is
# conserved in flight (to the solver's tolerance); with air it falls by the integral of P_air.

# %%
air = lambda s: (s.forces[1].coefficient, s.forces[2].linear, s.forces[2].quadratic)  # noqa: E731
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
    print(
        f"{name:17}: {wall:.2f} s; first impact at t = {first:.5f} s, at x, y = ({p[0]:.2f}, {p[1]:.2f}) mm, "
        f"energy lost in flight {(arr['energy'][0] - arr['energy'][before][-1]) * 1e3:.5f} mJ, "
        f"{int(tr.impacts.count)} impacts by t = 0.3 s"
    )
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
plt.show()

# %% [markdown]
# Air drag on a 4.5 g die in a 0.2 s throw is a small force (k |v|^2 / (m g) is about 1 %):
# it takes under 1 % of the energy before the first impact and moves the landing point by a few
# millimetres. After the first impacts the two runs drift apart: small differences in the landing
# attitude change which corner hits next, so the face a thrown die ends on is sensitive to
# everything, air included.
#
# ## 4. Two coin tosses: a face coming down, and a coin rolling on its rim
# A coin is a short cylinder, `jaxrb.Cylinder(radius, half_height)`, its axis along body z (heads
# = +z up). Its contact model (docs/contact.md) has, per cap, the lowest and the highest rim point,
# the side line, and the two caps as faces. On its rim it is in *point* mode (rolling where the
# contact sticks, sliding where it slips); its face comes down when the highest rim point reaches
# the floor (the *flat* event), and that is the only way it gets onto a face: no rule lays it flat.
# Rolling resistance is not modelled, so nothing but sliding friction and air takes energy from a
# coin rolling on its rim.
#
# A 5.67 g coin of 24.26 mm diameter and 1.75 mm thickness, with air drag and a small aerodynamic
# damping moment, lands on a table with restitution 0.3 and friction 0.3. Both tosses use the same
# compiled simulation (same scene structure, same number of saves):
#
# - **flip**: from 10 cm with 1.5 m/s upwards, spinning at 40 rad/s about a diameter;
# - **spin**: tilted by 34 deg, 1 m/s upwards, turning at 25 rad/s about a diameter and at
#   60 rad/s about its own axis.
#
# The lean angle is the angle between the coin's axis (body z) and the vertical, folded into
# 0–90 deg (0: flat on either face, 90: standing on its rim).

# %%
RADIUS, HALF, MASS = 0.01213, 0.000875, 0.00567
coin = jaxrb.RigidBody(MASS, shape=jaxrb.Cylinder(RADIUS, HALF))
coin_air = jaxrb.QuadraticDrag.from_air(rho=1.225, drag_coefficient=1.1, area=np.pi * RADIUS**2)
coin_scene = jaxrb.Scene(
    coin,
    forces=(jaxrb.Gravity(), coin_air, jaxrb.DampingMoment(quadratic=1e-9)),
    floor=jaxrb.Floor(0.3, friction=0.3),
)
x_axis = jnp.array([1.0, 0.0, 0.0])
tosses = {
    "flip": jaxrb.make_state(
        pos=(0.0, 0.0, 0.1),
        quat=jaxrb.axis_angle_to_quat(x_axis, jnp.asarray(0.02)),
        vel=(0.0, 0.0, 1.5),
        omega=(40.0, 0.0, 0.0),
    ),
    "spin": jaxrb.make_state(
        pos=(0.0, 0.0, 0.1),
        quat=jaxrb.axis_angle_to_quat(x_axis, jnp.asarray(0.6)),
        vel=(0.2, 0.0, 1.0),
        omega=(25.0, 0.0, 60.0),
    ),
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
    print(
        f"{name}: simulate {time.perf_counter() - t0:.1f} s (the first run compiles); {int(ctraj.impacts.count)} impacts, "
        f"first at t = {float(ctraj.impacts.time[0]):.3f} s; {int(clog.events)} events "
        f"({', '.join(f'{CAUSES[int(c)]} {m}' for c, m in zip(causes, counts, strict=True))})"
    )
    print(
        f"      at t = {float(cts[-1])} s: {mode_name(clog.kind[-1], clog.sliding[-1])}, lean {lean[-1]:.1f} deg, "
        f"{side} up, centre at z = {float(ctraj.states.pos[-1, 2]) * 1e3:.4f} mm, "
        f"|v| = {float(jnp.linalg.norm(ctraj.states.vel[-1])):.1e} m/s, E = {ca['energy'][-1] * 1e3:.4f} mJ "
        f"(from {ca['energy'][0] * 1e3:.4f} mJ)"
    )
    assert np.all(np.diff(ca["energy"]) <= 1e-9 * ca["energy"][0])  # never gains energy

flip, flip_lean, _ = coins["flip"]
flat = np.flatnonzero(np.asarray(flip.contact.event_cause) == CAUSES.index("flat"))
print(
    f"flip: the face came down (flat event) at t = {float(flip.contact.event_time[flat[0]]):.4f} s"
)
assert flat.size >= 1 and int(flip.contact.kind[-1]) == 3 and flip_lean[-1] < 1e-4
assert abs(float(flip.states.pos[-1, 2]) - HALF) < 1e-6
spin, spin_lean, _ = coins["spin"]
assert int(spin.contact.kind[-1]) == 1 and spin_lean[-1] > 1.0  # still on its rim at the end

# %%
fig, axes = plt.subplots(3, 2, figsize=(13, 8), sharex=True)
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
event_table(spin.contact, first=12)

# %% [markdown]
# The flipped coin bounces, rocks for a moment on its rim, and its face slaps down: a flat
# event, then it slides on its face until friction stops it. The spinning coin bounces a few
# times and then stays on its rim: it rolls, slips and wobbles (the lean angle swings while the
# contact point runs round the rim), losing energy only to sliding friction and air. It is still
# on its rim when the run ends; a real coin would come down sooner, by rolling resistance and air
# flow under it (Euler's disk), which the model does not have.
#
# ## 5. The animation
# `jaxrb.plotting.animate` draws the body at R(q) x + pos for each frame (world frame, z up) and
# saves a GIF; here into a temporary directory, shown inline.

# %%
with tempfile.TemporaryDirectory() as tmp:
    gif = Path(tmp) / "die.gif"
    anim = jaxrb.plotting.animate(
        traj, scene, path=gif, max_frames=30, fps=15, title="die thrown onto a table"
    )
    plt.close()  # the animation's figure: shown below as the GIF instead
    data = gif.read_bytes()
print(f"{len(data) / 1e6:.1f} MB GIF")
display(Image(data=data, format="gif"))
