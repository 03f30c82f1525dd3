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

The event itself is located outside diffrax (`_event_root.py`): diffrax stops at the end of
the step in which c fell to zero (its event without a root finder), and the solver's state
keeps that step's span and the inner solver's dense output of x (`LastStep`), returned by
`diffrax.SaveAt(solver_state=True)`. The root find there evaluates the conditions on the
dense output and returns, beside the time, the conditions at the root, whose least ended
the segment: the state at the root is only interpolated, with no solve of the mode there.
(With diffrax's own root find, the state diffrax returned at the root was interpolated with
the event function at it, a copy of the mode's solve kept only for that index.) Between
step ends the dense output the solver gives diffrax (for the saves) interpolates x alone.
"""

from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp

CONDITION, LIMIT = 0, 1  # the entries of the carried values [c, h]


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
    """The inner solver's dense output of x, as the segment's state (x, [0, 0]): the saves
    read x alone."""

    t0: object
    t1: object
    inner: dfx.AbstractLocalInterpolation

    def evaluate(self, t0, t1=None, left=True):
        x = self.inner.evaluate(t0, t1, left)
        if isinstance(x, tuple):  # the inner solver's (x, w) (module docstring)
            x = x[0]
        return x, jnp.zeros(2, x.dtype)


class LastStep(eqx.Module):
    """The last accepted step: its span [t0, t1] (s) and the inner solver's dense output of
    x alone over it (`dense`, the keyword arguments of its `interpolation_cls`); before the
    first step, x0 held over [t0, t0 + 1]."""

    t0: object
    t1: object
    dense: dict


def _x_part(dense_info, last_stage):
    """The inner solver's dense output restricted to x (on (x, w) every entry is a pair)."""
    return {k: v[0] for k, v in dense_info.items()} if last_stage else dict(dense_info)


class CarryingSolver(dfx.AbstractWrappedSolver):
    """`solver` on the segment's state x, returning at each step's end y1 = (x1, [c, h])
    (no derivative needed: diffrax takes only the sign of c there, the controller h). Where
    `mark` is given and `solver` allows it (`reads_last_stage`), [c, h] come from the last
    stage: the right-hand side, called with the arguments `mark(args, t1)`, returns them
    beside the rates at time t1; else from `at_step_end(t1, x1, args)`. Its state is the
    inner solver's and the `LastStep` (`last_step`)."""

    solver: dfx.AbstractSolver
    at_step_end: Callable = eqx.field(static=True)
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
            return CarryingInterpolation(t0, t1, inner)

        return build

    def order(self, terms):
        return self.solver.order(terms)

    def strong_order(self, terms):
        return self.solver.strong_order(terms)

    def error_order(self, terms):
        return self.solver.error_order(terms)

    def _inner(self, terms, y0):
        """The inner solver's term and state for `terms` on y0 = (x0, [c, h])."""
        x0, values0 = y0
        if self._last_stage:
            return _with_last_stage(terms, values0), (x0, _encoded(values0))
        return _on_state(terms, values0), x0

    def init(self, terms, t0, t1, y0, args):
        inner_terms, inner_y0 = self._inner(terms, y0)
        inner = self.solver.init(inner_terms, t0, t1, inner_y0, args)
        # before the first step: x0 held over a unit span (y0 = y1 = x0, no stages), so that
        # its dense output is finite where it is evaluated and thrown away (a member of a
        # batch that takes no step); the shapes from a step traced only
        shapes = eqx.filter_eval_shape(
            self.solver.step, inner_terms, t0, t1, inner_y0, args, inner, False
        )[2]
        x0 = y0[0]
        dense = {
            k: jnp.broadcast_to(x0, v.shape) if k in ("y0", "y1") else jnp.zeros(v.shape, v.dtype)
            for k, v in _x_part(shapes, self._last_stage).items()
        }
        return inner, LastStep(t0, t0 + 1, dense)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        inner_terms, inner_y0 = self._inner(terms, y0)
        inner_state, _ = solver_state
        if self._last_stage:
            (x1, _), xw_error, dense_info, inner_state, result = self.solver.step(
                inner_terms, t0, t1, inner_y0, self.mark(args, t1), inner_state, made_jump
            )
            _, (_, w1) = inner_state  # the last stage's value: (rates, [c, h] encoded)
            values1 = _decoded(w1)
            x_error = None if xw_error is None else xw_error[0]
        else:
            x1, x_error, dense_info, inner_state, result = self.solver.step(
                inner_terms, t0, t1, inner_y0, args, inner_state, made_jump
            )
            values1 = self.at_step_end(t1, x1, args)
        y_error = None if x_error is None else (x_error, jnp.zeros_like(values1))
        last = LastStep(t0, t1, _x_part(dense_info, self._last_stage))
        return (x1, values1), y_error, dense_info, (inner_state, last), result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)


def last_step(solver: CarryingSolver, solver_state) -> dfx.AbstractLocalInterpolation:
    """The inner solver's dense output of x over the last accepted step, from the final
    `solver_state` of a solve with `solver` (`diffrax.SaveAt(solver_state=True)`)."""
    _, last = solver_state
    return solver.solver.interpolation_cls(t0=last.t0, t1=last.t1, **last.dense)
