"""Impacts with the floor: event-located collisions, Newton's restitution with Coulomb friction,
repeated bounces and resting / sliding / rolling contact.

Conventions: world frame z up, the floor is the plane z = `floor.height` with normal n = e_z;
quaternions scalar first mapping body to world; `omega` is the body-frame angular velocity.

**Model.** The motion is a sequence of smooth segments, each a `diffrax.diffeqsolve` in one of
three modes, joined by maps at event times located by a root finder (`optimistix.Newton`) on
the solver's dense interpolant, i.e. to solver precision rather than to a step:

- `FLIGHT`: the free Newton-Euler equations. Event: the lowest contact candidate of the shape
  (`AbstractShape.contact_candidates`: a sphere's lowest point, a box's 8 corners, a cylinder's
  two lowest rim points) reaches the floor (downward crossing). Then the *impact map* is applied.
- `SLIDE`: resting contact while the contact slips: the normal motion is frozen on the floor and
  a Coulomb friction force mu N opposes the slip. A sphere keeps its point contact (normal
  force N from the constraint, friction at the contact point, so spin and translation couple).
  A box or cylinder lying on a face slides on it with the face's friction approximated by an
  ellipsoidal limit surface of radius rho = sqrt(I_zz / m) (radius of gyration about the
  vertical): the generalised slip s = (v_x, v_y, rho w_z) decays along a fixed direction, so
  translation and spin stop together. Event: the slip falls to `SLIP_STOP_FRACTION` (1e-3)
  times `rest_speed` or reverses along its initial direction (s . s_0 = 0), whichever comes
  first; the slip left is then removed by the tangential friction impulse at the contact
  (for a face: the body stops). Ending a few microseconds early keeps the solver off the
  discontinuity of Coulomb friction at zero slip (where adaptive steps creep towards zero
  slip without crossing it); it moves the body by about s_stop^2 / (2 mu g), 2e-11 m for the
  default rest_speed and mu = 0.3.
- `STICK`: a sphere rolls without slipping (the contact force solves the rolling constraint,
  so drag or a wrench act through it); a box or cylinder is at rest on its face.
  Static friction is assumed to hold and lift-off is not detected in contact modes.

**Impact map** (`impact_map`, THEORY.md "Impact with a floor"): at contact point A (offset r_A
from the mass centre, world), with contact velocity u = v + w x r_A and the effective inverse
mass K = 1/m - [r_A]x I_w^-1 [r_A]x (I_w = R J R^T), impulses j change u by K j. Tried in order:
(1) stick: u'_n = -e u_n, u'_t = 0, accepted if |j_t| <= mu j_n; (2) slide: j = j_n (n - mu s),
s the unit incoming slip direction, j_n from u'_n = -e u_n; (3) frictionless j = j_n n.
A candidate is accepted only if it does not increase the kinetic energy (Newton's kinematic
law with friction can, in rare configurations -- Kane's example, Painleve-type jams where
n.K(n - mu s) <= 0); the frictionless impulse never does for e <= 1, and for e = 1, mu = 0 it
conserves energy exactly.

**Simultaneous contacts** (a die landing flat): sequential impulses. The lowest candidate is
resolved first, then `_SWEEPS` sweeps over all candidates within `contact_tol` of the floor
apply the impact map to each one still approaching, in index order. Each single impulse is
dissipative, so the whole is; the order breaks ties (documented, not symmetric).

**Coming to rest (Zeno).** After an impact whose outgoing normal speed u' is below
`rest_speed` (default 1 cm/s: bounces of apex below u'^2 / (2 g), about 5 um), with e < 1 and,
for a box or cylinder, rocking speeds (|v_z| plus the face radius times the part of omega that
tips the lowest face, i.e. omega less its component along the face normal) below `rest_speed`
and the lowest face tilted by less than `REST_TILT` (0.1 rad) or by less than that apex height
over the face, the remaining bounce series is merged into resting contact: the body is placed
on the floor (a face snapped flat), its normal and rocking velocities set to zero (the energy
this removes is added to that impact's `energy_lost`), and the mode becomes SLIDE or STICK.
The tilt gate stands in for the last rock onto the face, which the model would otherwise
resolve as an endless chatter of corner impacts at a constant tiny speed (a die sliding on a
corner): the face is laid flat a few milliseconds early, moving the die by at most
REST_TILT times the face radius (about 1 mm for a 16 mm die). *Chatter* -- an impact whose
incoming normal speed is below `rest_speed` within 2 rest_speed / g of the previous impact,
i.e. a point in continuous contact on an edge, a corner or a coin's rim -- is laid on its
lowest face whatever the tilt: continuous point contact (pivoting on an edge, a coin rolling
on its rim) is not modelled, and this ends it with the outcome it leads to for a die (the
face below) at the cost of skipping the final fall; the energy it removes is reported in
`energy_lost`. The time at which
the merged series would have ended for a point bouncing on a flat floor, t + 2 u' / (g (1 - e)),
is recorded as `ImpactRecord.rest_time` (for a dropped ball: t1 (1 + e) / (1 - e) exactly).
Between that impact and `rest_time` the trajectory's height differs from the exact bounce by
at most u'^2 / (2 g).

**Not modelled:** continuous contact on an edge, a corner or a rim (pivoting, a coin rolling
on its rim: chatter ends it as above), lift-off from resting contact, rolling resistance, the
Painleve paradox (the energy guard falls back to a frictionless impulse instead of jamming).

**Differentiation.** Segments are restarted from the post-impact state at the located event
time, so gradients include the shift of the impact time (the saltation correction) through
the root finder; reverse mode works with the default adjoint, forward mode needs
`adjoint=diffrax.ForwardMode()`. The segment loop is a `lax.scan` of fixed length
(max_impacts + 4), so it vmaps (members bounce at different times and counts; finished
members run empty segments) and reverse-differentiates.
"""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._checks import is_concrete
from ._dynamics import accelerations, vector_field
from ._invariants import energy
from ._quaternion import (
    _safe_norm,
    axis_angle_to_quat,
    quat_multiply,
    quat_normalize,
    quat_to_matrix,
    skew,
)
from ._results import RESULTS
from ._state import State

