"""Choosing the next mode at an event: enumeration of the candidate modes of the touching
features, each solved and tested against the complementarity conditions (docs/contact.md,
section 3).

The candidates (`CandidateTable.candidates`: those of the resting points) are evaluated a
chunk at a time (vmap within a chunk, a while loop over the chunks that are tested) and the
first consistent one in the table's order is taken: it jits and vmaps.
"""

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np

from .._linalg import solve as small_solve
from .._quaternion import _safe_norm
from ._events import (
    AXIAL,
    CONE_A,
    CONE_B,
    COP,
    NORMAL_A,
    NORMAL_B,
    SLIP_A,
    SLIP_B,
    UNUSED,
    conditions,
)
from ._modes import (
    FACE,
    PAIR,
    POINT,
    active_points,
    blend_direction,
    cross,
    face_twist,
    held_and_sliding,
    inverse_mass_columns,
    on_pivot,
    on_support,
    only_where_needed,
    point_coefficients,
    support_vertex_b,
    support_vertex_starts,
    tree_index,
    tree_where,
    tree_zeros,
    unit_or,
)
from ._options import FORCE_TOL_PER_FORCE

FIXED_POINT_ITERATIONS = 4
DIRECTIONS = 64  # angles scanned for a sliding direction from rest
REFINEMENTS = 10  # regula falsi steps on the chosen bracket
ROOTED = 1e-2  # a refined root's turning rate below this share of its bracket's ends'
NEWTON_ITERATIONS = 8  # for the two directions of a pair whose ends both slide from rest
MAX_NEWTON_STEP = 0.5  # rad


def scan_direction(measure, n, t1, t2, dtype, slack):
    """The direction s (world, unit, in the floor plane) in which a contact at rest starts
    to slide, given `measure(s)` -> (its slip acceleration a_t (3,) when friction opposes s,
    whether the contact forces are then admissible): a_t must be kappa s, kappa >= 0. The
    circle of directions is scanned, the bracket of a root of (a_t x s) . n with the fastest
    admissible slip acceleration along s is refined by regula falsi. A root counts where
    a_t . s >= -`slack` (m/s^2): at the friction cone's edge the slip starts with no
    acceleration at all, and the sign of a_t . s there is roundoff's. Returns (s, found).
    (The impact law finds a lone sliding point's slip after the impact the same way, a_t
    then that slip, m/s.)"""
    step = 2 * jnp.pi / DIRECTIONS

    def at(phi):
        s = jnp.cos(phi) * t1 + jnp.sin(phi) * t2
        a, admissible = measure(s)
        return cross(a, s) @ n, a @ s, admissible

    angle = jnp.arange(DIRECTIONS, dtype=dtype) * step
    turn, along, admissible = jax.vmap(at)(angle)
    nxt, along_nxt, nxt_ok = jnp.roll(turn, -1), jnp.roll(along, -1), jnp.roll(admissible, -1)
    bracket = ((turn <= 0) & (nxt > 0)) | ((turn >= 0) & (nxt < 0))
    # a_t . s may rise above its ends' within a bracket: by at most step^2 / 8 times its
    # second derivative, bounded by the largest |a_t| (as a sinusoid's by its amplitude).
    # Near the cone's edge a_t . s is small at the root and its ends may both be below zero
    reach = step**2 / 8 * jnp.max(jnp.sqrt(turn**2 + along**2))
    bracket = bracket & (jnp.maximum(along, along_nxt) >= -reach)
    # admissible at both ends: where the forces change sign within a bracket they may pass
    # through a pole (the contact problem singular for some direction), and so does the
    # turning rate, which changes sign there without a root. Where no bracket is, one
    # admissible at one end: a root next to which a force passes through zero (a pair's end
    # starting from rest at its cone's edge while the other end's normal force is small),
    # told from a pole once refined (`rooted`)
    good = bracket & admissible & nxt_ok
    one_end = ~jnp.any(good)
    chosen = jnp.where(one_end, bracket & (admissible | nxt_ok), good)
    best = jnp.argmax(jnp.where(chosen, jnp.maximum(along, along_nxt), -jnp.inf))

    def regula_falsi(_, bracket):  # kept inside the bracket; each end: (angle, at(angle))
        lo, hi = bracket
        (phi_lo, f_lo, _, _), (phi_hi, f_hi, _, _) = lo, hi
        mid = (phi_lo * f_hi - phi_hi * f_lo) / jnp.where(f_hi != f_lo, f_hi - f_lo, 1.0)
        mid = jnp.clip(mid, jnp.minimum(phi_lo, phi_hi), jnp.maximum(phi_lo, phi_hi))
        new = (mid, *at(mid))
        left = jnp.sign(new[1]) == jnp.sign(f_lo)
        return tree_where(left, new, lo), tree_where(left, hi, new)

    lo, hi = jax.lax.fori_loop(
        0,
        REFINEMENTS,
        regula_falsi,
        (
            (angle[best], turn[best], along[best], admissible[best]),
            (angle[best] + step, nxt[best], along_nxt[best], nxt_ok[best]),
        ),
    )
    # the end nearer the root, with what was measured there
    phi, turn_root, along_root, admissible_root = tree_where(
        jnp.abs(lo[1]) < jnp.abs(hi[1]), lo, hi
    )
    # refined, a root's turning rate falls far below its bracket's ends'; next to a pole it
    # only grows (as 1 / distance)
    rooted = jnp.abs(turn_root) <= ROOTED * jnp.minimum(jnp.abs(turn[best]), jnp.abs(nxt[best]))
    found = jnp.any(chosen) & (along_root >= -slack) & admissible_root & (rooted | ~one_end)
    return jnp.cos(phi) * t1 + jnp.sin(phi) * t2, found


