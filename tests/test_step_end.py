"""The values a contact segment carries beside its state (`jaxrb/contact/_step_end.py`): the
solver around the user's leaves the user's solver's steps alone, the event fires where the
carried event function crosses zero (located on the dense output), the state at the event
names the condition that ended the run, every step is cut to the carried step limit, and
the values read from a first-same-as-last method's last stage are those computed apart."""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

from jaxrb.contact._events import EventTime
from jaxrb.contact._step_end import (
    CONDITION,
    LIMIT,
    TRIGGER,
    CarryingSolver,
    carried_event_value,
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


def _position(t, y, args):
    return y[0]


def _state_and_carried(t, y, args):
    return y


class _Args(eqx.Module):
    """The oscillator's arguments for the last-stage path: the velocity's condition, and the
    time of the running step's end (NaN outside a step)."""

    v_min: object
    step_end: object

    def marked(self, t1):
        return eqx.tree_at(lambda a: a.step_end, self, jnp.asarray(t1, jnp.result_type(float)))


@persistent(static_argnames=("fn", "solver", "last_stage"))
def _carrying(limit, v_min=-jnp.inf, fn=_position, solver=TSIT5, last_stage=False):
    """The problem with [c, h] carried beside the state, h = `limit` (s); at an
    interpolated state [c, k], k the index of the smaller condition. `fn` what is saved.
    [c, h] read from `solver`'s last stage (`last_stage`: the right-hand side returns them
    at the step's end) or computed at each step's end."""

    def at_step_end(t, x, args):
        return jnp.stack([_condition(t, x, args.v_min), jnp.asarray(limit, x.dtype)])

    def rates(t, y, args):
        x, _ = y
        at_end = t == args.step_end
        return _rates(t, x, args), jnp.where(at_end, at_step_end(t, x, args), 0.0)

    def condition(t, x, args):
        values = _conditions(t, x, args.v_min)
        return jnp.stack([jnp.min(values), jnp.argmin(values).astype(x.dtype)])

    args = _Args(v_min, jnp.array(jnp.nan))
    x0 = jnp.array([1.0, 0.0])
    return dfx.diffeqsolve(
        dfx.ODETerm(rates),
        CarryingSolver(solver, args, at_step_end, condition, _Args.marked if last_stage else None),
        0.0,
        T_END,
        None,
        (x0, at_step_end(0.0, x0, args)),
        args=args,
        stepsize_controller=limited(dfx.PIDController(rtol=1e-8, atol=1e-8)),
        saveat=dfx.SaveAt(t1=True, steps=True, fn=fn),
        event=dfx.Event(carried_event_value, ROOT, direction=False),
        max_steps=4096,
    )


def test_carried_values_leave_the_solvers_steps_alone():
    """With a step limit that never binds, the carried run takes the plain run's steps and
    finds its event time and state to roundoff; the event function at the event (computed by
    the dense output) is zero there."""
    plain = _plain(None)
    carried = _carrying(jnp.inf)
    assert int(plain.stats["num_accepted_steps"]) == int(carried.stats["num_accepted_steps"])
    assert int(plain.stats["num_rejected_steps"]) == int(carried.stats["num_rejected_steps"])
    assert bool(plain.event_mask) and bool(carried.event_mask)
    t_event = float(plain.ts[-1])
    assert 1.0 < t_event < T_END  # the oscillator reached -0.5 after its first half swing
    ts = np.asarray(carried.ts)
    ys = np.asarray(carried.ys)
    last = np.flatnonzero(np.isfinite(ts))[-1]
    np.testing.assert_allclose(ts[last], t_event, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ys[last], np.asarray(plain.ys[-1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(ys[last, 0], -0.5, rtol=0, atol=1e-9)


def test_every_step_is_cut_to_the_carried_limit():
    """With a carried step limit of 0.05 s (well under the steps the tolerance allows) every
    step is at most that long, and the run matches the plain run whose controller caps its
    steps at 0.05 s the same way (diffrax's `dtmax`)."""
    carried = _carrying(0.05)
    plain = _plain(0.05)
    ts = np.asarray(carried.ts)
    ts = ts[np.isfinite(ts)]
    steps = np.diff(ts)
    assert len(steps) > 0.9 * float(plain.ts[-1]) / 0.05  # the limit bound the steps
    assert np.max(steps) <= 0.05 * (1 + 1e-12)
    np.testing.assert_allclose(ts[-1], float(plain.ts[-1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(carried.ys)[len(ts) - 1], np.asarray(plain.ys[-1]), rtol=0, atol=1e-10
    )


@pytest.mark.parametrize("v_min, which", [(-jnp.inf, 0), (-0.8, 1)])
def test_the_state_at_the_event_names_the_condition_that_ended_the_run(v_min, which):
    """The state diffrax returns at an event is interpolated at the root: beside it the event
    function (zero there) and the index of the condition that ended the run, as the contact
    segment reads its trigger. With the velocity's condition at -0.8 the velocity ends the
    run before the position reaches -0.5; without it, the position does."""
    carried = _carrying(jnp.inf, v_min, fn=_state_and_carried)
    plain = _plain(None, v_min)
    last = np.flatnonzero(np.isfinite(np.asarray(carried.ts)))[-1]
    x_end, values_end = carried.ys[0][last], carried.ys[1][last]
    assert int(values_end[TRIGGER]) == which
    np.testing.assert_allclose(float(values_end[CONDITION]), 0.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(float(x_end[which]), [-0.5, -0.8][which], rtol=0, atol=1e-9)
    np.testing.assert_allclose(float(carried.ts[last]), float(plain.ts[-1]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("solver", [dfx.Tsit5(), dfx.Dopri8()], ids=["tsit5", "dopri8"])
def test_values_from_the_last_stage_equal_those_computed_at_each_step_end(solver):
    """With a first-same-as-last method the carried values come from the right-hand side's
    last stage, at the step's end: every step's [c, h] equals the one computed there apart
    (to roundoff), the steps, the event time and the trigger are the same, and every step
    was cut to the carried limit (so h reached the controller)."""
    assert reads_last_stage(solver)
    read = _carrying(0.05, -0.8, _state_and_carried, solver, last_stage=True)
    apart = _carrying(0.05, -0.8, _state_and_carried, solver, last_stage=False)
    ts_read, ts_apart = np.asarray(read.ts), np.asarray(apart.ts)
    n = np.flatnonzero(np.isfinite(ts_apart))[-1] + 1
    assert np.flatnonzero(np.isfinite(ts_read))[-1] + 1 == n
    np.testing.assert_allclose(ts_read[:n], ts_apart[:n], rtol=0, atol=1e-13)
    x_read, v_read = (np.asarray(a)[:n] for a in read.ys)
    x_apart, v_apart = (np.asarray(a)[:n] for a in apart.ys)
    np.testing.assert_allclose(x_read, x_apart, rtol=0, atol=1e-13)
    # every step's end (the last save is the event's interpolated state: [c, trigger])
    np.testing.assert_allclose(v_read[:-1, :2], v_apart[:-1, :2], rtol=0, atol=1e-13)
    np.testing.assert_allclose(v_read[:-1, LIMIT], 0.05)
    assert int(v_read[-1, TRIGGER]) == int(v_apart[-1, TRIGGER]) == 1
    assert np.max(np.diff(ts_read[:n])) <= 0.05 * (1 + 1e-12)
    assert n > 0.9 * float(ts_read[n - 1]) / 0.05


def test_a_method_without_first_same_as_last_computes_the_values_apart():
    """Heun's and Euler's methods have no last stage at the step's end: `reads_last_stage`
    says so, and the solver computes the values at each step's end even when given `mark`."""
    for method in (dfx.Heun(), dfx.Euler()):
        assert not reads_last_stage(method)
        solver = CarryingSolver(method, None, _condition, _condition, _Args.marked)
        assert not solver._last_stage
