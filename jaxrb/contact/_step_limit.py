"""A step-size limit that keeps the solver from stepping over a brief touch of the floor,
or over the stop of a slide.

diffrax looks for an event only at the ends of each step: a corner of a fast-spinning die
can dip under the floor and come back up within one step, and the touch is missed. The
limit below bounds every step so that no free contact point can reach the floor within it,
unless the step is already so short that the deepest dip it could hide is a quarter of the
contact tolerance (docs/contact.md, section 4):

    h_i = largest h with  v_i h + A_i h^2 / 2 <= k g_i,       h = max(min_i h_i, h_floor),

for each contact point i the mode does not hold, with gap g_i > 0, approach speed
v_i = max(-g_i', 0) and A_i twice its acceleration's magnitude (a bound over the step);
k = 0.8, and h_floor = sqrt(2 contact_tol / A) (A the largest A_i), below which a dip of a
point with acceleration A can reach A h^2 / 8 = contact_tol / 4 at most. The gap then
shrinks to about a fifth per step until h_floor; a real touch is crossed in a step of about
h_floor, so that the event is located on the dense output of a short step. Far from the
floor the limit is inactive. (With k = 1/2 a die's corner took about ten steps down to the
floor per bounce, with 0.8 about six, with the same errors at tolerances of 1e-8 and
tighter.)

A slide that stops is the same kind of dip: the slip's speed |s| falls to zero and, with
friction turning round, rises again, and its condition (|s| - slip_stop / 2, section 4)
is negative only for the time slip_stop / |s'| around the stop, a few microseconds. The
slip limit (`slip_step_limit`) bounds the step likewise, by k (|s| - slip_stop / 2) / |s'|
with k = 1/2 but not below slip_stop / (2 |s'|), half that window: the slip shrinks by
about half per step and a step then ends inside the window. Without it, whether a step
ended there was a matter of chance, and a coin whose face slide was stepped over slid on
round zero, its slip turning back and forth, for 10^4 steps.
"""

import diffrax as dfx
import jax
import jax.numpy as jnp

from ._events import mode_slips, slips_as_twist
from ._modes import FLIGHT, active_points, no_derivative
from ._step_end import LIMIT

GAP_SHRINK = 0.8  # k: the fraction of a gap a step may close
SLIP_SHRINK = 0.5  # k of a slip (`slip_step_limit`)
STABLE_STEPS = 1.0  # beta h: the longest step in a contact mode, in units of 1 / beta


def step_limit_of(sol, mode, offsets, model, tol) -> jax.Array:
    """The largest step (s) from the state of the mode's solution `sol` in `mode` (module
    docstring; no derivative); `offsets`: the gap conditions' start shifts (a point whose
    gap starts at its boundary is not limited: it is the contact the segment began on)."""
    sol, mode, offsets = no_derivative((sol, mode, offsets))
    geom = sol.geom
    P = model.num_points
    dtype = geom.gap.dtype
    free = ~active_points(model, mode) & (offsets[:P] == 0) & (geom.gap > 0)
    gap = jnp.where(free, geom.gap, 1.0)
    speed = jnp.maximum(-geom.gap_rate, 0.0)
    # a curved surface's gap also changes as the point moves along it: n' . v_p
    curving = jnp.abs(jnp.sum(geom.slip * geom.n_dot, axis=-1))
    acc = 2.0 * (jnp.linalg.norm(sol.point_accelerations(), axis=-1) + curving)
    acc = acc + jnp.finfo(dtype).tiny
    room = GAP_SHRINK * gap
    # v h + A h^2 / 2 = room, in the form that does not cancel
    h = 2.0 * room / (speed + jnp.sqrt(speed**2 + 2.0 * acc * room))
    h_points = jnp.where(free, h, jnp.inf)
    h_floor = jnp.sqrt(2.0 * tol.contact / jnp.max(jnp.where(free, acc, jnp.finfo(dtype).tiny)))
    h = jnp.maximum(jnp.min(h_points), h_floor)
    # a mode that holds the body relaxes its drift at the rate beta: an explicit solver
    # stepping far beyond 1 / beta is unstable there, and a body at rest would rock at the
    # level of the tolerances instead of staying put
    steady = STABLE_STEPS / tol.stabilisation if tol.stabilisation else jnp.inf
    h = jnp.minimum(h, slip_step_limit(sol, mode, model, tol))
    return jnp.where(mode.kind == FLIGHT, h, jnp.minimum(h, steady))


def slip_step_limit(sol, mode, model, tol) -> jax.Array:
    """The largest step (s) over which no slide can stop unseen (module docstring): for
    each slip s that ends when |s| falls to slip_stop / 2 (a slide that did not start from
    rest), with the rate s' of the slip, h = max(k (|s| - slip_stop / 2), slip_stop / 2) /
    |s'|. The slip then shrinks by at most about half per step, and, near zero, a step is
    at most half the time it spends within slip_stop / 2 of zero, so that a step ends
    there: the end of a slide is a dip of |s|, which a test of signs at the ends of longer
    steps could step over."""
    geom = sol.geom
    dtype = geom.gap.dtype
    slips, sliding, points = mode_slips(sol, mode)
    slides = sliding & ~mode.from_rest
    rates = geom.tangential(sol.point_accelerations())[points]
    on_face = slips_as_twist(mode)
    rates = rates.at[0].set(jnp.where(on_face, sol.twist_rate(model, mode.face), rates[0]))
    speed = jnp.linalg.norm(slips, axis=-1)
    change = jnp.linalg.norm(rates, axis=-1) + jnp.finfo(dtype).tiny
    room = jnp.maximum(SLIP_SHRINK * (speed - 0.5 * tol.slip_stop), 0.5 * tol.slip_stop)
    return jnp.min(jnp.where(slides, room / change, jnp.inf))


class GapLimitedSteps(dfx.AbstractStepSizeController):
    """Wraps the user's step-size controller: every step it proposes is cut to the step
    limit h carried in the state the step starts from (y = (x, [c, h]), `_step_end.py`);
    the inner controller sees x alone."""

    inner: dfx.AbstractStepSizeController

    def wrap(self, direction):
        return type(self)(self.inner.wrap(direction))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        x0, values0 = y0

        def func_on_state(terms, t, x, args):
            return func(terms, t, (x, values0), args)[0]

        t_next, state = self.inner.init(terms, t0, t1, x0, dt0, args, func_on_state, error_order)
        return jnp.minimum(t_next, t0 + values0[LIMIT]), state

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        (x0, values0), (x1, values1) = y0, y1_candidate
        x_error = None if y_error is None else y_error[0]
        keep, next_t0, next_t1, jump, state, result = self.inner.adapt_step_size(
            t0, t1, x0, x1, args, x_error, error_order, state
        )
        limit = jnp.where(keep, values1[LIMIT], values0[LIMIT])
        next_t1 = jnp.minimum(next_t1, next_t0 + limit)
        return keep, next_t0, next_t1, jump, state, result


class GapLimitedAdaptiveSteps(GapLimitedSteps, dfx.AbstractAdaptiveStepSizeController):
    """`GapLimitedSteps` around an adaptive controller (its tolerances stay visible, e.g.
    to an implicit solver's root finder)."""

    @property
    def rtol(self):
        return self.inner.rtol

    @property
    def atol(self):
        return self.inner.atol

    @property
    def norm(self):
        return self.inner.norm


def limited(controller):
    """`controller` with its steps cut to the carried step limit."""
    if isinstance(controller, dfx.AbstractAdaptiveStepSizeController):
        return GapLimitedAdaptiveSteps(controller)
    return GapLimitedSteps(controller)
