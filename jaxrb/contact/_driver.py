"""`simulate` for a scene with a floor: smooth segments in fixed contact modes joined by the
maps at events (docs/contact.md).

Each segment is one `diffrax.diffeqsolve` of the mode's right-hand side that stops at the
first zero of the mode's event function (root found on the dense output of the step diffrax
stops after, `_event_root.py`). The segment loop is an `equinox.internal.while_loop` bounded
by `max_events`: it stops once every member of a batch has reached the end time,
reverse-differentiates (checkpointed) and, with `diffrax.ForwardMode`, forward-differentiates.
Gradients include the shift of each event time.
"""

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import is_concrete
from .._inputs import input_result, safe_times
from .._persistent import entry_point
from .._quaternion import quat_normalize
from .._results import RESULTS, raise_if_failed
from .._scene import with_inertia_inverse
from .._shapes import Sphere
from .._solve import checks_without_host_callbacks
from .._solver_settings import SolverSettings
from .._state import State
from .._trajectory import Trajectory
from ._event_root import EventTime, event_root
from ._events import (
    cause_of,
    condition_tolerances,
    conditions,
    start_offsets,
)
from ._features import contact_model, contact_model_class
from ._modes import (
    FLIGHT,
    PAIR,
    flat,
    flight_mode,
    mode_rates,
    no_derivative,
    solve_mode,
    tree_where,
    unflat,
    unit_state,
)
from ._options import ContactOptions
from ._record import ContactLog, add_impact, empty_impacts
from ._step_end import CarryingSolver, carried_event_value, last_step
from ._step_limit import limited, step_limit_of
from ._transition import at_event


def traced_once(fn):
    """`fn` (pure) as a function whose trace is kept: while one program is traced, diffrax
    calls a segment's right-hand side, event condition and step limit many times with the
    same argument shapes (every stage of a step, its probes of the step's shapes, the root
    find); each later call reuses the first one's jaxpr instead of tracing `fn` again."""
    return eqx.filter_jit(fn)


def _sliding(mode):
    held_still = mode.stick[0] & ((mode.kind != PAIR) | mode.stick[1])
    return (mode.kind != FLIGHT) & ~held_still


def check_contact_scene(scene, options) -> None:
    """Raise for a scene the contact engine does not model, or options of the wrong type."""
    if scene.body.shape is None:
        raise ValueError(
            "a scene with a floor needs a body shape (Sphere, Box or Cylinder) for contact"
        )
    if scene.floor.curved and not isinstance(scene.body.shape, Sphere):
        raise ValueError(
            f"a {type(scene.floor).__name__} meets only a Sphere (the body is a "
            f"{type(scene.body.shape).__name__}); any shape meets a Floor"
        )
    contact_model_class(scene.body.shape, scene.floor.parts)  # raises for a shape with none
    resists = [scene.floor.rolling_resistance, scene.floor.spin_resistance]
    if not isinstance(scene.body.shape, Sphere) and any(
        is_concrete(x) and float(x) != 0.0 for x in resists
    ):
        raise ValueError(
            "rolling and spin resistance act on a ball (Sphere) only; the body is a "
            f"{type(scene.body.shape).__name__}: leave the floor's rolling_resistance and "
            "spin_resistance at 0"
        )
    friction = scene.floor.friction
    if all(is_concrete(x) for x in (friction, *resists)):
        resisting = (np.asarray(resists[0]) != 0) | (np.asarray(resists[1]) != 0)
        smooth = np.any((np.asarray(friction) == 0) & resisting)
    else:
        smooth = False
    if smooth:
        raise ValueError(
            "rolling and spin resistance need friction: with the floor's friction 0 nothing "
            "ties the ball's spin to its motion (and the resisting couple's fade near rest is "
            "stiff); give friction > 0 or leave rolling_resistance and spin_resistance at 0"
        )
    if not isinstance(options, ContactOptions):
        raise TypeError(f"options must be a ContactOptions, got {type(options).__name__}")


