"""The values a segment needs at the end of every step, from one solve of the mode there.

diffrax evaluates a segment's event function at the end of each step, and the step-size
controller (`_step_limit.py`) needs the step limit at the state the next step starts from:
the same state. Each computed where it was asked for, they cost two solves of the mode per
step (and two copies of that solve in the compiled program). Here the solver around the
user's (`CarryingSolver`) appends both to the state it returns:

    y = (x, [c, h]),

x the segment's flat 13-vector (`flat`), c the event function (the smallest shifted
condition, docs/contact.md section 4) and h the step limit (s), both at x. The event
function reads c (`carried_event_value`), the controller h. [c, h] do not change within a
step, and the inner solver's steps, error estimates and dense output of x are those it
takes without them. At the segment's start the caller gives both (it has solved the mode
there already).

Where they come from at a step's end:

- With an explicit Runge-Kutta method whose last stage is the step's end (first same as
  last: Tsit5, Dopri5, Dopri8, Bosh3), that stage already solves the mode at (t1, x1) for
  the right-hand side. The right-hand side returns [c, h] beside the rates where the
  arguments say the stage is at the step's end (`mark(args, t1)`: the contact segment's
  `step_end`), and the solver reads them from the last stage's value, which the method keeps
  for the next step: no solve of its own, and no copy of the solve in the compiled program.
  The inner solver then works on (x, w), w the right-hand side's second output, whose
  increments and error are thrown away.
- Otherwise (`mark` None, or another method) `at_step_end(t1, x1, args)` computes them.

Between step ends, where the root find of an event evaluates the event function on the
dense output, the interpolation (`CarryingInterpolation`) computes c from the interpolated
x, differentiably: the event time's derivative comes from it. No step starts there, so the
second entry holds instead what the caller's `condition` puts there; the contact segment
puts the index of the smallest condition, so that the state diffrax returns at an event
(interpolated at the root) says which condition ended the segment, without another solve.
"""

from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp

CONDITION, LIMIT = 0, 1  # the entries of the carried values [c, h]
TRIGGER = 1  # at an interpolated state: the entry after c (see the module docstring)


def carried_event_value(t, y, args, **kwargs):
    """The event function of a segment: the carried c of `y` (module docstring), in JAX's
    default float dtype (diffrax compares it with a Python float)."""
    del t, args, kwargs
    return y[1][CONDITION].astype(jnp.result_type(float))


def _on_state(terms, values):
    """`terms` (an ODE term on y = (x, values)) as a term on x alone."""
    return dfx.ODETerm(lambda t, x, args: terms.vf(t, (x, values), args)[0])


def _encoded(values):
    """`values` as finite numbers and the signs of their infinities (a step limit may be
    inf): the inner solver sums the right-hand side's w with the step, and in a
    derivative's backward pass an infinite w would give 0 * inf = NaN, discarded or not."""
    infinite = jnp.isinf(values)
    return jnp.where(infinite, 0.0, values), jnp.where(infinite, jnp.sign(values), 0.0)


def _decoded(encoded):
    finite, sign = encoded
    return jnp.where(sign != 0, sign * jnp.inf, finite)


def _with_last_stage(terms, values):
    """`terms` as a term on (x, w): its rates and, as w's, its second output, encoded
    (`_encoded`; module docstring)."""

    def rates(t, xw, args):
        dx, w = terms.vf(t, (xw[0], values), args)
        return dx, _encoded(w)

    return dfx.ODETerm(rates)


def reads_last_stage(solver) -> bool:
    """Whether `solver` is an explicit Runge-Kutta method whose last stage is its step's end
    and whose state keeps that stage's value for the next step (diffrax's first-same-as-last
    methods; module docstring)."""
    tableau = getattr(solver, "tableau", None)
    return (
        isinstance(solver, dfx.AbstractRungeKutta)
        and isinstance(tableau, dfx.ButcherTableau)
        and not tableau.implicit
        and tableau.fsal
        and tableau.ssal
    )


class CarryingInterpolation(dfx.AbstractLocalInterpolation):
    """The inner solver's dense output of x, with [c, k] = `condition(t, x, args)` computed
    at the interpolated state (k: the caller's; the contact segment's trigger)."""

    t0: object
    t1: object
    inner: dfx.AbstractLocalInterpolation
    args: object
    condition: Callable = eqx.field(static=True)

    def evaluate(self, t0, t1=None, left=True):
        x = self.inner.evaluate(t0, t1, left)
        if isinstance(x, tuple):  # the inner solver's (x, w) (module docstring)
            x = x[0]
        if t1 is not None:  # an increment: the values do not change
            return x, jnp.zeros(2, x.dtype)
        return x, self.condition(t0, x, self.args)


class CarryingSolver(dfx.AbstractWrappedSolver):
    """`solver` on the segment's state x, returning at each step's end y1 = (x1, [c, h])
    (no derivative needed: diffrax takes only the sign of c there, the controller h). Where
    `mark` is given and `solver` allows it (`reads_last_stage`), [c, h] come from the last
    stage: the right-hand side, called with the arguments `mark(args, t1)`, returns them
    beside the rates at time t1; else from `at_step_end(t1, x1, args)`. `condition(t, x,
    args)` -> [c, k] gives the event function c at an interpolated state, and k there in
    place of h (module docstring); `args` are the segment's arguments."""

    solver: dfx.AbstractSolver
    args: object
    at_step_end: Callable = eqx.field(static=True)
    condition: Callable = eqx.field(static=True)
    mark: Callable | None = eqx.field(static=True, default=None)

    @property
    def _last_stage(self) -> bool:
        return self.mark is not None and reads_last_stage(self.solver)

    @property
    def term_structure(self):
        return self.solver.term_structure

    @property
    def term_compatible_contr_kwargs(self):
        return self.solver.term_compatible_contr_kwargs

    @property
    def scan_kind(self):
        """The inner Runge-Kutta solver's loop over its stages (diffrax's adjoints set it,
        e.g. to `"lax"` for forward-mode derivatives, through this attribute)."""
        return self.solver.scan_kind

    @property
    def interpolation_cls(self):
        def build(*, t0, t1, **dense_info):
            inner = self.solver.interpolation_cls(t0=t0, t1=t1, **dense_info)
            return CarryingInterpolation(t0, t1, inner, self.args, self.condition)

        return build

    def order(self, terms):
        return self.solver.order(terms)

    def strong_order(self, terms):
        return self.solver.strong_order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        x0, values0 = y0
        if self._last_stage:
            inner_y0 = (x0, _encoded(values0))
            return self.solver.init(_with_last_stage(terms, values0), t0, t1, inner_y0, args)
        return self.solver.init(_on_state(terms, values0), t0, t1, x0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        x0, values0 = y0
        if self._last_stage:
            (x1, _), xw_error, dense_info, solver_state, result = self.solver.step(
                _with_last_stage(terms, values0),
                t0,
                t1,
                (x0, _encoded(values0)),
                self.mark(args, t1),
                solver_state,
                made_jump,
            )
            _, (_, w1) = solver_state  # the last stage's value: (rates, [c, h] encoded)
            values1 = _decoded(w1)
            x_error = None if xw_error is None else xw_error[0]
        else:
            x1, x_error, dense_info, solver_state, result = self.solver.step(
                _on_state(terms, values0), t0, t1, x0, args, solver_state, made_jump
            )
            values1 = self.at_step_end(t1, x1, args)
        y_error = None if x_error is None else (x_error, jnp.zeros_like(values1))
        return (x1, values1), y_error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)