FLIGHT, SLIDE, STICK = 0, 1, 2


def _quat_rate(quat, omega):
    """q_dot = 1/2 q (x) (0, w_body)."""
    return 0.5 * quat_multiply(quat, jnp.concatenate([jnp.zeros_like(omega[..., :1]), omega], -1))


_SWEEPS = 2
REST_TILT = 0.1  # rad: a box or cylinder this close to flat, chattering, is laid on its face
DEFAULT_MAX_IMPACTS = 64
DEFAULT_REST_SPEED = 1e-2
SLIP_STOP_FRACTION = 1e-3  # SLIDE ends when |slip| < SLIP_STOP_FRACTION * rest_speed


class ImpactRecord(eqx.Module):
    """The impacts of one trajectory (leading axis: impact slot, `max_impacts` long).

    **Fields:**

    - `time`: impact times (s); `inf` in unused slots.
    - `point`: world position (m) of the contact point first touched (the lowest candidate).
    - `impulse`: total impulse (N s, world frame) the floor gave the body at that impact
      (the sum over all simultaneous contacts).
    - `normal_speed`: incoming normal speed (m/s, > 0 when approaching) of that contact point.
    - `energy_lost`: kinetic + potential energy (J) lost at that impact (>= 0; includes what
      was removed when the body was placed into resting contact).
    - `count`: number of impacts recorded.
    - `rest_time`: time (s) at which the body came to rest on the floor (the end of the merged
      Zeno series, see the module docstring), `inf` if it did not.
    """

    time: jax.Array
    point: jax.Array
    impulse: jax.Array
    normal_speed: jax.Array
    energy_lost: jax.Array
    count: jax.Array
    rest_time: jax.Array

    @property
    def valid(self) -> jax.Array:
        """Mask of the used slots."""
        return jnp.arange(self.time.shape[-1]) < self.count[..., None]


def _where(c, a, b):
    return jax.tree.map(lambda x, y: jnp.where(c, x, y), a, b)


def _inverse_world_inertia(body, R):
    return R @ jnp.linalg.inv(body.inertia_matrix) @ R.T