def newton_directions(measure, seeds, dtype):
    """Two sliding directions from rest at once (the ends of a pair), as angles x = (x_a,
    x_b) in the floor plane: damped Newton (Levenberg-Marquardt, finite-difference Jacobian)
    on the turning rates r(x) = ((a_a x s_a) . n, (a_b x s_b) . n) from each of `seeds`
    (S, 2). `measure(x)` -> (r (2,), a_i . s_i (2,), whether the forces are admissible).
    Returns the angles with the smallest |r| among the admissible ends with a_i . s_i >= 0,
    and whether such a root was found (|r| below 1e-6 of the accelerations' scale)."""
    h = jnp.sqrt(jnp.finfo(dtype).eps)
    probe = jnp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], dtype) * h

    def newton(_, carry):  # (x, the x before it, what was measured there)
        x = carry[0]
        r, along, admissible = jax.vmap(measure)(x + probe)  # probe 0: at x itself
        J = (r[1:] - r[0]).T / h  # J[:, k] = dr / dx_k
        JtJ, g = J.T @ J, J.T @ r[0]
        damping = 1e-10 * jnp.trace(JtJ) + jnp.finfo(dtype).tiny
        a, b, d = JtJ[0, 0] + damping, JtJ[0, 1], JtJ[1, 1] + damping
        step = -jnp.stack([d * g[0] - b * g[1], a * g[1] - b * g[0]]) / (a * d - b * b)
        size = jnp.max(jnp.abs(step))
        x_next = x + step * jnp.minimum(1.0, MAX_NEWTON_STEP / jnp.maximum(size, 1e-300))
        return x_next, x, (r[0], along[0], admissible[0])

    def search(x0):  # a last pass measures the last iterate: the program holds one measure
        shapes = jax.eval_shape(measure, x0)
        unmeasured = tuple(jnp.zeros(m.shape, m.dtype) for m in shapes)
        _, x, measured = jax.lax.fori_loop(0, NEWTON_ITERATIONS + 1, newton, (x0, x0, unmeasured))
        return x, measured

    xs, (r, along, admissible) = jax.vmap(search)(seeds)
    size = jnp.max(jnp.abs(r), axis=1)
    scale = jnp.max(jnp.abs(along), axis=1) + 1.0
    good = admissible & jnp.all(along >= 0, axis=1)
    best = jnp.argmin(jnp.where(good, size / scale, jnp.inf))
    return xs[best], good[best] & (size[best] <= 1e-6 * scale[best])


def point_slip_measure(b, K, mu, n):
    """The `measure` of `scan_direction` for a single point contact at rest, in closed form:
    with the contact point's acceleration a = b + K f under the contact force f = lambda_n
    (n - mu s), lambda_n from n . a = 0 (admissible: lambda_n >= 0). `b` (3,) is the point's
    acceleration without contact force, `K` (3, 3) its Delassus matrix (world)."""

    def measure(s):
        force_dir = n - mu * s
        D = n @ K @ force_dir
        lam = -(n @ b) / jnp.where(D != 0, D, 1.0)
        a = b + lam * (K @ force_dir)
        return a - (a @ n) * n, lam >= 0

    return measure


def stabilisation_offsets(geom, beta):
    """What `relative_accelerations` adds to each point's acceleration (P, 3, world, m/s^2):
    (2 beta g' + beta^2 g) n + beta s. It depends on the state alone."""
    drift = 2 * beta * geom.gap_rate + beta**2 * geom.gap
    return drift[:, None] * geom.n + beta * geom.slip


