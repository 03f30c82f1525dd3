"""Impacts: Newton's restitution with Coulomb friction at all touching points at once
(docs/contact.md, section 5).

Unknowns: the impulse Lambda_i = (Lambda_n, Lambda_t) at each touching point i (N s, in the
frame n, t1, t2 of the surface there: on a surface of several parts, each point's own).
With the Delassus operator W = J M^-1 J^T and the contact velocities before, c = J u-, the
velocities after are c+ = c + W Lambda, and per point:

- Newton: Lambda_n >= 0, c+_n - target >= 0, complementary, with target = -e min(c_n, 0)
  (a point that approached leaves at e times its approach speed unless the others lift it; a
  resting one does not approach);
- Coulomb on the impulses: |Lambda_t| <= mu Lambda_n; sticking (c+_t = 0) or sliding with
  Lambda_t = -mu Lambda_n s, s the unit slip after the impact (maximum dissipation).

The touching points are gathered into `SLOTS` (4) slots: all touching points of a convex
body lie on one face (a box's corners; a flat cap is held by four of its rim points). The
problem is solved by projected Gauss-Seidel (until a sweep changes no impulse by more than
`SETTLED` machine epsilons of the largest, at most `SWEEPS` sweeps; an isotropic step in the
tangent plane, so that at the fixed point a sliding impulse opposes the slip exactly), then
*polished*: the pattern it identifies (which points push, which stick, the sliding
directions) is solved exactly (a minimum-norm solve of its equalities, as the four corners of
a face are redundant) and kept if it satisfies every condition (the polishes after one that
is exact to roundoff are not tried). Where the pattern is not unique (a face sliding on four
corners: the normal impulses split in many ways) the polish may fail and the Gauss-Seidel
solution, which satisfies the conditions to its convergence, is kept. Where nothing fits,
patterns of slots pushing are polished in turn, and a lone sliding slot's direction is
found by scanning the circle of directions of its slip after (`_lone_slide`).

Four variants (`solve_variant` solves one, `solve_impacts` all four; the event map solves
each only where it uses it): Newton-Coulomb; the frictionless impulse, used where the
first would add energy (Newton's law with friction can, in rare configurations); the
frictionless plastic impulse (e = 0), used where even the frictionless one would add energy
(with several points and e near 1 it can: a point that was separating is held at zero
normal speed, not let approach); and the limit of a bounce series: the smallest change of
the velocities (in the kinetic metric) that stops the normal motion of every touching
point, i.e. a frictionless plastic impulse holding them all (normal impulses of either
sign); the slip it leaves is then taken up by Coulomb friction in the contact mode that
follows.
"""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp

from .._body import RigidBody
from .._linalg import inverse3, solve as small_solve
from .._quaternion import _safe_norm
from .._state import State
from ._modes import cross
from ._select import scan_direction

SLOTS = 4
SWEEPS = 1000  # most impacts settle in a few; a face sliding on four corners with strong
# friction took 300-450 (60 left one landing unconverged, its outcome then 1e-6 off, set by
# roundoff and the order of the corners)
SETTLED = 64  # machine epsilons: a sweep that changes the impulses less has converged
# the variants, as `solve_impacts` returns them (`variant_parameters` gives each one's law)
VARIANTS = 4
NEWTON, FRICTIONLESS, HELD, PLASTIC = range(VARIANTS)


class ImpactOutcome(eqx.Module):
    """The state after an impact and what the floor did: the total impulse (N s, world), the
    world point on the floor where it acts (m), whether every condition holds."""

    state: State
    impulse: jax.Array
    point: jax.Array
    consistent: jax.Array


def _jacobians(body, R, r, n, t1, t2):
    """Per-point contact Jacobians J (S, 3, 6) (rows n, t1, t2: each (S, 3), the points'
    frames), M^-1 J^T rows, and W."""
    inv_iw = R @ inverse3(body.inertia_matrix) @ R.T
    lin = jnp.stack([n, t1, t2], axis=1)  # (S, 3, 3)
    ang = cross(r[:, None, :], lin)  # r x d
    J = jnp.concatenate([lin, ang], axis=-1)
    minv = jnp.concatenate([lin / body.mass, ang @ inv_iw.T], axis=-1)
    W = jnp.einsum("iad,jbd->iajb", J, minv)
    return J, minv, W


