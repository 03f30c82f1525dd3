"""The conditions that end a contact segment, and the event function diffrax roots.

Every mode has the same fixed list of conditions (docs/contact.md, section 4), unused ones
set to a large value; the event is the first zero of their minimum:

- entries 0..P-1: the gaps (m) of the contact points the mode does not hold (a cap's highest
  rim point: its gap less the flatness tolerance);
- then, per unit mass (m/s^2): the normal force at point a (or the face's), at point b, the
  friction margin at a (mu N - |f_t|; a face: its limit surface), at b, the margin of a
  sticking pair's force along its line; for a sliding point a (or face), b (m/s): its slip
  speed less half the stop speed `slip_stop`, or, for a slide that started from rest, its slip
  along the direction it started in plus half the blend speed, and the slip along the
  direction friction opposes plus 0.3 blend speeds (`slide_end`: they fire when the slip has
  stopped, turned back or is pushed on by friction; a slip that only turns, as a coin's on
  its rim, does not end a segment; a face on a support of three vertices: the slowest
  vertex's slip speed less half the stop speed); and a face's centre-of-pressure margin
  (m/s^2: N/m times the distance inside its support region over its friction radius; on a
  support: the least of its three vertices' normal forces); and on a curved surface whose
  curvature jumps (a rounded cone's tip), the junction margin times the mode's `side` (it
  fires when the ball passes to the other part, so that no step straddles the jump).

Every condition must start positive: diffrax fires on a downward crossing only, so one that
started at or below zero would disarm the whole event (impacts included). A condition that
starts at its boundary (within its tolerance) is therefore shifted, and fires only when it is
violated by more than the tolerance.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._linalg import vecmat
from .._quaternion import _safe_norm
from ._modes import (
    FACE,
    PAIR,
    POINT,
    Solution,
    active_points,
    blend_direction,
    on_pivot,
    on_support,
    point_coefficients,
    support_vertex_b,
    support_vertex_starts,
)

NORMAL_A, NORMAL_B, CONE_A, CONE_B, AXIAL, SLIP_A, SLIP_B, COP, JUNCTION = range(9)
NUM_FORCE_CONDITIONS = 9
UNUSED = 1e30
JUNCTION_TOL = 1e-12  # of the junction margin (a difference of cosines)
# a slide whose slip starts below half its stop speed ends once it falls this share of its
# condition's tolerance (`start_offsets`)
PROMPT = 1e-3
# how far (in blend speeds) friction may push a slide from rest's slip on; above the quarter
# blend speed that is the slip conditions' tolerance, so that the condition starts armed
PUSH = 0.3


def _sqrt_pos(x):
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def force_margins(lam, rows, mode, model, geom, mu) -> jax.Array:
    """The 8 force conditions of `mode` (module docstring) from its multipliers per unit
    mass `lam` (6,) (forces: m/s^2; impulses: m/s), with the slip entries left unused;
    `mu` (P,): the friction coefficient at each contact point."""
    dtype = lam.dtype
    big = jnp.asarray(UNUSED, dtype)
    kind, stick_a, stick_b = mode.kind, mode.stick[0], mode.stick[1]
    mu_a, mu_b = mu[mode.a], mu[mode.b]
    is_pair, is_face = kind == PAIR, kind == FACE
    holds = (kind == POINT) | is_pair | is_face
    both = is_pair & stick_a & stick_b
    cone_point = mu_a * lam[0] - _safe_norm(lam[2:4])
    cone_face = mu_a * lam[0] - _safe_norm(jnp.stack([lam[3], lam[4], lam[5] / rows.rho]))
    cone_a = jnp.where(
        is_face, cone_face, jnp.where(both, mu_a * lam[0] - jnp.abs(lam[2]), cone_point)
    )
    cone_b = jnp.where(both, mu_b * lam[1] - jnp.abs(lam[4]), mu_b * lam[1] - _safe_norm(lam[4:6]))
    # a face turning about a vertex (point b): that vertex's cone, with its share f_b of the
    # support's load
    pivot = on_pivot(mode)
    vertex_forces = rows.support_map @ lam[:3]
    pivot_force = vertex_forces @ support_vertex_b(mode).astype(dtype)
    cone_b = jnp.where(pivot, mu_b * pivot_force - _safe_norm(lam[3:5]), cone_b)
    axial = (
        _sqrt_pos((mu_a * lam[0]) ** 2 - lam[2] ** 2)
        + _sqrt_pos((mu_b * lam[1]) ** 2 - lam[4] ** 2)
        - jnp.abs(lam[3])
    )
    _, t1, t2 = geom.frame_of(0)  # a face meets a plane: one frame
    couple_body = vecmat(lam[1] * t1 + lam[2] * t2, geom.R)
    cop = model.cop_margin(mode.face, lam[0], couple_body) / rows.rho
    cop = jnp.where(on_support(mode), jnp.min(vertex_forces), cop)
    return jnp.stack(
        [
            jnp.where(holds, lam[0], big),
            jnp.where(is_pair, lam[1], big),
            jnp.where(holds & stick_a, cone_a, big),
            jnp.where((is_pair & stick_b) | pivot, cone_b, big),
            jnp.where(both, axial, big),
            big,
            big,
            jnp.where(is_face, cop, big),
        ]
    )


def slowest_support_vertex(geom, mode) -> jax.Array:
    """The point index of the slowest sliding vertex of a support (`Mode.support`), its
    vertex `b` left out where that one sticks or starts from rest (its slip is watched at
    slot b); any other mode: its point a."""
    vertices = jnp.where(on_support(mode), mode.support, mode.a)
    apart = (on_pivot(mode) | support_vertex_starts(mode)) & support_vertex_b(mode)
    return vertices[jnp.argmin(jnp.where(apart, jnp.inf, _safe_norm(geom.slip[vertices])))]


def slips_as_twist(mode) -> jax.Array:
    """Whether the slip that `mode_slips` watches at slot a is the face's slip twist (a
    face on its limit surface, or sticking) rather than a point's slip."""
    return (mode.kind == FACE) & ~on_support(mode)