def relative_accelerations(acc, geom, beta):
    """Point accelerations `acc` (P, 3, world, m/s^2) taken relative to the targets that the
    stabilisation (rate `beta`, 1/s) sets a held contact: the normal part plus 2 beta g' +
    beta^2 g, the slip's part plus beta s (gap g, gap rate g', slip s of each point). A mode's
    forces make these zero on the rows it holds, so its successors' conditions, tested on
    them, hold exactly where its own forces reach their bounds (docs/contact.md, section 3);
    on the constraint manifold (g = g' = 0, no slip) they are the accelerations themselves."""
    return acc + stabilisation_offsets(geom, beta)


class Choice(eqx.Module):
    """The chosen mode, whether it satisfied every condition, and whether the sliding
    contact problem had no solution (`painleve`) or several (`ambiguous`): the Painlevé
    paradox (docs/contact.md, section 3)."""

    mode: object
    consistent: jax.Array
    painleve: jax.Array
    ambiguous: jax.Array


def not_p_matrix(sol, mode, body) -> jax.Array:
    """Whether the normal forces of a point or pair mode respond to themselves the wrong way:
    the matrix that maps the normal forces (with the friction of a sliding contact riding on
    them) to the normal accelerations, the other rows held, is not a P-matrix. Then the
    sliding contact problem has no solution for some free accelerations and two for others
    (the Painlevé paradox). Tested on its inverse, a block of the rows' inverse matrix."""
    rows = sol.rows
    A = rows.J @ inverse_mass_columns(body, sol.geom.R, rows.C).T
    eye = jnp.eye(A.shape[0], dtype=A.dtype)
    A = jnp.where(rows.mask[:, None] & rows.mask[None, :], A, eye)
    Y = jax.vmap(lambda e: small_solve(A, e))(eye[:2])  # Y[k] = A^-1 e_k
    y00, y11, y01, y10 = Y[0, 0], Y[1, 1], Y[1, 0], Y[0, 1]
    single = y00 > 0
    both = (y00 > 0) & (y11 > 0) & (y00 * y11 - y01 * y10 > 0)
    return ~jnp.where(mode.kind == PAIR, both, single)


def unended_starts(old, k):
    """(2,) whether end a / end b of the mode `old` (a point's or a pair's end; a support's
    vertex b) slides from rest, that slide not ended by the event: its condition not the
    event's force condition `k` (the trigger less the number of points), and no impact at
    the event (which changes the slips; `k` < 0 then)."""
    on_points = (old.kind == POINT) | (old.kind == PAIR)
    ends = jnp.stack([on_points, (old.kind == PAIR) | support_vertex_starts(old)])
    ended = jnp.stack([k == SLIP_A, k == SLIP_B])
    return ends & old.from_rest & ~old.stick & ~ended & (k >= 0)


def continued_slides(mode, old, trigger, zero_slip):
    """The ends (a, b) of the candidate `mode` that go on with a slide from rest of the mode
    `old` that the event ended (`trigger` indexes the condition vector): the same point,
    sliding in both, its slip not at rest (`zero_slip`, (P,)), that slide's end not the
    event, and no impact at the event (`trigger` >= 0). Such an end keeps the old slide's
    start direction s0, and with it its friction law (opposing unit(s + blend s0)): the
    slip of a point that goes on sliding is the same function of state across an event
    elsewhere, and so are the candidates' forces and gap accelerations where they meet the
    old mode's at the boundary just reached. Returns ((2,) bool, (2, 3) world directions
    s0, zero where not kept)."""
    old_ends = unended_starts(old, trigger - zero_slip.shape[0])
    old_points = jnp.stack([old.a, old.b])
    points = jnp.stack([mode.a, mode.b])
    ends = jnp.stack([(mode.kind == POINT) | (mode.kind == PAIR), mode.kind == PAIR])
    ends = ends & ~mode.stick & ~zero_slip[points]
    match = (points[:, None] == old_points[None, :]) & old_ends[None, :]  # (candidate, old)
    kept = ends & jnp.any(match, axis=1)
    directions = jnp.where(match[:, :, None], old.slide_dir[None, :, :], 0.0).sum(axis=1)
    return kept, jnp.where(kept[:, None], directions, 0.0)


