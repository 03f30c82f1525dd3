"""The values a contact segment carries beside its state (`jaxrb/contact/_step_end.py`) and
the event located on the last step (`jaxrb/contact/_event_root.py`): the solver around the
user's leaves the user's solver's steps alone, the event is found where the carried event
function crosses zero (on the dense output of the step that diffrax stopped after, kept in
the solver's state) with the condition that ended the run, every step is cut to the carried
step limit, and the values read from a first-same-as-last method's last stage are those
computed apart."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from programs import persistent

from jaxrb.contact._event_root import EventTime, event_root
from jaxrb.contact._step_end import (
    LIMIT,
    CarryingSolver,
    carried_event_value,
    last_step,
    reads_last_stage,
)
from jaxrb.contact._step_limit import limited

ROOT = EventTime(rtol=1e-12, atol=1e-12)
TSIT5 = dfx.Tsit5()
T_END = 10.0


def _rates(t, x, args):  # a damped oscillator: x = (position, velocity)
    return jnp.stack([x[1], -x[0] - 0.1 * x[1]])


def _conditions(t, x, args):
    """Two conditions: the position falls through -0.5 (0), the velocity through `args`."""
    return jnp.stack([x[0] + 0.5, x[1] - args])


def _condition(t, x, args):  # the event function: the smaller condition
    return jnp.min(_conditions(t, x, args))


@persistent
def _plain(dtmax, v_min=-jnp.inf):
    """The same problem without carried values: the event function evaluated by diffrax."""
    return dfx.diffeqsolve(
        dfx.ODETerm(_rates),
        dfx.Tsit5(),
        0.0,
        T_END,
        None,
        jnp.array([1.0, 0.0]),
        args=v_min,
        stepsize_controller=dfx.PIDController(rtol=1e-8, atol=1e-8, dtmax=dtmax),
        saveat=dfx.SaveAt(t1=True),
        event=dfx.Event(lambda t, y, args, **kw: _condition(t, y, args), ROOT, direction=False),
        max_steps=4096,
    )


class _Args(eqx.Module):
    """The oscillator's arguments for the last-stage path: the velocity's condition, and the
    time of the running step's end (NaN outside a step)."""

    v_min: object
    step_end: object

    def marked(self, t1):
        return eqx.tree_at(lambda a: a.step_end, self, jnp.asarray(t1, jnp.result_type(float)))


def _carrying_run(limit, v_min=-jnp.inf, solver=TSIT5, last_stage=False):
    """The problem with [c, h] carried beside the state, h = `limit` (s), saved at every
    step's end; diffrax stops after the step in which c fell to zero, and the event is
    located on that step's dense output: its time, state and the index of the condition
    that fired (0 the position, 1 the velocity). [c, h] read from `solver`'s last stage
    (`last_stage`: the right-hand side returns them at the step's end) or computed at each
    step's end."""

    def at_step_end(t, x, args):
        return jnp.stack([_condition(t, x, args.v_min), jnp.asarray(limit, x.dtype)])

    def rates(t, y, args):
        x, _ = y
        at_end = t == args.step_end
        return _rates(t, x, args), jnp.where(at_end, at_step_end(t, x, args), 0.0)

    args = _Args(v_min, jnp.array(jnp.nan))
    x0 = jnp.array([1.0, 0.0])
    carrying = CarryingSolver(solver, at_step_end, _Args.marked if last_stage else None)
    sol = dfx.diffeqsolve(
        dfx.ODETerm(rates),
        carrying,
        0.0,
        T_END,
        None,
        (x0, at_step_end(0.0, x0, args)),
        args=args,
        stepsize_controller=limited(dfx.PIDController(rtol=1e-8, atol=1e-8)),
        saveat=dfx.SaveAt(t1=True, steps=True, solver_state=True),
        event=dfx.Event(carried_event_value, direction=False),
        max_steps=4096,
    )
    happened = jnp.asarray(sol.event_mask)
    step = last_step(carrying, sol.solver_state)
    t, x, trigger, _ = event_root(
        step, lambda t, x, args: _conditions(t, x, args.v_min), args, happened, ROOT
    )
    return dict(
        ts=sol.ts,
        ys=sol.ys,
        steps=sol.stats["num_accepted_steps"],
        rejected=sol.stats["num_rejected_steps"],
        happened=happened,
        t=t,
        x=x,
        trigger=trigger,
    )


_carrying = persistent(static_argnames=("solver", "last_stage"))(_carrying_run)