def mode_slips(sol: Solution, mode):
    """The slips whose end the slip conditions watch (m/s, world; (2, 3)): at slot a a
    point's slip or a face's slip twist (a support: its slowest vertex's slip), at slot b
    the pair's second point's (a support's vertex starting from rest); whether each slides
    in `mode` (2,); and the points whose slips they are (2,; slot a's is unused where it
    watches a face's twist)."""
    kind, geom = mode.kind, sol.geom
    on_face = slips_as_twist(mode)
    holds = (kind == POINT) | (kind == PAIR) | (kind == FACE)
    points = jnp.stack([slowest_support_vertex(geom, mode), mode.b])
    slips = geom.slip[points]
    slips = slips.at[0].set(jnp.where(on_face, sol.rows.twist, slips[0]))
    sliding_b = ((kind == PAIR) & ~mode.stick[1]) | support_vertex_starts(mode)
    sliding = jnp.stack([holds & ~mode.stick[0], sliding_b])
    return slips, sliding, points


def slide_end(slip, direction, from_rest, tol) -> jax.Array:
    """The condition (m/s) that ends a slide with slip `slip` (a point's, world; a face's
    slip twist): it fires when the slip has stopped. A slide that started from rest in the
    unit direction `direction` (s0), its friction opposing s_f = unit(s + blend s0), has
    stopped when its slip along s0 has passed zero by half the blend speed (friction still
    opposes s0 there), or when friction pushes the slip on: s . s_f below -`PUSH` times the
    blend speed (friction on its cone could then hold the slip near zero, a creep that no
    other condition ends); the next mode is chosen again. Any other slide has stopped when
    its speed has fallen to half the stop speed, where the next mode may stick whatever the
    root finder's resolution (a slip that only turns, as a coin's on its rim, does not end
    it)."""
    blend = tol.slip_blend
    turned = slip @ direction + 0.5 * blend
    pushed = slip @ blend_direction(slip, direction, blend) + PUSH * blend
    return jnp.where(from_rest, jnp.minimum(turned, pushed), _safe_norm(slip) - 0.5 * tol.slip_stop)