def _effective_inverse_mass(mass, inv_inertia_world, r):
    """K with (change of contact-point velocity) = K (impulse): 1/m - [r]x I_w^-1 [r]x."""
    S = skew(r)
    return jnp.eye(3, dtype=r.dtype) / mass - S @ inv_inertia_world @ S


def _apply_impulse(body, state, R, inv_iw, r, j):
    """The state after impulse j (N s, world) at offset r (m, world) from the mass centre;
    R = R(q), inv_iw the world-frame inverse inertia."""
    vel = state.vel + j / body.mass
    omega = R.T @ (R @ state.omega + inv_iw @ jnp.cross(r, j))
    return State(state.pos, state.quat, vel, omega)


def impact_map(body, state: State, point, restitution, friction=0.0):
    """Newton's impact law with Coulomb friction at one contact point on the floor (normal +z).

    **Arguments:**

    - `body`: the `RigidBody` (mass, inertia about the mass centre, body axes).
    - `state`: the `State` just before the impact (unit quaternion, body-frame omega).
    - `point`: contact point A relative to the mass centre, world frame (m), shape (3,).
    - `restitution`: e in [0, 1]: u'_n = -e u_n for the contact point's normal velocity.
    - `friction`: Coulomb coefficient mu >= 0: the tangential impulse obeys |j_t| <= mu j_n.

    **Returns:** `(state_after, impulse, energy_lost)`: impulse in N s (world), kinetic energy
    lost (J, >= 0). If the contact point is not approaching (u_n >= 0) nothing changes.
    The rule (stick, else slide, else frictionless; never an energy gain) is in the module
    docstring.
    """
    dtype = state.vel.dtype
    e = jnp.asarray(restitution, dtype)
    mu = jnp.asarray(friction, dtype)
    r = jnp.asarray(point, dtype)
    R = quat_to_matrix(state.quat)
    inv_iw = _inverse_world_inertia(body, R)
    w = R @ state.omega
    u = state.vel + jnp.cross(w, r)
    un = u[2]
    K = _effective_inverse_mass(body.mass, inv_iw, r)
    ez = jnp.array([0.0, 0.0, 1.0], dtype)
    zero = jnp.zeros(3, dtype)

    def gain(j):  # kinetic energy change j.(u + u')/2
        return 0.5 * jnp.dot(j, 2 * u + K @ j)

    target = ez * (-e * un)
    j_stick = jnp.linalg.solve(K, target - u)
    stick_ok = (_safe_norm(j_stick[:2]) <= mu * j_stick[2]) & (gain(j_stick) <= 0)
    ut = u * jnp.array([1.0, 1.0, 0.0], dtype)
    slip = _safe_norm(ut)
    s_hat = ut / jnp.where(slip > 0, slip, 1.0)
    d = ez - mu * s_hat
    den = (K @ d)[2]
    j_slide = -(1 + e) * un / jnp.where(den > 0, den, 1.0) * d
    slide_ok = (den > 0) & (gain(j_slide) <= 0)
    j_free = -(1 + e) * un / K[2, 2] * ez
    j = jnp.where(stick_ok, j_stick, jnp.where(slide_ok, j_slide, j_free))
    j = jnp.where(un < 0, j, zero)
    lost = -gain(j)
    return _apply_impulse(body, state, R, inv_iw, r, j), j, lost


def _unit(state):
    return State(state.pos, quat_normalize(state.quat), state.vel, state.omega)


def _contact_offsets(shape, state):
    """World offsets (K, 3) of the contact candidates from the mass centre."""
    R = quat_to_matrix(state.quat)
    return shape.contact_candidates(state.quat) @ R.T


def _normal_gravity(scene, t, state):
    """g_n > 0: the downward acceleration of the mass centre from the forces alone."""
    acc, _ = accelerations(t, state, scene)
    return -acc[2]


# ----------------------------------------------------------------------------- contact modes


def _contact_force_terms(t, state, scene, r):
    body = scene.body
    acc, omega_dot = accelerations(t, state, scene)
    R = quat_to_matrix(state.quat)
    alpha = R @ omega_dot
    inv_iw = _inverse_world_inertia(body, R)
    K = _effective_inverse_mass(body.mass, inv_iw, r)
    return acc, alpha, R, inv_iw, K