def test_carried_values_leave_the_solvers_steps_alone():
    """With a step limit that never binds, the carried run takes the plain run's steps and
    finds its event time and state to roundoff, on the last step's dense output; the
    position there is the condition's -0.5."""
    plain = _plain(None)
    carried = _carrying(jnp.inf)
    assert int(plain.stats["num_accepted_steps"]) == int(carried["steps"])
    assert int(plain.stats["num_rejected_steps"]) == int(carried["rejected"])
    assert bool(plain.event_mask) and bool(carried["happened"])
    t_event = float(plain.ts[-1])
    assert 1.0 < t_event < T_END  # the oscillator reached -0.5 after its first half swing
    ts = np.asarray(carried["ts"])
    last = np.flatnonzero(np.isfinite(ts))[-1]
    assert ts[last - 1] < t_event <= ts[last]  # diffrax stopped after the event's step
    np.testing.assert_allclose(float(carried["t"]), t_event, rtol=0, atol=1e-12)
    x_event = np.asarray(carried["x"])
    np.testing.assert_allclose(x_event, np.asarray(plain.ys[-1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(x_event[0], -0.5, rtol=0, atol=1e-9)


def test_every_step_is_cut_to_the_carried_limit():
    """With a carried step limit of 0.05 s (well under the steps the tolerance allows) every
    step is at most that long, and the run matches the plain run whose controller caps its
    steps at 0.05 s the same way (diffrax's `dtmax`)."""
    carried = _carrying(0.05)
    plain = _plain(0.05)
    ts = np.asarray(carried["ts"])
    ts = ts[np.isfinite(ts)]
    steps = np.diff(ts)
    assert len(steps) > 0.9 * float(plain.ts[-1]) / 0.05  # the limit bound the steps
    assert np.max(steps) <= 0.05 * (1 + 1e-12)
    np.testing.assert_allclose(float(carried["t"]), float(plain.ts[-1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(carried["x"]), np.asarray(plain.ys[-1]), rtol=0, atol=1e-10
    )


@pytest.mark.parametrize("v_min, which", [(-jnp.inf, 0), (-0.8, 1)])
def test_the_event_names_the_condition_that_ended_the_run(v_min, which):
    """The root find on the last step returns, beside the event time, the index of the
    condition that ended the run (the least of the conditions at the root), as the
    contact segment reads its trigger. With the velocity's condition at -0.8 the velocity
    ends the run before the position reaches -0.5; without it, the position does."""
    carried = _carrying(jnp.inf, v_min)
    plain = _plain(None, v_min)
    assert int(carried["trigger"]) == which
    x_event = np.asarray(carried["x"])
    np.testing.assert_allclose(float(x_event[which]), [-0.5, -0.8][which], rtol=0, atol=1e-9)
    np.testing.assert_allclose(float(carried["t"]), float(plain.ts[-1]), rtol=0, atol=1e-12)


def test_the_root_finder_returns_the_conditions_at_the_root():
    """`EventTime` returns beside the root the function's auxiliary output (here the
    conditions) interpolated between its final bracket's ends to the root: for conditions
    linear in t, their values there to roundoff (an end's values would be up to a slope
    times the time tolerance away, 1e-9 here), or, for a bracket already below the
    tolerance, evaluated at its midpoint. Two conditions whose zeros lie 1e-13 s apart,
    within the tolerance, are told apart: the one that falls to zero first ends the run."""
    slopes = jnp.array([2.0, 1e3, -1.0])
    zeros = jnp.array([0.3, 0.3 + 1e-13, -0.5])

    def fn(t, _):
        values = slopes * (zeros - t)
        return jnp.min(values), values

    # a long bracket, and one already below the tolerance (0.3 -/+ 4e-13 s): its midpoint is
    # returned, and the conditions evaluated there
    for lower, upper in ((0.0, 1.0), (0.3 - 4e-13, 0.3 + 4e-13)):
        sol = optx.root_find(
            fn, ROOT, upper, options=dict(lower=lower, upper=upper), has_aux=True, throw=False
        )
        root = float(sol.value)
        np.testing.assert_allclose(root, 0.3, rtol=0, atol=2e-12)
        np.testing.assert_allclose(
            np.asarray(sol.aux), np.asarray(fn(root, None)[1]), rtol=0, atol=1e-13
        )
        assert int(jnp.argmin(sol.aux)) == 0


def test_the_root_is_the_zero_of_the_condition_that_falls_not_of_the_least_at_the_start():
    """Where the condition least at the final bracket's lower end is not the one that falls
    to zero in it (a constant 1e-7 beside a condition falling at 1e6 per second, which
    crosses it 1e-13 s before its zero), the root is the falling condition's zero to
    roundoff: a line through the least's values at the two ends would put it up to 1e-12 s
    early, where the falling condition is still up to 1e-6 (the event's state would not yet
    be past the boundary that ended the segment)."""

    def fn(t, _):
        values = jnp.stack([jnp.asarray(1e-7) + 0.0 * t, 1e6 * (0.3 - t)])
        return jnp.min(values), values

    for lower, upper in ((0.0, 1.0), (0.29, 0.3 + 1e-3), (0.3 - 3e-12, 0.3 + 7e-12)):
        sol = optx.root_find(
            fn, ROOT, upper, options=dict(lower=lower, upper=upper), has_aux=True, throw=False
        )
        final = sol.state
        # the final bracket's least at its lower end is the constant (the case in question)
        assert float(final.f_lower) == 1e-7
        np.testing.assert_allclose(float(sol.value), 0.3, rtol=0, atol=1e-15)
        np.testing.assert_allclose(np.asarray(sol.aux), [1e-7, 0.0], rtol=0, atol=1e-9)
        assert int(jnp.argmin(sol.aux)) == 1


def test_the_event_time_and_state_are_differentiable():
    """The event time and the state there, found on the last step, differentiate through the
    root (implicit function theorem) and the step's dense output: their derivatives with
    respect to the velocity's threshold equal central differences (float64), and the event
    time's equals 1 / (the velocity's rate there), the inverse function's derivative."""

    def event(v_min):
        out = _carrying_run(jnp.inf, v_min)
        return jnp.concatenate([out["t"][None], out["x"]])

    v_min, h = jnp.array(-0.8), 1e-5
    derivative = np.asarray(jax.jit(jax.jacrev(event))(v_min))
    run = jax.jit(event)
    differences = (np.asarray(run(v_min + h)) - np.asarray(run(v_min - h))) / (2 * h)
    np.testing.assert_allclose(derivative, differences, rtol=1e-6, atol=1e-8)
    t, x = float(run(v_min)[0]), np.asarray(run(v_min)[1:])
    acceleration = float(_rates(t, x, None)[1])
    np.testing.assert_allclose(derivative[0], 1 / acceleration, rtol=1e-6)
    np.testing.assert_allclose(derivative[2], 1.0, rtol=1e-6)  # the velocity is v_min there


@pytest.mark.parametrize("solver", [dfx.Tsit5(), dfx.Dopri8()], ids=["tsit5", "dopri8"])
def test_values_from_the_last_stage_equal_those_computed_at_each_step_end(solver):
    """With a first-same-as-last method the carried values come from the right-hand side's
    last stage, at the step's end: every step's [c, h] equals the one computed there apart
    (to roundoff), the steps, the event time and the trigger are the same, and every step
    was cut to the carried limit (so h reached the controller)."""
    assert reads_last_stage(solver)
    read = _carrying(0.05, -0.8, solver, last_stage=True)
    apart = _carrying(0.05, -0.8, solver, last_stage=False)
    ts_read, ts_apart = np.asarray(read["ts"]), np.asarray(apart["ts"])
    n = np.flatnonzero(np.isfinite(ts_apart))[-1] + 1
    assert np.flatnonzero(np.isfinite(ts_read))[-1] + 1 == n
    np.testing.assert_allclose(ts_read[:n], ts_apart[:n], rtol=0, atol=1e-13)
    x_read, v_read = (np.asarray(a)[:n] for a in read["ys"])
    x_apart, v_apart = (np.asarray(a)[:n] for a in apart["ys"])
    np.testing.assert_allclose(x_read, x_apart, rtol=0, atol=1e-13)
    np.testing.assert_allclose(v_read, v_apart, rtol=0, atol=1e-13)  # every step's end
    np.testing.assert_allclose(v_read[:, LIMIT], 0.05)
    np.testing.assert_allclose(float(read["t"]), float(apart["t"]), rtol=0, atol=1e-13)
    assert int(read["trigger"]) == int(apart["trigger"]) == 1
    assert np.max(np.diff(ts_read[:n])) <= 0.05 * (1 + 1e-12)
    assert n > 0.9 * float(ts_read[n - 1]) / 0.05


def test_a_method_without_first_same_as_last_computes_the_values_apart():
    """Heun's and Euler's methods have no last stage at the step's end: `reads_last_stage`
    says so, and the solver computes the values at each step's end even when given `mark`."""
    for method in (dfx.Heun(), dfx.Euler()):
        assert not reads_last_stage(method)
        solver = CarryingSolver(method, _condition, _Args.marked)
        assert not solver._last_stage