def simulate_contact(scene, state0, ts, settings, *, throw, options, members=False):
    """`jaxrb.simulate` for a scene with a floor, with the `SolverSettings` `settings` (each
    smooth segment is one solve with them; the progress meter is not used). `options` is a
    `ContactOptions`. With `members`, `state0` is a batch (a leading axis N on every leaf),
    each member running the one-body program (`_simulate_contact_members`); a member that
    starts below the floor is then flagged in its result code."""
    check_contact_scene(scene, options)
    ts = jnp.asarray(ts)
    state0 = jax.tree.map(lambda x: jnp.asarray(x, ts.dtype), state0)
    tol = options.resolved(ts.dtype)
    concrete = all(is_concrete(x) for x in (*jax.tree.leaves(state0), *jax.tree.leaves(scene)))
    if throw and concrete and not members:
        d0 = float(
            scene.floor.body_distance(scene.body.shape, state0.pos, quat_normalize(state0.quat))
        )
        if d0 < -tol.contact:
            raise ValueError(
                f"the body starts below the floor: its lowest point is {-d0:.3g} m under the "
                "floor plane"
            )
    kind = "lax" if isinstance(settings.adjoint, dfx.ForwardMode) else "checkpointed"
    # also around the call: under jax.grad / jacfwd JAX differentiates the compiled
    # program's jaxpr here, tracing the derivative of each event time's root find (a linear
    # solve with its own check) only now
    program = _simulate_contact_members if members else _simulate_contact
    with checks_without_host_callbacks():
        traj = program(scene, state0, ts, settings, options, tol, kind)
    if throw:  # outside the compiled program: throw=True and False share one compilation
        traj = raise_if_failed(traj)
    return traj