def _round_rates(t, state, scene, mode):
    """A sphere in point contact (contact offset r = -radius e_z, fixed in the world)."""
    body, mu = scene.body, scene.floor.friction
    r = _contact_offsets(body.shape, state)[0]
    acc, alpha, R, inv_iw, K = _contact_force_terms(t, state, scene, r)
    b = acc + jnp.cross(alpha, r)  # d/dt (v + w x r) without contact force
    w = R @ state.omega
    s = (state.vel + jnp.cross(w, r)) * jnp.array([1.0, 1.0, 0.0], r.dtype)
    slip = _safe_norm(s)
    d = jnp.array([0.0, 0.0, 1.0], r.dtype) - mu * s / jnp.where(slip > 0, slip, 1.0)
    den = (K @ d)[2]
    f_slide = -b[2] / jnp.where(den != 0, den, 1.0) * d
    f_stick = -jnp.linalg.solve(K, b)
    f = jnp.where(mode == STICK, f_stick, f_slide)
    a = (acc + f / body.mass) * jnp.array([1.0, 1.0, 0.0], r.dtype)
    omega_dot = R.T @ (alpha + inv_iw @ jnp.cross(r, f))
    return State(
        state.vel * jnp.array([1.0, 1.0, 0.0], r.dtype),
        _quat_rate(state.quat, state.omega),
        a,
        omega_dot,
    )


def _face_gyration_radius(body, R):
    Jw = R @ body.inertia_matrix @ R.T
    return jnp.sqrt(Jw[2, 2] / body.mass)


def _face_slip(body, state):
    R = quat_to_matrix(state.quat)
    rho = _face_gyration_radius(body, R)
    w = R @ state.omega
    return jnp.stack([state.vel[0], state.vel[1], rho * w[2]])


def _face_rates(t, state, scene, mode):
    """A box or cylinder lying on a face: planar sliding (ellipsoidal limit surface) or rest."""
    body, mu = scene.body, scene.floor.friction
    acc, omega_dot = accelerations(t, state, scene)
    R = quat_to_matrix(state.quat)
    rho = _face_gyration_radius(body, R)
    s = _face_slip(body, state)
    slip = _safe_norm(s)
    s_hat = s / jnp.where(slip > 0, slip, 1.0)
    normal = jnp.maximum(-acc[2], 0.0)  # N / m
    a = jnp.stack(
        [acc[0] - mu * normal * s_hat[0], acc[1] - mu * normal * s_hat[1], jnp.zeros_like(acc[2])]
    )
    alpha_z = (R @ omega_dot)[2] - mu * normal / rho * s_hat[2]
    alpha = jnp.stack([jnp.zeros_like(alpha_z), jnp.zeros_like(alpha_z), alpha_z])
    vel = state.vel * jnp.array([1.0, 1.0, 0.0], acc.dtype)
    sliding = State(vel, _quat_rate(state.quat, state.omega), a, R.T @ alpha)
    rest = jax.tree.map(jnp.zeros_like, sliding)
    return _where(mode == STICK, rest, sliding)


def _contact_slip(scene, state):
    """The slip vector whose zero ends SLIDE."""
    shape = scene.body.shape
    if shape.rest_faces() is None:
        r = _contact_offsets(shape, state)[0]
        w = quat_to_matrix(state.quat) @ state.omega
        return (state.vel + jnp.cross(w, r)) * jnp.array([1.0, 1.0, 0.0], r.dtype)
    return _face_slip(scene.body, state)


def _zero_slip(scene, state):
    """Remove the contact's slip: a box or cylinder on a face stops; a sphere gets the
    tangential impulse at its contact point that brings the slip to zero (what Coulomb
    friction would deliver over the last instant of sliding)."""
    body = scene.body
    if body.shape.rest_faces() is not None:
        z = jnp.zeros_like(state.vel)
        return State(state.pos, state.quat, z, z)
    r = _contact_offsets(body.shape, state)[0]
    R = quat_to_matrix(state.quat)
    inv_iw = _inverse_world_inertia(body, R)
    K = _effective_inverse_mass(body.mass, inv_iw, r)
    s = _contact_slip(scene, state)
    j_t = jnp.linalg.solve(K[:2, :2], -s[:2])
    j = jnp.concatenate([j_t, jnp.zeros_like(j_t[:1])])
    return _apply_impulse(body, state, R, inv_iw, r, j)