def _gauss_seidel(W, c, target, present, mu, bilateral, lam0, sweeps):
    """Projected Gauss-Seidel for the impulses (S, 3) (normal, t1, t2) per slot, from lam0;
    `mu` (S,): each slot's friction coefficient. Sweeps until a sweep changes no impulse by
    more than `SETTLED` of the largest (most impacts settle in a few), at most `sweeps`. No
    derivative flows through the sweeps (the polish carries them)."""
    W, c, target, mu, lam0 = jax.lax.stop_gradient((W, c, target, mu, lam0))
    S = c.shape[0]
    tiny = jnp.finfo(c.dtype).tiny
    diag = jnp.einsum("iaia->ia", W)
    wn = jnp.maximum(diag[:, 0], tiny)
    # an isotropic tangential step: the largest eigenvalue of each slot's 2 x 2 block
    a, d, b = diag[:, 1], diag[:, 2], W[jnp.arange(S), 1, jnp.arange(S), 2]
    wt = jnp.maximum(0.5 * (a + d) + _safe_norm(jnp.stack([0.5 * (a - d), b], -1)), tiny)

    def sweep(_, lam):
        for i in range(S):  # unrolled: a few slots
            v = c[i] + jnp.einsum("ajb,jb->a", W[i], lam)
            ln = lam[i, 0] - (v[0] - target[i]) / wn[i]
            ln = jnp.where(bilateral, ln, jnp.maximum(ln, 0.0))
            ln = jnp.where(present[i], ln, 0.0)
            vt = v[1:] + W[i, 1:, i, 0] * (ln - lam[i, 0])
            trial = lam[i, 1:] - vt / wt[i]
            size = _safe_norm(trial)
            bound = mu[i] * jnp.abs(ln)
            shrink = jnp.where(size > bound, bound / jnp.where(size > 0, size, 1.0), 1.0)
            lt = jnp.where(present[i], trial * shrink, 0.0)
            lam = jnp.where((jnp.arange(S) == i)[:, None], jnp.concatenate([ln[None], lt]), lam)
        return lam

    settled = SETTLED * jnp.finfo(c.dtype).eps

    def going(carry):
        i, lam, change = carry
        return (i < sweeps) & (change > settled * jnp.max(jnp.abs(lam)))

    def step(carry):
        i, lam, _ = carry
        new = sweep(i, lam)
        return i + 1, new, jnp.max(jnp.abs(new - lam))

    start = (jnp.zeros((), jnp.int32), lam0, jnp.array(jnp.inf, c.dtype))
    return jax.lax.while_loop(going, step, start)[1]


# refinements at most, each taking the slip after the last iterate as the sliding directions
# (a fixed point, stopped once exact): a corner landing with friction 1.5 needed 12 to reach
# 6e-13 m/s, from 1.3e-5 after 3 (its sliding direction turns by 0.08 rad in the impact)
POLISH_ITERATIONS = 12
POLISH_MARGINS = (1e-9, 1e-2, -1e-2)  # relative distance inside the cone that counts as sticking
# the patterns of slots pushing tried where no polish of Gauss-Seidel's fits: every set of one
# to three of the `SLOTS` slots (three points of a face determine its impulses)
POLISH_PATTERNS = [
    [slot in chosen for slot in range(SLOTS)]
    for size in (3, 2, 1)
    for chosen in itertools.combinations(range(SLOTS), size)
]