def conditions(sol: Solution, mode, model, scene, tol) -> jax.Array:
    """The condition vector (P + 8,) of `mode` at the solution's state."""
    dtype = sol.acc.dtype
    big = jnp.asarray(UNUSED, dtype)
    rows, geom = sol.rows, sol.geom
    threshold = jnp.where(jnp.asarray(model.flat_points), tol.flat, 0.0).astype(dtype)
    gaps = jnp.where(active_points(model, mode), big, geom.gap - threshold)
    mu, _, _ = point_coefficients(scene, model)
    force = force_margins(sol.lam / scene.body.mass, rows, mode, model, geom, mu)
    slips, sliding, _ = mode_slips(sol, mode)
    dir_a = jnp.where(mode.kind == FACE, mode.twist_dir, mode.slide_dir[0])
    end_a = slide_end(slips[0], dir_a, mode.from_rest[0], tol)
    end_b = slide_end(slips[1], mode.slide_dir[1], mode.from_rest[1], tol)
    force = force.at[SLIP_A].set(jnp.where(sliding[0], end_a, big))
    force = force.at[SLIP_B].set(jnp.where(sliding[1], end_b, big))
    # the ball passes to another part of a curved surface (its curvature jumps there)
    junction = jnp.where(scene.floor.curved, mode.side * geom.region, big)
    return jnp.concatenate([gaps, force, junction[None]])


def cause_of(trigger, model) -> jax.Array:
    """The `ContactLog.CAUSES` code of condition index `trigger` (-1: the start)."""
    P = model.num_points
    k = trigger - P
    flat = jnp.asarray(model.flat_points)[jnp.clip(trigger, 0, P - 1)]
    return jnp.select(
        [
            trigger < 0,
            (trigger < P) & ~flat,
            trigger < P,
            k <= NORMAL_B,
            k <= AXIAL,
            k <= SLIP_B,
            k == JUNCTION,
        ],
        [0, 1, 2, 3, 4, 5, 7],
        6,
    )


def condition_tolerances(model, tol, dtype) -> jax.Array:
    """Per-condition tolerance (P + 8,): penetration for gaps, force_tol for the force
    conditions, a quarter of the blend speed for the slips."""
    P = model.num_points
    slip = 0.25 * tol.slip_blend
    force = np.array([tol.force] * 5 + [slip, slip] + [tol.force, JUNCTION_TOL])
    return jnp.asarray(np.concatenate([np.full(P, tol.penetration), force]), dtype)


def start_offsets(values0, tolerances, mode, model) -> jax.Array:
    """Shifts making each condition start positive when it starts at its boundary: a
    condition at c0 <= tol fires once it has fallen tol below min(c0, 0). A slide (not
    from rest) whose slip starts already below half the stop speed, which the projection
    at an event can leave (it holds the other points' normal and stopped slips, and moves
    this one's by as much), is over: its condition fires as soon as it falls at all
    (`PROMPT` of its tolerance), where the band would never let it fire."""
    P = model.num_points
    near = values0 <= tolerances
    shift = tolerances + jnp.maximum(-values0, 0.0)
    slides = jnp.zeros(values0.shape, bool)
    slides = slides.at[P + SLIP_A].set(~mode.from_rest[0]).at[P + SLIP_B].set(~mode.from_rest[1])
    over = slides & (values0 < 0)
    shift = jnp.where(over, PROMPT * tolerances - values0, shift)
    return jnp.where(near & (tolerances > 0), shift, 0.0)