def _candidate(t, state, geom, mode, scene, model, tol, resting, zero_slip, continued, live):
    """Solve one candidate, finding the directions of any sliding that starts from rest by
    fixed-point iteration (s_hat <- s'(s_hat) / |s'(s_hat)|). Returns (the mode with those
    directions, its margins: all must be >= 0 for it to be consistent). `continued`: the
    ends that go on with a slide from rest and its start directions (`continued_slides`);
    `live`: whether the event's choice is used (False: a finished member of a batch, whose
    searches are skipped)."""
    dtype = state.pos.dtype
    zero3 = jnp.zeros(3, dtype)
    beta = jnp.asarray(tol.stabilisation, dtype)
    twist, _ = face_twist(state, geom, model, mode.face)
    # a support one of whose vertices is at rest (and does not pivot): that vertex, made
    # the mode's point b, starts to slide from rest (`support_vertex_starts`)
    support = on_support(mode)
    vertices = jnp.where(support, mode.support, 0)
    still_vertices = zero_slip[vertices]
    starts = support & ~on_pivot(mode) & (jnp.sum(still_vertices) == 1)
    mode = eqx.tree_at(
        lambda m: (m.b, m.from_rest),
        mode,
        (
            jnp.where(starts, vertices[jnp.argmax(still_vertices)], mode.b),
            mode.from_rest.at[1].set(starts | mode.from_rest[1]),
        ),
    )
    slides_a = ((mode.kind == POINT) | (mode.kind == PAIR)) & ~mode.stick[0]
    rest_a = slides_a & zero_slip[mode.a]
    rest_b = ((mode.kind == PAIR) & ~mode.stick[1] & zero_slip[mode.b]) | starts
    rest_f = (mode.kind == FACE) & ~mode.stick[0] & ~support
    rest_f = rest_f & (jnp.linalg.norm(twist) <= tol.slip_stop)

    # the mode made to stick, and its solution for any sliding directions (at the cost of a
    # 3 x 3 solve each), built side by side. Sliding from rest starts opposite to the
    # friction that sticking would need (exactly so at the cone's boundary, where the slip's
    # acceleration vanishes)
    held, solve = held_and_sliding(t, state, mode, scene, model, tol, geom)
    # `relative_accelerations`, its offsets computed once: the searches below solve many times
    offsets = stabilisation_offsets(geom, beta)
    relative = lambda sol: sol.point_accelerations() + offsets  # noqa: E731
    lam, d = held.lam, held.rows.J[:, :3]
    need_a = lam[2] * d[2] + lam[3] * d[3]
    # (a support's vertex starting from rest: the friction of that vertex as a pivot)
    need_b = jnp.where(starts, lam[3] * d[3] + lam[4] * d[4], lam[4] * d[4] + lam[5] * d[5])
    need_f = jnp.stack([lam[3], lam[4], lam[5] / held.rows.rho])
    # a single point: its sliding direction in closed form (the others: fixed point below)
    rows = held.rows
    keep = np.array([0, 2, 3])  # rows: normal, t1, t2 at point a
    Jp = rows.J[keep]
    Kp = Jp @ inverse_mass_columns(scene.body, geom.R, Jp).T
    frame = jnp.stack(geom.frame_of(mode.a))
    # the point's acceleration without contact force: J u' - K lambda, plus the rows' bias,
    # relative to the stabilisation's targets (`relative_accelerations`)
    u_dot = jnp.concatenate([held.acc, held.alpha])
    bp = frame.T @ (Jp @ u_dot - Kp @ lam[keep] + rows.bias[keep]) + offsets[mode.a]
    mu, _, _ = point_coefficients(scene, model)

    # a sliding end: friction opposes its slip (a slide from rest that goes on: the blend
    # with its start direction)
    kept, kept_dirs = continued
    blend = lambda p, s0: blend_direction(geom.slip[p], s0, tol.slip_blend)  # noqa: E731

    def seeds(need_a):
        return (
            jnp.where(rest_a, unit_or(-need_a, zero3), blend(mode.a, kept_dirs[0])),
            jnp.where(rest_b, unit_or(-need_b, zero3), blend(mode.b, kept_dirs[1])),
            jnp.where(rest_f, unit_or(-need_f, zero3), unit_or(twist, zero3)),
        )

    # one scan of directions (the program holds it once) for a single point sliding from
    # rest, its slip's acceleration in closed form, and for a pair's end starting from rest
    # while the other end slides, by the sliding solver with that end's direction fixed
    # (exact, as for a single point); the others: fixed point below, Newton for a pair
    hats0 = seeds(need_a)
    point = (mode.kind == POINT) & rest_a
    pair = mode.kind == PAIR
    scan_b = (pair & rest_b & ~rest_a) | starts
    point_measure = point_slip_measure(bp, frame.T @ Kp @ frame, mu[mode.a], frame[0])

    def measure(s):
        if not model.pairs:  # a shape without pairs (a ball on one surface)
            return point_measure(s)
        hats = (jnp.where(scan_b, hats0[0], s), jnp.where(scan_b, s, hats0[1]), hats0[2])
        sol = solve(hats)
        acc = geom.tangential(relative(sol))[jnp.where(scan_b, mode.b, mode.a)]
        pushes = jnp.where(
            starts,
            jnp.all(sol.rows.support_map @ sol.lam[:3] >= 0),  # a support's vertex forces
            (sol.lam[0] >= 0) & (sol.lam[1] >= 0),
        )
        return tree_where(point, point_measure(s), (acc, pushes))

    scan_dir, found = only_where_needed(
        live & (point | (pair & (rest_a != rest_b)) | starts),
        lambda: scan_direction(
            measure, *geom.frame_of(jnp.where(scan_b, mode.b, mode.a)), dtype, tol.force
        ),
        lambda: (zero3, jnp.array(False)),
    )
    # (none found: at a single point's cone's edge the slip's acceleration vanishes along
    # the direction opposite to the friction sticking needs, which the seed already is; a
    # pair's seed is that of both ends sticking, which is not where one end slides)
    hats0 = seeds(jnp.where((mode.kind == POINT) & found, -scan_dir, need_a))
    # a shape without pairs (a ball on one surface) has no pair modes: no pair searches
    exact_a = exact_b = exact_pair = jnp.array(False)
    if model.pairs:
        rests = (rest_a, rest_b, starts)
        hats0, exact_a, exact_b, exact_pair = _pair_directions(
            geom, mode, hats0, rests, (scan_dir, found), live, solve, relative, dtype
        )
    small = 1e-6 * (1.0 + _safe_norm(held.acc))  # slip accelerations below this: keep the seed

    def slip_rates(sol):  # relative to the stabilisation's targets, as every condition
        slip_acc = geom.tangential(relative(sol))
        twist_rate = sol.twist_rate(model, mode.face) + beta * twist
        return slip_acc[mode.a], slip_acc[mode.b], twist_rate

    def follow(rest, rate, hat):  # a single point's direction is exact already
        iterate = rest & (mode.kind != POINT) & (_safe_norm(rate) > small)
        return jnp.where(iterate, unit_or(rate, hat), hat)

    def iterate(_, carry):  # carry: (next directions, last directions, their solution)
        hats = carry[0]
        sol = solve(hats)
        sa, sb, st = slip_rates(sol)
        followed = (
            follow(rest_a & ~exact_a & ~exact_pair, sa, hats[0]),
            follow(rest_b & ~exact_b & ~exact_pair, sb, hats[1]),
            follow(rest_f, st, hats[2]),
        )
        return followed, hats, sol

    # FIXED_POINT_ITERATIONS updates, then the solution with the last directions (one more
    # pass of the same loop: the solve is traced, and compiled, once); where no direction
    # follows in any candidate (of any member of a batch), the directions stay as they are
    # and one pass gives the solution (no derivative flows here: a loop of traced length)
    follows = live & (
        (rest_a & ~exact_a & ~exact_pair & (mode.kind != POINT))
        | (rest_b & ~exact_b & ~exact_pair)
        | rest_f
    )
    passes = jnp.where(eqxi.unvmap_any(follows), FIXED_POINT_ITERATIONS + 1, 1)
    _, hats, sol = jax.lax.fori_loop(0, passes, iterate, (hats0, hats0, held))
    P = model.num_points
    force = conditions(sol, mode, model, scene, tol)[P:]
    keep = jnp.array([True] * 5 + [False, False, True, False])  # not the slips, junction
    force = jnp.where(keep, force, UNUSED)
    gap_acc = jnp.sum(relative(sol) * geom.n, axis=-1)
    gap_margin = jnp.where(resting & ~active_points(model, mode), gap_acc, UNUSED)
    # sliding from rest: the slip must accelerate along the direction friction opposes
    sa, sb, st = slip_rates(sol)
    align = jnp.stack(
        [
            jnp.where(rest_a, sa @ hats[0], UNUSED),
            jnp.where(rest_b, sb @ hats[1], UNUSED),
            jnp.where(rest_f, st @ hats[2], UNUSED),
        ]
    )
    # the blend direction only for a slide from rest, and one that goes on: any other
    # slide's friction opposes its own slip exactly (a blend kept along a start direction
    # would bias it all the way)
    chosen = eqx.tree_at(
        lambda m: (m.slide_dir, m.twist_dir, m.from_rest),
        mode,
        (
            jnp.stack(
                [jnp.where(rest_a, hats[0], kept_dirs[0]), jnp.where(rest_b, hats[1], kept_dirs[1])]
            ),
            jnp.where(rest_f, hats[2], zero3),
            jnp.stack([rest_a | rest_f | kept[0], rest_b | kept[1]]),
        ),
    )
    # a sticking face needs its slip twist at rest (its corners' slips may be larger); a
    # support, each of its vertices sliding (its friction follows their slips)
    still = jnp.where(
        mode.kind == FACE,
        ~mode.stick[0] | (jnp.linalg.norm(twist) <= tol.slip_stop),
        ~(mode.stick[0] & ~zero_slip[mode.a]) & ~(mode.stick[1] & ~zero_slip[mode.b]),
    )
    # (but its vertex b, at rest where it pivots or starts to slide from rest)
    at_rest = (on_pivot(mode) | starts) & support_vertex_b(mode)
    still = still & ~(support & jnp.any(still_vertices != at_rest))
    # the Painlevé paradox: a contact that slides (not from rest) on a normal problem that
    # is not a P-matrix, while every resting point the mode does not hold stays clear of the
    # floor (where one would not, the mode is not the body's contact whatever its own normal
    # problem: a pair of a face that lies flat, say)
    slides = ((mode.kind == POINT) | (mode.kind == PAIR)) & (
        (~mode.stick[0] & ~rest_a) | ((mode.kind == PAIR) & ~mode.stick[1] & ~rest_b)
    )
    clear = jnp.all(gap_margin >= -tol.force)
    paradox = slides & clear & not_p_matrix(sol, mode, scene.body)
    return chosen, jnp.concatenate([gap_margin, force, align]), still, paradox