def _rates(t, y, args, scene):
    mode = args[0]
    state = _unit(y)
    contact = _round_rates if scene.body.shape.rest_faces() is None else _face_rates
    flight = vector_field(t, y, scene)
    return jax.lax.cond(mode == FLIGHT, lambda: flight, lambda: contact(t, state, scene, mode))


def _event_value(t, y, args, scene):
    mode, slip0_dir, dist_shift, slip_stop = args
    state = _unit(y)
    floor = scene.floor
    dist = scene.body.shape.floor_distance(state.pos, state.quat, floor.height) - dist_shift
    s = _contact_slip(scene, state)
    slip = jnp.minimum(jnp.dot(s, slip0_dir), _safe_norm(s) - slip_stop)
    return jnp.where(mode == FLIGHT, dist, jnp.where(mode == SLIDE, slip, jnp.ones_like(dist)))


# ----------------------------------------------------------------------------- maps at events


def _resolve_impact(scene, t, state, contact_tol, rest_speed, t_last=-jnp.inf):
    """Impulses at all touching candidates, then the rest decision (`t_last`: the previous
    impact's time, to tell chatter from a first touch).

    Returns (state, mode, point, impulse, normal_speed, energy_lost, rest_time).
    """
    body, floor = scene.body, scene.floor
    shape = body.shape
    e, mu = floor.restitution, floor.friction
    dtype = state.vel.dtype
    state = _unit(state)
    e_before = energy(scene, state)
    pos_before = state.pos
    offsets = _contact_offsets(shape, state)
    heights = state.pos[2] + offsets[:, 2] - floor.height
    i0 = jnp.argmin(heights)
    R = quat_to_matrix(state.quat)
    r0 = offsets[i0]
    u_in = (state.vel + jnp.cross(R @ state.omega, r0))[2]
    total = jnp.zeros(3, dtype)
    order = [None] + [i for _ in range(_SWEEPS) for i in range(offsets.shape[0])]
    for i in order:
        r = r0 if i is None else offsets[i]
        touching = True if i is None else heights[i] <= contact_tol
        new, j, _ = impact_map(body, state, r, e, mu)
        state = _where(touching, new, state)
        total = total + jnp.where(touching, j, jnp.zeros_like(j))
    R = quat_to_matrix(state.quat)
    w = R @ state.omega
    u_out = (state.vel + jnp.cross(w, r0))[2]
    g_n = _normal_gravity(scene, t, state)
    has_gravity = g_n > 0
    g_safe = jnp.where(has_gravity, g_n, 1.0)
    rest_height = rest_speed**2 / (2 * g_safe)
    faces = shape.rest_faces()
    if faces is None:
        slow = u_out < rest_speed
        pos = state.pos.at[2].add(-heights[i0])
        settled = State(pos, state.quat, state.vel.at[2].set(0.0), state.omega)
    else:
        normals, face_offsets, radii = faces
        nw = normals @ R.T
        down = -nw[:, 2]
        f = jnp.argmax(down)
        n_f, size = nw[f], radii[f]
        tilt = _safe_norm(n_f[:2])
        w_tip = w - jnp.dot(w, n_f) * n_f  # turning the face over (spin about it is not)
        rock = jnp.abs(state.vel[2]) + _safe_norm(w_tip) * size
        # chatter: the contact point is still touching the floor and hits it again within
        # the flight time of a rest_speed bounce (continuous contact on an edge, a corner or
        # the rim, resolved as ever smaller impacts): it is laid on its lowest face
        chatter = (-u_in < rest_speed) & (t - t_last < 2 * rest_speed / g_safe)
        slow = chatter | ((rock < rest_speed) & ((tilt * size < rest_height) | (tilt < REST_TILT)))
        target = jnp.array([0.0, 0.0, -1.0], dtype)
        axis = jnp.cross(n_f, target)
        angle = jnp.arctan2(_safe_norm(axis), jnp.dot(n_f, target))
        quat = quat_normalize(quat_multiply(axis_angle_to_quat(axis, angle), state.quat))
        pos = state.pos.at[2].set(floor.height + face_offsets[f])
        w_flat = w * jnp.array([0.0, 0.0, 1.0], dtype)
        settled = State(pos, quat, state.vel.at[2].set(0.0), quat_to_matrix(quat).T @ w_flat)
    settle = slow & has_gravity & (e < 1)
    slip = _contact_slip(scene, settled)
    sliding = _safe_norm(slip) > SLIP_STOP_FRACTION * rest_speed
    settled = _where(sliding, settled, _zero_slip(scene, settled))
    state = _where(settle, settled, state)
    mode = jnp.where(settle, jnp.where(sliding, SLIDE, STICK), FLIGHT)
    zeno = 2 * jnp.maximum(u_out, 0.0) / (g_safe * jnp.where(e < 1, 1 - e, 1.0))
    rest_time = jnp.where(settle, t + zeno, jnp.inf)
    lost = e_before - energy(scene, state)
    point = pos_before + r0  # world contact point
    return state, mode, point, total, -u_in, lost, rest_time


