"""The values a contact segment carries beside its state (`jaxrb/contact/_step_end.py`): the
solver around the user's leaves the user's solver's steps alone, the event fires where the
carried event function crosses zero (located on the dense output), and every step is cut to
the carried step limit."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

from jaxrb.contact._events import EventTime
from jaxrb.contact._step_end import CarryingSolver, carried_event_value, carried_rates
from jaxrb.contact._step_limit import limited

ROOT = EventTime(rtol=1e-12, atol=1e-12)
T_END = 10.0


def _rates(t, x, args):  # a damped oscillator: x = (position, velocity)
    return jnp.stack([x[1], -x[0] - 0.1 * x[1]])


def _condition(t, x, args):  # fires when the position falls through -0.5
    return x[0] + 0.5


def _plain(dtmax):
    """The same problem without carried values: the event function evaluated by diffrax."""
    return dfx.diffeqsolve(
        dfx.ODETerm(_rates),
        dfx.Tsit5(),
        0.0,
        T_END,
        None,
        jnp.array([1.0, 0.0]),
        stepsize_controller=dfx.PIDController(rtol=1e-8, atol=1e-8, dtmax=dtmax),
        saveat=dfx.SaveAt(t1=True),
        event=dfx.Event(lambda t, y, args, **kw: _condition(t, y, args), ROOT, direction=False),
        max_steps=4096,
    )


def _carrying(limit):
    """The problem with [c, h] carried beside the state, h = `limit` (s)."""

    def at_step_end(t, x, args):
        return jnp.stack([_condition(t, x, args), jnp.asarray(limit, x.dtype)])

    x0 = jnp.array([1.0, 0.0])
    return dfx.diffeqsolve(
        dfx.ODETerm(carried_rates(_rates)),
        CarryingSolver(dfx.Tsit5(), None, at_step_end, _condition),
        0.0,
        T_END,
        None,
        (x0, at_step_end(0.0, x0, None)),
        stepsize_controller=limited(dfx.PIDController(rtol=1e-8, atol=1e-8)),
        saveat=dfx.SaveAt(t1=True, steps=True, fn=lambda t, y, args: y[0]),
        event=dfx.Event(carried_event_value, ROOT, direction=False),
        max_steps=4096,
    )


def test_carried_values_leave_the_solvers_steps_alone():
    """With a step limit that never binds, the carried run takes the plain run's steps and
    finds its event time and state to roundoff; the event function at the event (computed by
    the dense output) is zero there."""
    plain = jax.jit(lambda: _plain(None))()
    carried = jax.jit(lambda: _carrying(jnp.inf))()
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
    carried = jax.jit(lambda: _carrying(0.05))()
    plain = jax.jit(lambda: _plain(0.05))()
    ts = np.asarray(carried.ts)
    ts = ts[np.isfinite(ts)]
    steps = np.diff(ts)
    assert len(steps) > 0.9 * float(plain.ts[-1]) / 0.05  # the limit bound the steps
    assert np.max(steps) <= 0.05 * (1 + 1e-12)
    np.testing.assert_allclose(ts[-1], float(plain.ts[-1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(carried.ys)[len(ts) - 1], np.asarray(plain.ys[-1]), rtol=0, atol=1e-10
    )