def _pair_directions(geom, mode, hats0, rests, scanned, live, solve, relative, dtype):
    """The sliding directions from rest of a pair's ends (`_candidate`): one end sliding,
    the other from rest, from the candidate's scan (`scanned`: its direction and whether
    it found one), as a support's vertex b starting from rest; both from rest, by Newton.
    `rests`: whether end a, end b, a support's vertex b start from rest. `solve(hats)`
    solves the candidate for given directions, `relative(sol)` its point accelerations
    relative to the stabilisation's targets. Returns the directions and which are exact
    (a, b, both)."""
    pair = mode.kind == PAIR
    rest_a, rest_b, starts = rests
    end_dir, end_found = scanned
    exact_a = pair & rest_a & ~rest_b & end_found
    exact_b = ((pair & rest_b & ~rest_a) | starts) & end_found
    hats0 = (
        jnp.where(exact_a, end_dir, hats0[0]),
        jnp.where(exact_b, end_dir, hats0[1]),
        hats0[2],
    )
    # a pair whose ends both start from rest: both directions at once, by Newton from the
    # directions opposite to the friction sticking would need and from those across and
    # along the line (rigidity ties the two ends' slips along it, and a line that slides
    # sideways as a whole has both ends sliding across it)
    # (each end's directions in its own point's frame)
    ends = (geom.frame_of(mode.a), geom.frame_of(mode.b))
    chord = geom.r[mode.b] - geom.r[mode.a]
    angle = lambda s, end: jnp.arctan2(s @ end[2], s @ end[1])  # noqa: E731
    on_floor = lambda x, end: jnp.cos(x) * end[1] + jnp.sin(x) * end[2]  # noqa: E731

    def line_angles(end):  # the directions across and along the line at that end
        n, t1, _ = end
        line = unit_or(chord - (chord @ n) * n, t1)
        return angle(cross(n, line), end), angle(line, end)

    (across_a, along_a), (across_b, along_b) = line_angles(ends[0]), line_angles(ends[1])
    seeds = jnp.stack(
        [
            jnp.stack([angle(hats0[0], ends[0]), angle(hats0[1], ends[1])]),
            jnp.stack([across_a, across_b]),
            jnp.stack([across_a + jnp.pi, across_b + jnp.pi]),
            jnp.stack([along_a, along_b]),
            jnp.stack([along_a + jnp.pi, along_b + jnp.pi]),
        ]
    )

    def pair_measure(x):
        sa, sb = on_floor(x[0], ends[0]), on_floor(x[1], ends[1])
        sol = solve((sa, sb, hats0[2]))
        acc = geom.tangential(relative(sol))
        aa, ab = acc[mode.a], acc[mode.b]
        turning = jnp.stack([cross(aa, sa) @ ends[0][0], cross(ab, sb) @ ends[1][0]])
        return turning, jnp.stack([aa @ sa, ab @ sb]), (sol.lam[0] >= 0) & (sol.lam[1] >= 0)

    pair_x, pair_found = only_where_needed(
        live & pair & rest_a & rest_b,
        lambda: newton_directions(pair_measure, seeds, dtype),
        lambda: (seeds[0], jnp.array(False)),
    )
    exact_pair = pair & rest_a & rest_b & pair_found
    hats0 = (
        jnp.where(exact_pair, on_floor(pair_x[0], ends[0]), hats0[0]),
        jnp.where(exact_pair, on_floor(pair_x[1], ends[1]), hats0[1]),
        hats0[2],
    )
    return hats0, exact_a, exact_b, exact_pair