def _polish(W, c, target, present, mu, bilateral, lam, margin, exact):
    """The exact solution of the pattern of `lam`: which slots push (Lambda_n > 0, or all
    present ones when bilateral), which stick (inside the cone by more than the relative
    `margin`), and along which directions the others slide (those opposing their friction;
    then, while the best violates the conditions by more than `exact`, those of the slip
    after the last polished impulse)."""
    S = c.shape[0]
    dtype = c.dtype
    tiny = jnp.finfo(dtype).tiny
    scale = jnp.max(jnp.abs(lam[:, 0])) + tiny
    push = present & (bilateral | (lam[:, 0] > 1e-9 * scale))
    lt = _safe_norm(lam[:, 1:])
    stick = push & (lt < mu * jnp.abs(lam[:, 0]) * (1 - margin))
    slide = push & ~stick
    rows = jnp.stack([push, stick, stick], 1).reshape(-1)
    unknown = jnp.stack([push, push, push], 1).reshape(-1)
    rhs = (jnp.stack([target, jnp.zeros(S, dtype), jnp.zeros(S, dtype)], 1) - c).reshape(-1)
    eye = jnp.eye(3, dtype=dtype)
    first = jnp.array([1.0, 0.0, 0.0], dtype)
    # the Gauss-Seidel unknowns z = (Lambda_n, Lambda_t1, Lambda_t2); a sliding slot's
    # tangential impulse rides on its normal one
    z0 = jnp.where(slide[:, None], lam * first, lam).reshape(-1)

    def solve(hats):
        ride = eye * first + jnp.concatenate(
            [jnp.zeros((S, 1, 3), dtype), -mu[:, None, None] * hats[:, :, None] * first], axis=1
        )
        B = jnp.where(slide[:, None, None], ride, eye)
        A = jnp.einsum("iajb,jbc->iajc", W, B).reshape(3 * S, 3 * S)
        A = jnp.where(rows[:, None] & rows[None, :], A, 0.0)
        # the smallest change of z that satisfies the equalities exactly: unique where they
        # determine the impulses; where they do not (a face's four corners) it keeps the
        # Gauss-Seidel split of the normal impulses
        G = A @ A.T
        size = jnp.max(jnp.abs(jnp.diagonal(G))) + tiny
        G = jnp.where(rows[:, None] & rows[None, :], G, jnp.eye(3 * S, dtype=dtype))
        G = G + 1e-13 * size * jnp.eye(3 * S, dtype=dtype)
        z = z0 + A.T @ jnp.where(
            rows, small_solve(G, jnp.where(rows, rhs - A @ z0, 0.0), unroll=True), 0.0
        )
        return jnp.einsum("iab,ib->ia", B, jnp.where(unknown, z, 0.0).reshape(S, 3))

    hats0 = -lam[:, 1:] / jnp.where(lt > 0, lt, 1.0)[:, None]  # the slip after, as friction says
    speed = jnp.max(jnp.abs(c)) + tiny

    def attempt(i, carry):  # first the directions friction says, then the slip after each
        def refine(carry):
            best, best_error, hats, last = carry
            v = c + jnp.einsum("iajb,jb->ia", W, last)
            vt = _safe_norm(v[:, 1:])
            slips = (i > 0) & (vt > 1e-6 * speed)  # a slip of roundoff size tells no direction
            hats = jnp.where(slips[:, None], v[:, 1:] / jnp.where(slips, vt, 1.0)[:, None], hats)
            trial = solve(hats)
            error = _violation(W, c, target, present, mu, bilateral, trial)
            better = error < best_error
            best = jnp.where(better, trial, best)
            return best, jnp.where(better, error, best_error), hats, trial

        # a solution exact to roundoff is not refined
        return jax.lax.cond(carry[1] <= exact, lambda carry: carry, refine, carry)

    # a loop, so that the solve is traced (and compiled) once; the directions follow the
    # slip after each iterate (from the best one they would stall where an iterate is worse)
    start = (jnp.zeros_like(lam), jnp.array(jnp.inf, dtype), hats0, jnp.zeros_like(lam))
    best, _, _, _ = jax.lax.fori_loop(0, 1 + POLISH_ITERATIONS, attempt, start)
    return best


def _exact(c):
    """A violation of the conditions (m/s) that small is roundoff: `SETTLED` machine
    epsilons of the largest contact speed `c`."""
    return SETTLED * jnp.finfo(c.dtype).eps * (jnp.max(jnp.abs(c)) + jnp.finfo(c.dtype).tiny)


