"""The values a segment needs at the end of every step, from one solve of the mode there.

diffrax evaluates a segment's event function at the end of each step, and the step-size
controller (`_step_limit.py`) needs the step limit at the state the next step starts from:
the same state. Each computed where it was asked for, they cost two solves of the mode per
step (and two copies of that solve in the compiled program). Here the solver around the
user's (`CarryingSolver`) appends both to the state it returns:

    y = (x, [c, h]),

x the segment's flat 13-vector (`flat`), c the event function (the smallest shifted
condition, docs/contact.md section 4) and h the step limit (s), both at x. The event
function reads c (`carried_event_value`), the controller h. The right-hand side leaves
[c, h] unchanged (derivative 0), and the inner solver never sees them: its steps, error
estimates and dense output are those of x alone. At the segment's start the caller gives
both (it has solved the mode there already).

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


def carried_rates(rates):
    """The right-hand side on y = (x, values) of `rates(t, x, args)`: the values stay."""

    def rhs(t, y, args):
        x, values = y
        return rates(t, x, args), jnp.zeros_like(values)

    return rhs


def _on_state(terms, values):
    """`terms` (an ODE term on y = (x, values)) as a term on x alone."""
    return dfx.ODETerm(lambda t, x, args: terms.vf(t, (x, values), args)[0])


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
        if t1 is not None:  # an increment: the values do not change
            return x, jnp.zeros(2, x.dtype)
        return x, self.condition(t0, x, self.args)


class CarryingSolver(dfx.AbstractWrappedSolver):
    """`solver` on the segment's state x, returning at each step's end y1 = (x1, [c, h])
    with `at_step_end(t1, x1, args)` -> [c, h] (no derivative needed: diffrax takes only the
    sign of c there, the controller h). `condition(t, x, args)` -> [c, k] gives the event
    function c at an interpolated state, and k there in place of h (module docstring);
    `args` are the segment's arguments."""

    solver: dfx.AbstractSolver
    args: object
    at_step_end: Callable = eqx.field(static=True)
    condition: Callable = eqx.field(static=True)

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
        return self.solver.init(_on_state(terms, values0), t0, t1, x0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        x0, values0 = y0
        x1, x_error, dense_info, solver_state, result = self.solver.step(
            _on_state(terms, values0), t0, t1, x0, args, solver_state, made_jump
        )
        values1 = self.at_step_end(t1, x1, args)
        y_error = None if x_error is None else (x_error, jnp.zeros_like(values1))
        return (x1, values1), y_error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)