def exclusions(table, candidates, model, old, trigger, zero_slip, resting):
    """Masks of the `candidates` that the event which ended the segment rules out (they would
    re-enter the boundary just crossed; `trigger` indexes the condition vector, -1: none),
    and of those among them that are readmitted where no candidate fits: a pair's end that
    lifted off, or whose sticking friction reached its cone, rules out the pair's modes only
    while the other end still slides (`zero_slip`: (P,) points whose slip is below
    slip_stop); and a mode that also holds a point the ended mode did not hold, resting
    (`resting`, (P,)) as the event came, is another contact, whose forces the event has not
    tested. A mode that sticks where the ended mode slid from rest, that slide not ended by
    the event, is tried only where nothing else fits."""
    P = model.num_points
    old_active = active_points(model, old)
    t_active = jnp.asarray(table.active)[candidates]
    t_sticking = jnp.asarray(table.sticking)[candidates]
    kind = jnp.asarray(table.kind)[candidates]
    stick = jnp.asarray(table.stick)[candidates]
    same_face = (kind == FACE) & (jnp.asarray(table.face)[candidates] == old.face)
    old_face = old.kind == FACE
    k = trigger - P
    idx = jnp.arange(P, dtype=old.a.dtype)
    same_pair = (
        (kind == PAIR)
        & (jnp.asarray(table.a)[candidates] == old.a)
        & (jnp.asarray(table.b)[candidates] == old.b)
    )
    # a normal force reached zero: that point (a face: all its points) stops carrying, in
    # the mode that ended. Where the pair's other point slid and its slip is gone too (both
    # boundaries reached within the event's tolerance), or it slid from rest with its slip
    # still below slip_stop, every mode of the pair is another mode (that point now sticks
    # or slides from rest in another direction), whose normal force the event has not
    # tested: those are readmitted
    slid = (old.kind == PAIR) & ~old.stick
    slid_to_rest = slid & zero_slip[jnp.stack([old.a, old.b])]
    lifted_a = jnp.where(old_face, old_active, idx == old.a)
    ex_normal_a = jnp.any(t_active & lifted_a, axis=1)
    ex_normal_b = jnp.any(t_active & (idx == old.b), axis=1)
    # friction reached the cone: that point (or face) no longer sticks
    ex_cone_a = jnp.where(old_face, same_face & stick[:, 0], t_sticking[:, old.a])
    ex_cone_b = t_sticking[:, old.b]
    ex_axial = same_pair & stick[:, 0] & stick[:, 1]
    # the centre of pressure left the face (a support: a vertex's normal force reached
    # zero): that face's limit-surface modes, or that support, no longer hold; the face's
    # other supports may (each vertex friction's own load distribution)
    support = jnp.asarray(table.support)[candidates]
    same_support = jnp.all(support == old.support, axis=1)
    ex_cop = same_face & jnp.where(on_support(old), same_support, support[:, 0] < 0)
    excluded = jnp.select(
        [k == NORMAL_A, k == NORMAL_B, k == CONE_A, k == CONE_B, k == AXIAL, k == COP],
        [ex_normal_a, ex_normal_b, ex_cone_a, ex_cone_b, ex_axial, ex_cop],
        jnp.zeros(candidates.shape, bool),
    )
    # (and the same where a sticking end's friction reached its cone: the modes of the pair
    # with the other end sticking or sliding from rest need another friction there)
    at_a, at_b = (k == NORMAL_A) | (k == CONE_A), (k == NORMAL_B) | (k == CONE_B)
    other_end_stopped = (at_a & slid_to_rest[1]) | (at_b & slid_to_rest[0])
    # (a point that came down onto the floor as the boundary was reached: a gap that closed
    # within the event's tolerance of it)
    holds_new = jnp.any(t_active & resting & ~old_active, axis=1)
    readmitted = excluded & ((same_pair & other_end_stopped) | holds_new)
    # a point that started to slide from rest in the ended mode, its slide not ended by the
    # event (and no impact changed its slip), slides on: a mode that holds it sticking is
    # tried only where nothing else fits (its slip may still lie below slip_stop, where
    # sticking is admissible, and would end a slide that is starting, which no condition
    # ended; any other slide with its slip that low is ending)
    starts = unended_starts(old, k)
    starting = ((idx == old.a) & starts[0]) | ((idx == old.b) & starts[1])
    stops = jnp.any(t_sticking & starting, axis=1)
    return excluded | stops, readmitted | (stops & ~excluded)