def _violation(W, c, target, present, mu, bilateral, lam):
    """The largest violation (m/s) of the conditions by the impulses `lam`."""
    v = c + jnp.einsum("iajb,jb->ia", W, lam)
    per_mass = jnp.maximum(jnp.max(jnp.abs(lam[:, 0])), jnp.finfo(c.dtype).tiny)
    speed = jnp.max(jnp.abs(c)) + jnp.finfo(c.dtype).tiny
    to_speed = speed / per_mass  # impulses measured on the scale of the speeds
    ln = lam[:, 0]
    lt = _safe_norm(lam[:, 1:])
    vt = _safe_norm(v[:, 1:])
    gap = v[:, 0] - target
    bad = jnp.stack(
        [
            jnp.where(bilateral, 0.0, -ln * to_speed),  # pushes only
            jnp.where(bilateral, jnp.abs(gap), -gap),  # no approach (held: none at all)
            jnp.where(bilateral, 0.0, jnp.minimum(ln * to_speed, jnp.abs(gap))),  # complementary
            (lt - mu * jnp.abs(ln)) * to_speed,  # inside the cone
            # stick (no slip after), or slide on the cone's edge, opposing the slip (a point
            # without impulse has no friction to satisfy)
            jnp.minimum(
                vt,
                jnp.maximum(
                    (mu * jnp.abs(ln) - lt) * to_speed,
                    jnp.where(
                        lt > 0,
                        jnp.sum(lam[:, 1:] * v[:, 1:], -1) / jnp.where(lt > 0, lt, 1.0) + vt,
                        0.0,
                    ),
                ),
            ),
        ]
    )
    return jnp.max(jnp.where(present[None, :], bad, 0.0))


def _lone_slide(W, c, target, present, mu, slack):
    """The impulses (S, 3) of a lone present slot sliding through the impact, in its frame
    (normal, t1, t2): Lambda_n (1, -mu s), s the unit slip after the impact, found by
    scanning the circle of directions s (`scan_direction`) for a slip after c+_t = kappa s,
    kappa >= -`slack` (m/s), with Lambda_n >= 0 meeting the slot's target; and whether one
    was found. The slip's direction may turn so far in the impact that following it from
    the slip before cycles (a corner landing with `mu` 1.2 as it spins at 61 rad/s). No
    derivative flows here (the polish from this start carries them)."""
    W, c, target, mu = jax.lax.stop_gradient((W, c, target, mu))
    i = jnp.argmax(present)
    Wi, ci = W[i, :, i, :], c[i]  # (3, 3), (3,): normal, t1, t2
    dtype = c.dtype
    n, t1, t2 = jnp.eye(3, dtype=dtype)  # the slot's frame in its own coordinates

    def impulse(s):  # s: (0, s_t1, s_t2)
        b = n - mu[i] * s  # Lambda = Lambda_n b
        slope = Wi[0] @ b
        normal = (target[i] - ci[0]) / jnp.where(slope != 0, slope, 1.0)
        return normal * b, slope > 0

    def measure(s):  # the slip after (its tangential velocity), whether the slot pushes
        lam, pushes = impulse(s)
        after = ci + Wi @ lam
        return after * (1.0 - n), pushes

    s, found = scan_direction(measure, n, t1, t2, dtype, slack)
    lam = jnp.where((jnp.arange(c.shape[0]) == i)[:, None], impulse(s)[0], 0.0)
    return lam, found


class ImpactProblem(eqx.Module):
    """An impact's touching points gathered into `SLOTS` slots: the body, the state before
    (unit quaternion), the rotation R (body to world) and angular velocity `w` (world,
    rad/s), the slots' points `r` (S, 3) (world offsets from the mass centre, m), their
    surface frames `frames` (S, 3, 3) (rows n, t1, t2), which are `present` (S,), and their
    friction coefficients `mu` (S,)."""

    body: RigidBody
    state: State
    R: jax.Array
    w: jax.Array
    r: jax.Array
    frames: jax.Array
    present: jax.Array
    mu: jax.Array


def impact_problem(state, geom, points, touching, scene, frames=None, mu=None) -> ImpactProblem:
    """The impact at `state` (unit quaternion) at the contact `points` (Q, 3) (world offsets
    from the mass centre) of which `touching` (Q,) touch the surface.

    `frames` = (n, t1, t2), each (Q, 3), and `mu` (Q,): each point's surface frame and
    friction coefficient (a surface of several parts); by default the frame of the
    geometry's first point and the surface's friction, for every point."""
    Q = points.shape[0]
    if frames is None:
        frames = geom.frame_of(0)
    n, t1, t2 = (jnp.broadcast_to(x, (Q, 3)) for x in frames)
    mu = jnp.broadcast_to(scene.floor.friction if mu is None else mu, (Q,))
    # the touching points, gathered into the first slots in an order set by where they are
    # (along a fixed direction of the floor), not by how the shape numbers them: where the
    # impulses are not unique (a face on four corners, with friction) the solution the
    # sweeps settle on depends on the slots' order, and so the outcome would depend on the
    # numbering too. Where more points touch than there are slots (a
    # d12's pentagon lands flat), the slots take those that approach fastest: a point left
    # out must not be one that still approaches (it would be hit again at once, unresolved)
    where = jnp.sum(points * (t1 + 0.6180339887498949 * t2), axis=-1)
    rate = jnp.sum((state.vel + cross(geom.w, points)) * n, axis=-1)
    chosen = jnp.lexsort((where, jnp.where(touching, rate, jnp.inf)))[:SLOTS]
    order = chosen[jnp.argsort(jnp.where(touching[chosen], where[chosen], jnp.inf))]
    frames = jnp.stack([n[order], t1[order], t2[order]], axis=1)
    return ImpactProblem(
        scene.body, state, geom.R, geom.w, points[order], frames, touching[order], mu[order]
    )