# ----------------------------------------------------------------------------- the driver


def _check_scene(scene):
    if scene.body.shape is None:
        raise ValueError(
            "a scene with a floor needs a body shape (Sphere, Box or Cylinder) for contact"
        )


def simulate_with_impacts(
    scene,
    state0: State,
    ts,
    *,
    solver,
    stepsize_controller,
    adjoint,
    atol,
    dt0,
    max_steps,
    throw,
    max_impacts: int = DEFAULT_MAX_IMPACTS,
    rest_speed: float = DEFAULT_REST_SPEED,
    contact_tol: float | None = None,
    event_rtol: float | None = None,
    event_atol: float | None = None,
):
    """`simulate` for a scene with a floor (called by `jaxrb.simulate`, which resolves the
    solver, step-size controller and adjoint defaults); see the module docstring.

    Extra keyword arguments (beyond `simulate`'s):

    - `max_impacts`: static size of the impact record and bound on the number of impacts;
      reaching it before `ts[-1]` gives `RESULTS.max_impacts_reached`.
    - `rest_speed`: outgoing normal speed (m/s) below which the bounce series is merged into
      resting contact (default 1e-2); 1e-3 of it is the slip (m/s) at which sliding
      contact ends.
    - `contact_tol`: distance (m) under which a contact candidate counts as touching at an
      impact (simultaneous contacts); default 100 * atol.
    - `event_rtol`, `event_atol`: tolerances (s) of the bisection on the event time; default
      1e-12 in float64, 64 machine epsilons (about 8e-6) in float32.

    **Returns:** a `Trajectory` whose `impacts` is an `ImpactRecord`.
    """
    _check_scene(scene)
    if isinstance(max_impacts, bool) or not isinstance(max_impacts, int) or max_impacts < 1:
        raise ValueError(f"max_impacts must be a Python int >= 1, got {max_impacts!r}")
    if contact_tol is None:
        contact_tol = 100 * atol
    floor = scene.floor
    for name, x in (("restitution", floor.restitution), ("friction", floor.friction)):
        if is_concrete(x) and not np.all(np.isfinite(np.asarray(x))):
            raise ValueError(f"floor {name} must be finite, got {x}")
    if is_concrete(floor.restitution) and not np.all(
        (np.asarray(floor.restitution) >= 0) & (np.asarray(floor.restitution) <= 1)
    ):
        raise ValueError(f"floor restitution must be in [0, 1], got {floor.restitution}")
    if is_concrete(floor.friction) and np.any(np.asarray(floor.friction) < 0):
        raise ValueError(f"floor friction must be >= 0, got {floor.friction}")
    ts = jnp.asarray(ts)
    state0 = jax.tree.map(lambda x: jnp.asarray(x, ts.dtype), state0)
    event_tol = max(1e-12, 64 * float(jnp.finfo(ts.dtype).eps))
    event_rtol = event_tol if event_rtol is None else event_rtol
    event_atol = event_tol if event_atol is None else event_atol
    if all(is_concrete(x) for x in (*jax.tree.leaves(state0), *jax.tree.leaves(scene))):
        d0 = float(
            scene.body.shape.floor_distance(state0.pos, quat_normalize(state0.quat), floor.height)
        )
        if d0 < -contact_tol:
            raise ValueError(
                f"the body starts below the floor: its lowest point is {-d0:.3g} m under the "
                "floor plane"
            )
    return _simulate_impacts(
        scene,
        state0,
        ts,
        solver,
        stepsize_controller,
        adjoint,
        dt0,
        max_steps,
        throw,
        max_impacts,
        rest_speed,
        contact_tol,
        event_rtol,
        event_atol,
    )


