"""What happens at an event (docs/contact.md, section 5): the touching set, the impact (all
touching points at once), the limit of a bounce series, the next mode, and the projection."""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._dynamics import accelerations
from .._invariants import energy
from .._state import State
from ._events import COP, JUNCTION
from ._impact_law import (
    FRICTIONLESS,
    HELD,
    NEWTON,
    PLASTIC,
    VARIANTS,
    ImpactOutcome,
    impact_problem,
    solve_variant,
    variant_parameters,
)
from ._modes import (
    FACE,
    CandidateTable,
    Mode,
    cross,
    geometry,
    no_derivative,
    only_where_needed,
    point_coefficients,
    point_gaps,
    solve_mode,
    tree_index,
    tree_where,
    tree_zeros,
    unit_state,
)
from ._projection import project
from ._resting import resting_points, touching_points
from ._select import select_mode

# the order in which `at_event` solves the impact variants: each one's need is known from
# those before it
SOLVING_ORDER = (NEWTON, FRICTIONLESS, PLASTIC, HELD)


class EventOutcome(eqx.Module):
    """The state and mode after an event, and what happened there.

    `impact`: whether a touching point approached (an impact); then `impulse` (N s, world),
    `point` (m, world), `speed` (largest approach speed, m/s) and `energy_lost` (J) describe
    it. `merged`: the bounce series was replaced by its limit, which would have ended at
    `rest_time`. `guarded`: the frictionless impulse replaced one that would add energy.
    `inconsistent`: no candidate mode met every condition. `painleve`: because a sliding
    contact's normal problem has no solution (the Painlevé paradox); `ambiguous`: it had two,
    and the contact lifting off was taken. `energy_rise` (J, >= 0) and `penetration` (m,
    >= 0) are for the log.
    """

    state: State
    mode: Mode
    impact: jax.Array
    impulse: jax.Array
    point: jax.Array
    speed: jax.Array
    energy_lost: jax.Array
    merged: jax.Array
    rest_time: jax.Array
    guarded: jax.Array
    inconsistent: jax.Array
    painleve: jax.Array
    ambiguous: jax.Array
    energy_rise: jax.Array
    penetration: jax.Array


def _put(stacked, one, k):
    # a dynamic slice, not a scatter: XLA's CPU backend compiles a loop without scatters as
    # one kernel
    return jax.lax.dynamic_update_index_in_dim(stacked, one, k, 0)


def _kinetic(body, state):
    return 0.5 * body.mass * state.vel @ state.vel + 0.5 * state.omega @ (
        body.inertia_matrix @ state.omega
    )