def variant_parameters(e, mu):
    """The law of each variant, indexed by `NEWTON`, `FRICTIONLESS`, `HELD`, `PLASTIC`:
    restitution (VARIANTS,), friction coefficients (VARIANTS, S) from the surface's `e` and
    the slots' `mu` (S,), and whether the normal impulses hold every point (VARIANTS,)."""
    law = {
        NEWTON: (e, mu, False),
        FRICTIONLESS: (e, jnp.zeros_like(mu), False),
        HELD: (jnp.zeros_like(e), jnp.zeros_like(mu), True),
        PLASTIC: (jnp.zeros_like(e), jnp.zeros_like(mu), False),
    }
    restitution, friction, bilateral = zip(*(law[k] for k in range(VARIANTS)), strict=True)
    return jnp.stack(restitution), jnp.stack(friction), jnp.array(bilateral)


def solve_variant(problem: ImpactProblem, e, mu, bilateral, tol) -> ImpactOutcome:
    """The impulses of `problem` with restitution `e`, friction coefficients `mu` (S,) and,
    where `bilateral`, normal impulses of either sign holding every present point (the
    limit of a bounce series: e = 0, mu = 0); the state after and what the floor did."""
    present, state = problem.present, problem.state
    n, t1, t2 = (problem.frames[:, k] for k in range(3))
    J, minv, W = _jacobians(problem.body, problem.R, problem.r, n, t1, t2)
    u = jnp.concatenate([state.vel, problem.w])
    c = jnp.where(present[:, None], J @ u, 0.0)  # (S, 3) m/s: normal, t1, t2
    dtype = c.dtype
    tiny = jnp.finfo(dtype).tiny
    target = jnp.where(present, -e * jnp.minimum(c[:, 0], 0.0), 0.0)
    # derivatives flow through the polish's exact solve, not through the sweeps
    lam = _gauss_seidel(W, c, target, present, mu, bilateral, jnp.zeros_like(c), SWEEPS)
    # polished up to three ways: a slot that Gauss-Seidel leaves near its cone's edge may
    # stick (on the edge) or slide; the best (or Gauss-Seidel's own solution) is kept, and
    # once a polish is exact to roundoff the others are not tried (a loop over the margins,
    # not `jax.vmap`: the same program, but traced without batching every operation of the
    # polish's unrolled solve)
    violation = lambda x: _violation(W, c, target, present, mu, bilateral, x)  # noqa: E731
    exact = _exact(c)

    fits = lambda error: error <= 1e-5 * jnp.max(jnp.abs(c)) + tol.velocity  # noqa: E731
    # where no polish of Gauss-Seidel's pattern fits (its sweeps need not converge where
    # sliding friction makes the problem unsymmetric: a d12's face landing flat as it slides
    # 50 times faster than it approaches), the patterns of one to three slots pushing and
    # sliding against their slips before, from impulses on the cone's edge of the size of
    # Gauss-Seidel's (the polish's least change from a start far larger than the solution
    # would leave its regularisation's error in the equalities)
    # (where the sweeps end with no impulse at all, the size of the impulse that alone would
    # meet a slot's target: a corner landing as it slides 11 times faster than it approaches,
    # `mu` 1.5, whose sweeps alternate between no impulse and one whose friction lifts it)
    slips = c[:, 1:]
    away = slips / jnp.maximum(_safe_norm(slips), tiny)[:, None]
    swept = jnp.max(jnp.abs(lam[:, 0]))
    alone = jnp.where(
        present, (target - c[:, 0]) / jnp.maximum(jnp.einsum("iaia->ia", W)[:, 0], tiny), 0.0
    )
    size = jnp.maximum(jnp.where(swept > 0, swept, jnp.max(alone)), tiny)
    edge = size * jnp.concatenate([jnp.ones((c.shape[0], 1), dtype), -mu[:, None] * away], axis=1)

    # and where a lone slot slides and nothing fits, its sliding direction from a scan of
    # the circle of directions of its slip after (`_lone_slide`), polished in turn
    lone = jnp.sum(present) == 1

    def polish(carry, item):  # carry: (an exact polish found, a polish that fits found)
        done, fitted = carry
        # own: Gauss-Seidel's pattern; scanned: the lone slot's slide; else `pattern`'s
        margin, pattern, own, scanned = item
        plain = jnp.where(own, lam, jnp.where((pattern & present)[:, None], edge, 0.0))

        def tried():
            start, found = jax.lax.cond(
                scanned,
                lambda: _lone_slide(W, c, target, present, mu, tol.velocity),
                lambda: (plain, jnp.array(True)),
            )
            polished = _polish(W, c, target, present, mu, bilateral, start, margin, exact)
            return polished, jnp.where(found, violation(polished), jnp.inf)

        untried = lambda: (jnp.zeros_like(lam), jnp.array(jnp.inf, dtype))  # noqa: E731
        unneeded = jnp.where(scanned, ~lone, ~jnp.any(pattern & present))
        skip = done | (~own & (fitted | unneeded))
        polished, error = jax.lax.cond(skip, untried, tried)
        return (done | (error <= exact), fitted | fits(error)), (polished, error)

    patterns = POLISH_PATTERNS[: len(POLISH_PATTERNS) if c.shape[0] == SLOTS else 0]
    margins, others = len(POLISH_MARGINS), len(patterns) + 1
    items = (
        jnp.array(POLISH_MARGINS + (POLISH_MARGINS[0],) * others, dtype),
        jnp.array([[False] * c.shape[0]] * margins + patterns + [[False] * c.shape[0]], bool),
        jnp.array([True] * margins + [False] * others),
        jnp.array([False] * (margins + len(patterns)) + [True]),
    )
    swept_error = violation(lam)
    start = (jnp.array(False), fits(swept_error))
    _, (polished, errors) = jax.lax.scan(polish, start, items)
    tries = jnp.concatenate([lam[None], polished])
    errors = jnp.concatenate([swept_error[None], errors])
    # prefer an exact (polished) solution on ties: derivatives flow through it only
    best = jnp.argmin(errors.at[0].set(2.0 * errors[0] + tol.velocity))
    lam = tries[best]
    consistent = fits(errors[best])
    u_after = u + jnp.einsum("ia,iad->d", lam, minv)
    generalised = jnp.einsum("ia,iad->d", lam, J)
    after = State(state.pos, state.quat, u_after[:3], u_after[3:] @ problem.R)  # omega: body
    impulse, moment = generalised[:3], generalised[3:]
    # where the impulse acts: the point of its line of action on the tangent plane of the
    # first slot's point
    jn = impulse @ n[0]
    arm = cross(impulse, moment) / jnp.maximum(jnp.sum(impulse**2), tiny)
    lowest = problem.r[0]
    pushes = jn > 0
    along = ((lowest - arm) @ n[0]) / jnp.where(pushes, jn, 1.0)
    arm = jnp.where(pushes, arm + impulse * along, lowest)
    return ImpactOutcome(after, impulse, state.pos + arm, consistent)


def solve_impacts(state, geom, points, touching, scene, tol, frames=None, mu=None):
    """The impact at `state` (unit quaternion) at the contact `points` (Q, 3) (world offsets
    from the mass centre) of which `touching` (Q,) touch the surface (`impact_problem`),
    four ways: Newton-Coulomb, frictionless, the limit of a bounce series (frictionless,
    holding every touching point), and frictionless plastic. Returns an `ImpactOutcome`
    with a leading axis of `VARIANTS`."""
    problem = impact_problem(state, geom, points, touching, scene, frames, mu)
    parameters = variant_parameters(scene.floor.restitution, problem.mu)
    return jax.lax.map(lambda args: solve_variant(problem, *args, tol), parameters)