def dependent_from_start(scene, state0):
    """A function that subtracts from every float of a tree a zero depending on every float
    of `scene` and `state0` (their finite values times 0): the values, and any derivative,
    are unchanged, to the bit (-0 and inf too). For the first carry of the loop over
    segments: its time, state and records depend on those inputs once a segment has run,
    and with this from the start. JAX differentiates (forward mode, and reverse mode, which
    starts from it) and batches (`jax.vmap`, `jax.jacfwd`) a while loop by transforming its
    body again until the set of carries with derivatives (or a batch axis) stops growing,
    and with each pass the loops nested inside it; given the set at the start, one pass
    does. Not the save times (an input of their own) nor the mode (no derivative flows into
    its directions; one seeded there would be carried through every solve)."""
    leaves = [
        x
        for x in jax.tree.leaves((scene, state0))
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating)
    ]
    # +0 exactly (each term a finite |x| times 0), subtracted: x - 0 is x, -0 and inf too
    zero = sum(jnp.sum(0.0 * jnp.abs(jnp.where(jnp.isfinite(x), x, 0.0))) for x in leaves)

    def seeded(tree):
        return jax.tree.map(
            lambda x: x - zero.astype(x.dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x,
            tree,
        )

    return seeded


class _Segment(eqx.Module):
    """The arguments of a segment's right-hand side, event function and step limit: the
    scene, the segment's mode, the shifts of its conditions, and whether the body moves
    (False: a finished member of a batch, held still)."""

    scene: object
    mode: object
    offsets: jax.Array
    moving: jax.Array
    step_end: jax.Array  # the time of the step's end while a step runs, else NaN

    def marked(self, t1):
        """These arguments while a step ending at t1 runs (`_step_end.py`)."""
        return eqx.tree_at(lambda a: a.step_end, self, jnp.asarray(t1, self.step_end.dtype))


class ContactProgram(eqx.Module):
    """What every body of a contact simulation shares: the shape's contact model, the
    `SolverSettings`, the contact options and tolerances. `start`, `advance` and
    `trajectory` are the pieces of a simulation (the loop of `simulate` runs them for one
    body, the lanes of `simulate_throws` for many); the scene is an argument of each, so
    that every body may have its own parameters."""

    model: object
    settings: SolverSettings
    options: ContactOptions = eqx.field(static=True)
    tol: object = eqx.field(static=True)

    def start(self, scene, state0, ts) -> dict:
        """The carry of a simulation of `scene` from `state0`, saved at `ts`, before its
        first pass (which applies the maps of the start: a body may start touching)."""
        options, tol = self.options, self.tol
        dtype = ts.dtype
        result = input_result(scene, state0, ts, self.settings.ok)
        if not isinstance(scene.body.shape, Sphere):  # traced resistances: checked here
            floor = scene.floor
            resists = (floor.rolling_resistance != 0) | (floor.spin_resistance != 0)
            result = RESULTS.where(
                (result == RESULTS.successful) & resists, RESULTS.invalid_resistance, result
            )
        ts = safe_times(ts, result == RESULTS.successful)
        T = ts.shape[0]
        y0 = unit_state(state0)
        d0 = scene.floor.body_distance(scene.body.shape, y0.pos, y0.quat)
        result = RESULTS.where(
            (result == RESULTS.successful) & (d0 < -tol.contact),
            RESULTS.starts_below_floor,
            result,
        )
        log0 = dict(
            events=jnp.array(0, jnp.int32),
            zeno_merges=jnp.array(0, jnp.int32),
            energy_guards=jnp.array(0, jnp.int32),
            inconsistent=jnp.array(0, jnp.int32),
            ambiguous=jnp.array(0, jnp.int32),
            max_energy_rise=jnp.zeros((), dtype),
            max_penetration=jnp.zeros((), dtype),
            event_time=jnp.full(options.max_events + 1, jnp.inf, dtype),
            event_cause=jnp.zeros(options.max_events + 1, jnp.int32),
            event_kind=jnp.zeros(options.max_events + 1, jnp.int32),
            event_sliding=jnp.zeros(options.max_events + 1, bool),
            event_inconsistent=jnp.zeros(options.max_events + 1, bool),
        )
        seeded = dependent_from_start(scene, state0)
        return dict(
            ts=ts,
            t=seeded(ts[0]),
            y=seeded(y0),
            mode=flight_mode(dtype),
            trigger=jnp.array(-1),
            done=result != RESULTS.successful,
            impacts=seeded(empty_impacts(options.max_impacts, dtype)),
            log=seeded(log0),
            buffer=seeded(jax.tree.map(lambda x: jnp.zeros((T,) + x.shape, dtype), y0)),
            kind=jnp.zeros(T, jnp.int32),
            sliding=jnp.zeros(T, bool),
            filled=jnp.zeros(T, bool),
            result=result,
            num_steps=jnp.array(0),
            passes=jnp.array(0, jnp.int32),
        )

    def advance(self, scene, carry) -> dict:
        """One pass: the maps of the event that ended the previous segment (at the first
        pass, of the start), then one smooth segment up to the next event or the end."""
        model, options, tol = self.model, self.options, self.tol
        ts = carry["ts"]
        T = ts.shape[0]
        t_end = ts[-1]
        cond_tol = condition_tolerances(model, tol, ts.dtype)
        done = carry["done"]
        t0 = jnp.where(done, t_end, carry["t"])
        out = at_event(t0, carry["y"], carry["mode"], carry["trigger"], scene, model, tol, ~done)
        impacts = carry["impacts"]
        too_many = ~done & out.impact & (impacts.count >= options.max_impacts)
        do = ~done & ~too_many
        impacts = add_impact(
            impacts,
            do & out.impact,
            t0,
            out.point,
            out.impulse,
            out.speed,
            out.energy_lost,
            out.rest_time,
        )
        log = carry["log"]
        count = lambda flag: (do & flag).astype(jnp.int32)  # noqa: E731
        log = dict(
            events=log["events"],
            zeno_merges=log["zeno_merges"] + count(out.merged),
            energy_guards=log["energy_guards"] + count(out.guarded),
            inconsistent=log["inconsistent"] + count(out.inconsistent),
            ambiguous=log["ambiguous"] + count(out.ambiguous),
            max_energy_rise=jnp.maximum(
                log["max_energy_rise"], jnp.where(do, out.energy_rise, 0.0)
            ),
            max_penetration=jnp.maximum(
                log["max_penetration"], jnp.where(do, out.penetration, 0.0)
            ),
        )
        slot = jnp.minimum(log["events"], options.max_events)

        def put(name, value):
            buf = carry["log"][name]
            log[name] = buf.at[slot].set(jnp.where(do, value, buf[slot]))

        put("event_time", t0)
        put("event_cause", cause_of(carry["trigger"], model))
        put("event_kind", out.mode.kind)
        put("event_sliding", _sliding(out.mode))
        put("event_inconsistent", out.inconsistent)
        # the Painlevé paradox: no contact force exists; the run stops at the state reached
        paradox = do & out.painleve
        moves_on = do & ~paradox
        mode = tree_where(moves_on, out.mode, carry["mode"])
        y = tree_where(moves_on, out.state, carry["y"])
        start, values0 = _solve_with_conditions(t0, y, mode, scene, model, tol)
        offsets = start_offsets(values0, cond_tol, mode, model)
        # the event function and the step limit at the start, carried beside the state
        # (`_step_end.py`)
        carried0 = _carried(start, values0, mode, offsets, model, tol)
        done = done | too_many | paradox
        # a finished member (of a vmapped batch) is held still over a last sliver
        # [t_end - idle, t_end], whose result is discarded: its saves, all at t_end, are
        # then taken in its one step. Starting at t_end itself, diffrax would take them all
        # again at every step of the members still running (its save loop restarts from a
        # finished member's first save): a batch of three roulette balls with 481 saves
        # ran 4x slower than with 3 saves, and 6x slower than a loop over the balls
        idle = 64 * jnp.finfo(ts.dtype).eps * jnp.maximum(jnp.abs(t_end), 1.0)
        t0 = jnp.where(done, t_end - idle, t0)
        settings = self.settings
        args = _Segment(scene, mode, offsets, ~done, jnp.array(jnp.nan, ts.dtype))
        rates, at_step_end, shifted_conditions = _step_end_functions(model, tol)
        solver = CarryingSolver(settings.solver, at_step_end, _Segment.marked)
        state_only = lambda t, y, args: y[0]  # noqa: E731
        # diffrax stops at the end of the step in which the event function fell to zero; the
        # event is located on that step's dense output, kept in the solver's state
        # (`_event_root.py`)
        with checks_without_host_callbacks():
            sol = dfx.diffeqsolve(
                dfx.ODETerm(rates),
                solver,
                t0=t0,
                t1=t_end,
                dt0=settings.dt0,
                y0=(flat(y), carried0.astype(ts.dtype)),
                args=args,
                saveat=dfx.SaveAt(
                    subs=[
                        dfx.SubSaveAt(ts=jnp.clip(ts, t0, t_end), fn=state_only),
                        dfx.SubSaveAt(t1=True, fn=state_only),
                    ],
                    solver_state=True,
                ),
                stepsize_controller=settings.controller,
                adjoint=settings.adjoint,
                max_steps=settings.max_steps,
                event=dfx.Event(carried_event_value, direction=False),
                throw=False,
            )
        ev = jnp.asarray(sol.event_mask) & ~done
        step = last_step(solver, sol.solver_state)
        t_root, x_root, trigger, located = event_root(
            step, shifted_conditions, args, ev, EventTime(rtol=tol.event, atol=tol.event)
        )
        t_stop = jnp.where(ev, t_root, sol.ts[1][0])
        y_stop = unflat(jnp.where(ev, x_root, sol.ys[1][0]))
        res = RESULTS.promote(sol.result)
        located = RESULTS.promote(located)
        res = RESULTS.where(located == RESULTS.successful, res, located)
        failed = ~done & (res != RESULTS.successful) & (res != RESULTS.event_occurred)
        filled = carry["filled"]
        owned = ~filled & ~done & (ts >= t0) & ((ts < t_stop) | (~ev & (ts <= t_stop)))

        def keep(buf, new):
            return jnp.where(owned.reshape((T,) + (1,) * (buf.ndim - 1)), new, buf)

        trigger = trigger.astype(carry["trigger"].dtype)  # at an event only
        log["events"] = log["events"] + ev.astype(jnp.int32)
        result = carry["result"]
        result = RESULTS.where(failed & (result == RESULTS.successful), res, result)
        result = RESULTS.where(
            too_many & (result == RESULTS.successful), RESULTS.max_impacts_reached, result
        )
        result = RESULTS.where(
            paradox & (result == RESULTS.successful), RESULTS.painleve_paradox, result
        )
        moved = ~done & ~failed
        return dict(
            ts=ts,
            t=jnp.where(moved, t_stop, carry["t"]),
            y=tree_where(moved, y_stop, y),
            mode=mode,
            trigger=jnp.where(ev, trigger, carry["trigger"]),
            done=done | ~ev | failed,
            impacts=impacts,
            log=log,
            buffer=jax.tree.map(keep, carry["buffer"], unflat(sol.ys[0])),
            kind=jnp.where(owned, mode.kind, carry["kind"]),
            sliding=jnp.where(owned, _sliding(mode), carry["sliding"]),
            filled=filled | owned,
            result=result,
            num_steps=carry["num_steps"] + jnp.where(done, 0, sol.stats["num_accepted_steps"]),
            passes=carry["passes"] + (~carry["done"]).astype(jnp.int32),
        )

    def trajectory(self, carry, user_ts) -> Trajectory:
        """The `Trajectory` of a finished carry, saved at `user_ts`."""
        T = user_ts.shape[0]
        result = carry["result"]
        result = RESULTS.where(
            ~carry["done"] & (result == RESULTS.successful), RESULTS.max_events_reached, result
        )
        filled = carry["filled"]
        raw = jax.tree.map(
            lambda b, end: jnp.where(filled.reshape((T,) + (1,) * (b.ndim - 1)), b, end[None]),
            carry["buffer"],
            carry["y"],
        )
        drift = jnp.max(jnp.where(filled, jnp.abs(jnp.linalg.norm(raw.quat, axis=-1) - 1), 0.0))
        states = State(raw.pos, quat_normalize(raw.quat), raw.vel, raw.omega)
        log = ContactLog(
            kind=jnp.where(filled, carry["kind"], carry["mode"].kind),
            sliding=jnp.where(filled, carry["sliding"], _sliding(carry["mode"])),
            **carry["log"],
        )
        return Trajectory(
            ts=user_ts,
            states=states,
            result=result,
            quat_norm_drift=drift,
            num_steps=carry["num_steps"],
            impacts=carry["impacts"],
            contact=log,
        )


def _step_end_functions(model, tol):
    """(rates, at_step_end, shifted_conditions) of a segment's `CarryingSolver`
    (`_step_end.py`) and its event's root find (`_event_root.py`): the right-hand side on
    y = (x, [c, h]), which returns beside the rates of x the event function and the step
    limit at a step's end (`args.step_end`), from the same solve of the mode, with no
    derivative; the same two values from a solve of their own, for solvers whose last stage
    is not the step's end; and, for the root find, the shifted conditions at (t, x),
    differentiable (their least is the event function, its index the trigger)."""

    def carried_of(sol, args):  # [c, h] of a solution in the segment (no derivative)
        sol, mode, scene, offsets = no_derivative((sol, args.mode, args.scene, args.offsets))
        values = conditions(sol, mode, model, scene, tol)
        return _carried(sol, values, mode, offsets, model, tol)

    @traced_once
    def rates(t, y, args):
        x, values = y
        dx, values1 = mode_rates(
            t,
            x,
            args.mode,
            args.scene,
            model,
            tol,
            t == args.step_end,
            lambda sol: carried_of(sol, args),
            jnp.zeros_like(values),
        )
        return jnp.where(args.moving, dx, 0.0), values1

    @traced_once
    def shifted_conditions(t, x, args):  # x: the segment's flat state
        _, values = _solve_with_conditions(t, unflat(x), args.mode, args.scene, model, tol)
        return values + args.offsets

    @traced_once
    def at_step_end(t, x, args):
        t, x, args = no_derivative((t, x, args))
        sol = solve_mode(t, unit_state(unflat(x)), args.mode, args.scene, model, tol)
        return carried_of(sol, args)

    return rates, at_step_end, shifted_conditions


def _solve_with_conditions(t, y, mode, scene, model, tol):
    """The solution of `mode` at the state `y` (its quaternion normalised) and the mode's
    condition vector there (docs/contact.md, section 4)."""
    sol = solve_mode(t, unit_state(y), mode, scene, model, tol)
    return sol, conditions(sol, mode, model, scene, tol)


def _carried(sol, values, mode, offsets, model, tol):
    """The values a segment carries beside its state (`_step_end.py`): [c, h], the event
    function (the smallest condition `values` shifted by `offsets`) and the step limit (s)
    at the state of the mode's solution `sol`."""
    return jnp.stack([jnp.min(values + offsets), step_limit_of(sol, mode, offsets, model, tol)])


def contact_program(scene, settings, options, tol) -> ContactProgram:
    """The `ContactProgram` of `scene`'s shape with the `SolverSettings` `settings`; the
    step-size controller learns each segment's step limit."""
    model = contact_model(scene.body.shape, scene.floor.parts)
    controller = limited(settings.controller)
    settings = eqx.tree_at(lambda s: s.controller, settings, controller)
    return ContactProgram(model, settings, options, tol)


@entry_point
def _simulate_contact(scene, state0, ts, settings, options, tol, loop_kind):
    return run_throw(with_inertia_inverse(scene), state0, ts, settings, options, tol, loop_kind)


@entry_point
def _simulate_contact_members(scene, states0, ts, settings, options, tol, loop_kind):
    """A batch's members, each through `run_throw`: on a CPU one after another
    (`jax.lax.map`: each runs only its own events and steps, about a loop of `simulate`
    over them in one call), elsewhere side by side (`jax.vmap`: every member for as many
    passes as the one with the most events). One compiled entry point, so that a later call
    with the same shapes and settings neither traces nor compiles again."""
    from ._lanes import one_after_another  # _lanes imports this module

    scene = with_inertia_inverse(scene)

    def one(state0):
        return run_throw(scene, state0, ts, settings, options, tol, loop_kind)

    traj = jax.lax.map(one, states0) if one_after_another() else jax.vmap(one)(states0)
    return eqx.tree_at(lambda t: t.ts, traj, ts)


def run_throw(scene, state0, ts, settings, options, tol, loop_kind) -> Trajectory:
    """One throw's passes (the start, then one per event) in a loop of the `loop_kind`
    ("lax" or "checkpointed"), and its `Trajectory`; traced inside an entry point."""
    program = contact_program(scene, settings, options, tol)
    carry = eqxi.while_loop(
        lambda c: ~jnp.all(c["done"]),
        lambda c: program.advance(scene, c),
        program.start(scene, state0, ts),
        max_steps=options.max_events + 1,  # the start, then one pass per event
        kind=loop_kind,
    )
    return program.trajectory(carry, ts)