@eqx.filter_jit
def _simulate_impacts(
    scene,
    state0,
    ts,
    solver,
    stepsize_controller,
    adjoint,
    dt0,
    max_steps,
    throw,
    max_impacts,
    rest_speed,
    contact_tol,
    event_rtol,
    event_atol,
):
    from ._simulate import Trajectory, input_result

    dtype = ts.dtype
    floor, shape = scene.floor, scene.body.shape
    t_end = ts[-1]
    T = ts.shape[0]
    y0 = _unit(state0)
    result = input_result(scene, state0, ts)
    d0 = shape.floor_distance(y0.pos, y0.quat, floor.height)
    result = RESULTS.where(
        (result == RESULTS.successful) & (d0 < -contact_tol), RESULTS.starts_below_floor, result
    )

    M = max_impacts
    records = ImpactRecord(
        time=jnp.full(M, jnp.inf, dtype),
        point=jnp.zeros((M, 3), dtype),
        impulse=jnp.zeros((M, 3), dtype),
        normal_speed=jnp.zeros(M, dtype),
        energy_lost=jnp.zeros(M, dtype),
        count=jnp.array(0),
        rest_time=jnp.array(jnp.inf, dtype),
    )

    def record(records, do, t, point, impulse, un, lost, rest_time):
        k = jnp.minimum(records.count, M - 1)

        def put(buf, val):
            return buf.at[k].set(jnp.where(do, val, buf[k]))

        return ImpactRecord(
            time=put(records.time, t),
            point=put(records.point, point),
            impulse=put(records.impulse, impulse),
            normal_speed=put(records.normal_speed, un),
            energy_lost=put(records.energy_lost, lost),
            count=records.count + do.astype(records.count.dtype),
            rest_time=jnp.where(do & jnp.isfinite(rest_time), rest_time, records.rest_time),
        )

    def after_event(t, y, mode, records, event, done):
        """Maps at an event; returns (y, mode, records, too_many)."""
        is_impact = event & (mode == FLIGHT)
        too_many = is_impact & (records.count >= M)
        do = is_impact & ~too_many
        t_last = jnp.where(
            records.count > 0, records.time[jnp.maximum(records.count - 1, 0)], -jnp.inf
        )
        yi, mode_i, point, impulse, un, lost, rest_time = _resolve_impact(
            scene, t, y, contact_tol, rest_speed, t_last
        )
        records = record(records, do, t, point, impulse, un, lost, rest_time)
        is_stop = event & (mode == SLIDE)
        y = _where(do, yi, _where(is_stop, _zero_slip(scene, y), y))
        mode = jnp.where(do, mode_i, jnp.where(is_stop, STICK, mode))
        return y, mode, records, too_many

    def slip0_and_shift(y):
        y = _unit(y)
        slip0 = _contact_slip(scene, y)
        slip0_dir = slip0 / jnp.maximum(_safe_norm(slip0), jnp.finfo(dtype).tiny)
        d = shape.floor_distance(y.pos, y.quat, floor.height)
        shift = jnp.where(d > 0, 0.0, d - 1e-12)
        return slip0_dir, shift

    # a body starting in contact (on the floor, approaching or at rest) is resolved at ts[0]
    start_touch = (d0 <= contact_tol) & (result == RESULTS.successful)
    y, mode, records, _ = after_event(
        ts[0], y0, jnp.array(FLIGHT), records, start_touch, jnp.array(False)
    )

    term = dfx.ODETerm(lambda t, y, args: _rates(t, y, args, scene))
    event = dfx.Event(
        # in JAX's default float dtype: diffrax compares it with a Python float internally,
        # which fails for a float32 scene when float64 is enabled
        lambda t, y, args, **kw: _event_value(t, y, args, scene).astype(jnp.result_type(float)),
        root_finder=optx.Bisection(
            rtol=event_rtol, atol=event_atol, flip="detect", expand_if_necessary=True
        ),
        direction=False,
    )
    buffer = jax.tree.map(lambda x: jnp.zeros((T,) + x.shape, dtype), y0)
    carry0 = dict(
        t=ts[0],
        y=y,
        mode=mode,
        done=result != RESULTS.successful,
        records=records,
        buffer=buffer,
        filled=jnp.zeros(T, bool),
        result=result,
        num_steps=jnp.array(0),
    )

    def segment(carry, _):
        done, mode, y = carry["done"], carry["mode"], carry["y"]
        t0 = jnp.where(done, t_end, carry["t"])
        slip0_dir, shift = slip0_and_shift(y)
        sol = dfx.diffeqsolve(
            term,
            solver,
            t0=t0,
            t1=t_end,
            dt0=dt0,
            y0=y,
            args=(mode, slip0_dir, shift, jnp.asarray(SLIP_STOP_FRACTION * rest_speed, dtype)),
            saveat=dfx.SaveAt(
                subs=[dfx.SubSaveAt(ts=jnp.clip(ts, t0, t_end)), dfx.SubSaveAt(t1=True)]
            ),
            stepsize_controller=stepsize_controller,
            adjoint=adjoint,
            max_steps=max_steps,
            event=event,
            throw=False,
        )
        ys_seg = sol.ys[0]
        t_stop = sol.ts[1][0]
        y_stop = jax.tree.map(lambda x: x[0], sol.ys[1])
        ev = jnp.asarray(sol.event_mask) & ~done
        res = RESULTS.promote(sol.result)
        failed = ~done & (res != RESULTS.successful) & (res != RESULTS.event_occurred)
        filled = carry["filled"]
        owned = ~filled & ~done & (ts >= t0) & ((ts < t_stop) | (~ev & (ts <= t_stop)))
        buffer = jax.tree.map(
            lambda b, s: jnp.where(owned.reshape((T,) + (1,) * (b.ndim - 1)), s, b),
            carry["buffer"],
            ys_seg,
        )
        y_new, mode_new, records, too_many = after_event(
            t_stop, y_stop, mode, carry["records"], ev, done
        )
        result = carry["result"]
        result = RESULTS.where(failed & (result == RESULTS.successful), res, result)
        result = RESULTS.where(
            too_many & (result == RESULTS.successful), RESULTS.max_impacts_reached, result
        )
        new = dict(
            t=jnp.where(done, carry["t"], t_stop),
            y=_where(done, y, y_new),
            mode=jnp.where(done, mode, mode_new),
            done=done | ~ev | failed | too_many,
            records=records,
            buffer=buffer,
            filled=filled | owned,
            result=result,
            num_steps=carry["num_steps"] + jnp.where(done, 0, sol.stats["num_accepted_steps"]),
        )
        return new, None

    carry, _ = jax.lax.scan(segment, carry0, None, length=M + 4)
    result = carry["result"]
    result = RESULTS.where(
        ~carry["done"] & (result == RESULTS.successful), RESULTS.max_impacts_reached, result
    )
    last = carry["y"]
    filled = carry["filled"]
    raw = jax.tree.map(
        lambda b, end: jnp.where(filled.reshape((T,) + (1,) * (b.ndim - 1)), b, end[None]),
        carry["buffer"],
        last,
    )
    drift = jnp.max(jnp.where(filled, jnp.abs(jnp.linalg.norm(raw.quat, axis=-1) - 1), 0.0))
    states = State(raw.pos, quat_normalize(raw.quat), raw.vel, raw.omega)
    traj = Trajectory(
        ts=ts,
        states=states,
        result=result,
        quat_norm_drift=drift,
        num_steps=carry["num_steps"],
        impacts=carry["records"],
    )
    if throw:
        traj = result.error_if(traj, result != RESULTS.successful)
    return traj