def at_event(t, y: State, mode: Mode, trigger, scene, model, tol, live=True) -> EventOutcome:
    """Apply the maps of an event at time `t` to the state `y` reached in `mode`; `trigger`
    is the index of the condition that ended the segment (-1: the start of the run).
    `live`: whether the outcome is used (False: a finished member of a batch, for which the
    impact law and the searches for sliding directions are skipped)."""
    table = CandidateTable(model)
    body = scene.body
    e = scene.floor.restitution
    state = unit_state(y)
    dtype = state.pos.dtype
    energy0 = energy(scene, state)
    geom = geometry(state, scene, model, mode.seed)
    flat = jnp.asarray(model.flat_points)
    touching = touching_points(geom, model, mode, tol)
    # the impact points (a coin's caps: rings of rim points) and which of them touch; on a
    # surface of several parts they are the contact points, each with its part's frame
    several = scene.floor.parts > 1
    down = geom.n @ geom.R if several else geom.R.T @ geom.n[0]
    body_points, ring = model.impact_points(down, mode.seed)
    points = body_points @ geom.R.T
    Q = points.shape[0]
    frames = (geom.n, geom.t1, geom.t2) if several else geom.frame_of(0)
    frames = tuple(jnp.broadcast_to(e, (Q, 3)) for e in frames)
    mu = point_coefficients(scene, model)[0]
    mu = mu if several else jnp.broadcast_to(mu[0], (Q,))
    points_gap = point_gaps(scene.floor, state.pos + points)
    points_rate = jnp.sum((state.vel + cross(geom.w, points)) * frames[0], axis=-1)
    hitting = points_gap <= jnp.where(ring, tol.flat, tol.contact)
    approaching = hitting & (points_rate < -tol.slip_stop)
    # (for a finished member, `live` False, nothing is applied: its outcome is discarded)
    impact = jnp.any(approaching) & live
    speed = jnp.max(jnp.where(approaching, -points_rate, 0.0))
    penetration = jnp.maximum(-jnp.min(jnp.where(flat, jnp.inf, geom.gap)), 0.0)

    # the impact: Newton-Coulomb unless it adds energy, then the frictionless impulse unless
    # that adds energy too, then the plastic one; where the bounces that follow would merge,
    # their series' limit. Each solved only where it is used (a loop over the variants, so
    # that the impact law is traced once)
    no_problem = lambda: tree_zeros(  # noqa: E731
        jax.eval_shape(impact_problem, state, geom, points, hitting, scene, frames, mu)
    )
    problem = only_where_needed(
        impact,
        lambda: impact_problem(state, geom, points, hitting, scene, frames, mu),
        no_problem,
    )
    kinetic0 = _kinetic(body, state)
    allowed = 1e-12 * kinetic0 + jnp.finfo(dtype).tiny
    acc0, _ = accelerations(t, state, scene)
    # > 0: the forces press the body onto the surface where it approaches fastest
    fastest = jnp.argmax(jnp.where(approaching, -points_rate, -jnp.inf))
    pressing = -(acc0 @ frames[0][fastest])

    def outcome_of(variants):
        """The impact's outcome from the variants solved so far (zeros where not solved),
        whether Newton's law and then the frictionless one would add energy, whether the
        bounces that follow merge, and the fastest leaving speed."""
        gains = lambda out: _kinetic(body, out.state) - kinetic0 > allowed  # noqa: E731
        newton, smooth = tree_index(variants, NEWTON), tree_index(variants, FRICTIONLESS)
        guarded, plastic = gains(newton), gains(smooth)
        smooth = tree_where(plastic, tree_index(variants, PLASTIC), smooth)
        hit = tree_where(guarded, smooth, newton)
        v, w = hit.state.vel, geom.R @ hit.state.omega
        leaving = jnp.sum((v + cross(w, points)) * frames[0], axis=-1)
        bounce = jnp.max(jnp.where(hitting, leaving, 0.0))
        merged = impact & (pressing > 0) & (bounce > tol.slip_stop) & (bounce < tol.rest_speed)
        return hit, guarded, plastic, merged, bounce

    restitution, friction, bilateral = variant_parameters(e, problem.mu)
    no_outcome = ImpactOutcome(
        tree_zeros(state), jnp.zeros(3, dtype), jnp.zeros(3, dtype), jnp.array(False)
    )

    def solve(variants, k):
        _, guarded, plastic, merged, _ = outcome_of(variants)
        rule = {NEWTON: True, FRICTIONLESS: guarded, PLASTIC: guarded & plastic, HELD: merged}
        needed = impact & jnp.stack([rule[v] for v in range(VARIANTS)])[k]
        out = only_where_needed(
            needed,
            lambda: solve_variant(problem, restitution[k], friction[k], bilateral[k], tol),
            lambda: no_outcome,
        )
        return jax.tree.map(lambda all_, one: _put(all_, one, k), variants, out), None

    unsolved = jax.tree.map(lambda x: jnp.stack(VARIANTS * [x]), no_outcome)
    variants, _ = jax.lax.scan(solve, unsolved, jnp.array(SOLVING_ORDER))
    hit, guarded, _, merged, bounce = outcome_of(variants)
    hit = tree_where(merged, tree_index(variants, HELD), hit)
    one_minus_e = jnp.where(e < 1, 1 - e, 1.0)
    rest_time = jnp.where(
        merged, t + 2 * bounce / (jnp.where(pressing > 0, pressing, 1.0) * one_minus_e), jnp.inf
    )
    state = tree_where(impact, hit.state, state)

    # the next mode (a flat cap's rim needs to know where the body tips: the seed)
    if model.needs_seed:
        old = solve_mode(t, *no_derivative((state, mode, scene)), model, tol)
        n, t1, t2 = geom.frame_of(0)  # a face meets a plane: one frame
        couple = geom.R.T @ (old.lam[1] * t1 + old.lam[2] * t2)
        normals, _, _ = model.face_frame()
        tipped = (mode.kind == FACE) & (trigger == model.num_points + COP)
        cop_offset = cross(couple, normals[mode.face])
        down = jax.lax.stop_gradient(geom.R.T @ n)
        seed = model.rim_seed(down, jnp.where(tipped, cop_offset, 0.0), mode.seed)
        mode = eqx.tree_at(lambda m: m.seed, mode, seed)
    # the part of a curved surface the ball now touches: past a junction the other one, else
    # where it is (the next segment keeps to that part's geometry, the `side` of its mode)
    crossed = ~impact & (trigger == model.num_points + JUNCTION)
    region = geom.region  # an impact changes the velocities only: the region before it
    side = jnp.where(crossed, -mode.side, jnp.where(region >= 0, 1.0, -1.0)).astype(dtype)
    mode = eqx.tree_at(lambda m: m.side, mode, side)
    geom = geometry(state, scene, model, mode.seed, mode.side)
    resting, zero_slip = resting_points(touching, geom, model, tol)
    trigger = jnp.where(impact, -1, trigger)
    # the choice of mode is discrete; of its continuous parts (the direction a slide from
    # rest starts in, a flat cap's seed) no derivative is taken: that keeps the reverse pass
    # small, and they matter only while the slip is below the blend speed
    choice = select_mode(
        no_derivative(t),
        *no_derivative((state, geom, mode)),
        trigger,
        no_derivative(scene),
        model,
        table,
        tol,
        resting,
        zero_slip,
        live,
    )
    new_mode = choice.mode
    state = project(state, new_mode, scene, model, tol.slip_stop)
    energy1 = energy(scene, state)
    return EventOutcome(
        state=state,
        mode=new_mode,
        impact=impact,
        impulse=hit.impulse,
        point=hit.point,
        speed=speed,
        energy_lost=energy0 - energy1,
        merged=merged,
        rest_time=rest_time,
        guarded=impact & guarded,
        inconsistent=~choice.consistent | (impact & ~hit.consistent),
        painleve=choice.painleve,
        ambiguous=choice.ambiguous,
        energy_rise=jnp.maximum(energy1 - energy0, 0.0),
        penetration=penetration,
    )