def select_mode(
    t, state, geom, old, trigger, scene, model, table, tol, resting, zero_slip, live=True
):
    """The next mode at an event (state after any impact). `resting`: (P,) points touching
    with zero normal velocity; `zero_slip`: (P,) points whose slip is below slip_stop;
    `live`: whether the choice is used (False: a finished member of a batch)."""
    candidates, chunks = table.candidates(resting)
    size = table.chunk

    @eqx.filter_jit  # traced once, for its shapes and for its chunks
    def one(i):
        mode = table.mode(i, old)
        continued = continued_slides(mode, old, trigger, zero_slip)
        return _candidate(
            t, state, geom, mode, scene, model, tol, resting, zero_slip, continued, live
        )

    t_active = jnp.asarray(table.active)[candidates]
    held_resting = jnp.all(~t_active | resting, axis=1)  # every point it holds rests
    # where no candidate fits, those `exclusions` readmits are tried
    excluded, readmitted = exclusions(table, candidates, model, old, trigger, zero_slip, resting)
    relaxed = held_resting & (~excluded | readmitted)
    admissible = held_resting & ~excluded

    # a chunk of candidates at a time (under vmap side by side), in the table's order, until
    # one holds a consistent candidate with no rival (the Painlevé paradox's, below): the
    # first such one is taken, and no later one can come before it. A while loop: a chunk
    # that is not needed costs nothing (under `jax.vmap` the loop runs while any member
    # needs a chunk, and each member keeps its own results)
    def verdict(admissible, margins, still, paradox):
        admissible = admissible & still
        violation = jnp.max(jnp.maximum(-margins, 0.0), axis=1)
        # the tolerance grows with the candidate's forces (`FORCE_TOL_PER_FORCE`)
        used = jnp.abs(margins) < 0.5 * UNUSED
        scale = jnp.max(jnp.where(used, jnp.abs(margins), 0.0), axis=1)
        ok = admissible & (violation <= tol.force + FORCE_TOL_PER_FORCE * scale)
        return admissible, violation, ok, ok & ~paradox

    split = lambda x: x.reshape((-1, size) + x.shape[1:])  # noqa: E731
    by_chunk, allowed_by_chunk = split(candidates), split(admissible)
    shapes = jax.eval_shape(jax.vmap(one), candidates[:size])
    stacked = lambda x: jax.ShapeDtypeStruct((len(by_chunk), *x.shape), x.dtype)  # noqa: E731
    tested = tree_zeros(jax.tree.map(stacked, shapes))

    def more(carry):
        k, settled, _, _ = carry
        return (k < chunks) & ~settled

    def test_chunk(carry):
        k, _, tested, was_tested = carry
        out = jax.vmap(one)(by_chunk[k])
        plain = verdict(allowed_by_chunk[k], *out[1:])[3]
        tested = jax.tree.map(lambda all_, x: all_.at[k].set(x), tested, out)
        return k + 1, jnp.any(plain), tested, was_tested.at[k].set(True)

    start = (jnp.zeros((), chunks.dtype), jnp.array(False), tested, jnp.zeros(len(by_chunk), bool))
    _, _, tested, was_tested = jax.lax.while_loop(more, test_chunk, start)
    modes, margins, still, paradox = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), tested)
    was_tested = jnp.repeat(was_tested, size)  # per candidate
    admissible, violation, ok, plain = verdict(admissible & was_tested, margins, still, paradox)
    # no candidate fits: the loop tested every chunk, and the narrower exclusions may leave
    # one that does
    relaxed = verdict(relaxed & was_tested, margins, still, paradox)
    use_relaxed = ~jnp.any(ok) & jnp.any(relaxed[2])
    admissible, violation, ok, plain = jax.tree.map(
        lambda r, s: jnp.where(use_relaxed, r, s), relaxed, (admissible, violation, ok, plain)
    )
    any_ok = jnp.any(ok)
    # the Painlevé paradox: with no consistent mode, a sliding contact on a normal problem
    # that is not a P-matrix has no solution; a consistent mode of that kind has a rival (the
    # contact lifting off), and the mode without it is taken
    # (with no consistent mode, whatever the event excluded: the forces of a sliding mode
    # whose normal problem turns singular pass through a pole, which the event function
    # takes for a force reaching zero)
    painleve = ~any_ok & jnp.any(held_resting & was_tested & still & paradox)
    paradox = admissible & paradox
    ambiguous = any_ok & jnp.any(ok & paradox) & jnp.any(plain)
    # the first in the table's order of preference
    first_of = lambda mask: jnp.argmin(jnp.where(mask, candidates, len(table)))  # noqa: E731
    first = jnp.where(jnp.any(plain), first_of(plain), first_of(ok))
    least = jnp.min(jnp.where(admissible, violation, jnp.inf))
    i = jnp.where(any_ok, first, first_of(admissible & (violation == least)))
    # no point rests: nothing was tested, and the body flies (`_candidate`'s FLIGHT)
    dtype = state.pos.dtype
    flight = eqx.tree_at(
        lambda m: (m.slide_dir, m.twist_dir, m.from_rest),
        table.mode(len(table) - 1, old),
        (jnp.zeros((2, 3), dtype), jnp.zeros(3, dtype), jnp.zeros(2, bool)),
    )
    flies = chunks == 0
    return Choice(
        mode=tree_where(flies, flight, tree_index(modes, i)),
        consistent=any_ok | flies,
        painleve=painleve,
        ambiguous=ambiguous,
    )
