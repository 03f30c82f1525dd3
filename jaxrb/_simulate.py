"""`simulate`: integrate a scene with diffrax and return full `State`s at the save times.

One body, or a batch of bodies (a `State` whose leaves have a leading axis N) integrated as
one diffrax solve with batch-wide step-size control (`jaxrb/_batched.py`).
"""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ._batched import batch_rms_norm, check_batch_inputs, simulate_batched
from ._checks import as_float_array
from ._coordinates import FullState, coordinates_for
from ._inputs import check_concrete_inputs, input_result, safe_times, save_times
from ._persistent import entry_point
from ._results import RESULTS, raise_if_failed
from ._solve import DEFAULT_ATOL, DEFAULT_MAX_STEPS, DEFAULT_RTOL, default_solver, solve
from ._solver_settings import solver_settings
from ._state import State
from ._trajectory import Trajectory
from .contact import ContactOptions
from .contact._driver import simulate_contact


def _coordinates(scene):
    """The scene's one-body coordinates in the joints' interface (`reduce(state0)`,
    `expand(y, state0)`, `coordinate_rates(y, rates)`): its joint, or a free body's full
    state. `simulate` itself integrates `coordinates_for(scene)`."""
    return FullState() if scene.joint is None else scene.joint


def _batch_size(state0: State) -> int | None:
    """None for one body (leaves (3,), (4,), (3,), (3,)), N for a batch ((N, 3), ...)."""
    for name, n in (("pos", 3), ("quat", 4), ("vel", 3), ("omega", 3)):
        as_float_array(getattr(state0, name), f"state0.{name}", (n,))
    shapes = {k: jnp.shape(getattr(state0, k)) for k in ("pos", "quat", "vel", "omega")}
    if all(len(s) == 1 for s in shapes.values()):
        return None
    sizes = {s[0] for s in shapes.values() if len(s) == 2}
    if all(len(s) == 2 for s in shapes.values()) and len(sizes) == 1:
        return sizes.pop()
    shown = ", ".join(f"{k} {s}" for k, s in shapes.items())
    raise ValueError(
        "state0 must be one body's state (pos (3,), quat (4,), vel (3,), omega (3,)) or a "
        f"batch's (pos (N, 3), quat (N, 4), vel (N, 3), omega (N, 3)), got {shown}"
    )


def simulate(
    scene,
    state0: State,
    ts,
    *,
    solver: dfx.AbstractSolver | None = None,
    rtol: float = DEFAULT_RTOL,
    atol: float = DEFAULT_ATOL,
    dt0: float | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    stepsize_controller: dfx.AbstractStepSizeController | None = None,
    adjoint: dfx.AbstractAdjoint | None = None,
    progress_meter: dfx.AbstractProgressMeter | None = None,
    throw: bool = True,
    max_impacts: int | None = None,
    rest_speed: float | None = None,
    contact: ContactOptions | None = None,
) -> Trajectory:
    """Integrate `scene` from `state0` at time `ts[0]` and save at the times `ts`.

    **Arguments:**

    - `scene`: a `Scene`.
    - `state0`: the initial `State` of one body (leaves pos (3,), quat (4,), vel (3,),
      omega (3,)), or of a batch of N bodies (pos (N, 3), quat (N, 4), vel (N, 3),
      omega (N, 3)) in the same scene: see *Batches* below. The quaternion is normalised
      (any non-zero norm is accepted). For a jointed scene only `quat` and `omega` matter
      (plus `pos` to place the anchor): the velocity follows from the joint, and a hinge
      keeps only the component of `omega` along its axis.
    - `ts`: increasing save times (s), shape (T,); the solve runs from ts[0] to ts[-1].
    - `solver`: any diffrax solver. Default, chosen by `rtol` for scenes without a floor:
      `diffrax.Dopri8()` (8th order) where it reaches a given error at less cost, i.e. when
      rtol < 1e-9 for one body (also under `jax.vmap`) and rtol < 1e-5 for a batched
      `state0` (whose solve shares its fixed cost per step over the batch), else
      `diffrax.Tsit5()` (5th order). A traced rtol (under jit) gets the choice for the
      default rtol 1e-8; a `stepsize_controller` of your own and scenes with a floor get
      Tsit5. Measured: `benchmarks/README.md`, B1. For many forward runs of one body
      without a floor (a `jax.vmap` sweep), `jaxrb.unrolled_solver(diffrax.Dopri8())` is
      the same method at 3-4x less cost per body on a CPU (a reverse gradient compiles
      1.5-3x longer with it).
    - `rtol`, `atol`: tolerances of the default PID step-size controller (default 1e-8 each;
      with float32, use about 1e-5).
    - `dt0`: initial step (s); default: chosen by the controller.
    - `max_steps`: the solver's step budget; hitting it is an error (see `throw`).
    - `stepsize_controller`: replaces the default `PIDController(rtol, atol)`; pass
      `ConstantStepSize()` with `dt0` for fixed steps.
    - `adjoint`: diffrax adjoint; default `RecursiveCheckpointAdjoint()` (reverse mode). For
      forward-mode differentiation (`jax.jacfwd`, `jax.jvp`) pass `diffrax.ForwardMode()`.
      With a floor and a few parameters, forward mode compiles several times quicker, and
      `jax.jvp` along one parameter at a time in `jax.lax.map` quicker than `jax.jacfwd`
      (docs/contact.md, "Derivatives through contact").
    - `progress_meter`: e.g. `diffrax.TqdmProgressMeter()` for long runs, scenes without a
      floor only (the contact engine's many short segments report no progress).
    - `throw`: if True (default) raise on bad input or solver failure (concrete bad values
      raise a ValueError naming the field, and for a batch the member, before anything is
      compiled); if False, return a per-trajectory `result` code instead, for concrete and
      traced input alike (a bad member of a batch, or under `jax.vmap`, is flagged and
      takes no solver steps, the others are computed). Structural mistakes (wrong shapes or
      types) always raise.
    - `max_impacts`, `rest_speed`: scenes with a floor only: shortcuts for the options of the
      same names in `contact` (the bound on the number of impacts, default 64; the speed below
      which a bounce series is replaced by its limit, default 1e-2 m/s).
    - `contact`: scenes with a floor only: a `jaxrb.contact.ContactOptions` (bounds and
      tolerances of the contact engine; docs/contact.md).

    **Returns:** a `Trajectory` with full `State`s at `ts`.

    **What is integrated:** a free body whose only forces are uniform `Gravity` (or none)
    integrates its rotation only (quat, omega: no moment acts about the mass centre) and its
    mass centre follows the exact parabola; any other force integrates the full state; a
    jointed body integrates the joint's coordinates.

    **Batches:** with a batched `state0` the whole batch is one diffrax solve: the
    right-hand side is mapped over the members and one step-size controller serves them all,
    accepting a step when the worst member's error norm is <= 1 (the default controller is a
    `PIDController` whose `norm` is the largest of the members' RMS norms; a `PIDController`
    you pass with diffrax's default norm gets that norm too; a norm of your own sees the
    coordinates with the member axis last, e.g. quat (4, N)). All members take the same
    steps, so batch members of similar time scales together. Every array that
    `jax.vmap(simulate)` would return per member has a leading axis N: the states' leaves are
    (N, T, ...), `result`, `quat_norm_drift` and `num_steps` (N,) (`num_steps` is the shared
    count); `ts` is returned once, shape (T,). On a CPU a batch of more than 1024 members
    runs as consecutive solves of 1024 (the last padded), each with its own step control,
    so that each solve's buffers stay in a core's cache: `num_steps` is then the count of
    the member's part (`jaxrb.simulate_batch` takes another `part_size`). Elsewhere (a GPU)
    a `diffrax.Tsit5`, `Dopri5` or `Dopri8` takes the batch's steps with its stages written
    out (the same method and steps, results equal to roundoff; `jaxrb/_unrolled_stages.py`),
    and for free bodies sharing one scene each step is a single GPU kernel
    (`jaxrb/_fused_rotation_step.py`): B1 at N = 1e6 on an H200, Dopri8 at tol 5e-10 in
    float64, 0.035 us per body against 0.24 with the stages written out and 0.63 with
    diffrax's loop. Pass `jaxrb.unrolled_solver(...)` to keep one kernel per stage. A member
    with bad input is flagged in `result` (with `throw=False`), takes no part in the step
    control and has NaN states; the others are computed. The solve is differentiable like a single
    body's (reverse mode by default, forward mode with `adjoint=diffrax.ForwardMode()`).
    `jax.vmap(simulate)` still works and gives each member its own step-size control. A
    scene with a floor runs the contact engine per member: on a CPU one member after
    another (`jax.lax.map`, the cheapest there; `jax.vmap(simulate)` runs every member for
    as many events as the busiest one, at 3-5x the cost per die in benchmarks/README.md),
    elsewhere side by side (`jax.vmap`), in one compiled program that a later call with the
    same shapes reuses. To split a batch of throws over several CPU devices (not
    differentiable) use `jaxrb.simulate_throws`; a free body's batch over several devices,
    or with its own scene parameters per member: `jaxrb.simulate_batch`.

    Quaternion-norm policy: the right-hand side normalises q before rotating vectors, the
    kinematics preserve |q| up to the solver's error, and saved quaternions are normalised;
    `Trajectory.quat_norm_drift` reports the drift the solver allowed.
    """
    ts = save_times(ts)
    if not isinstance(state0, State):
        raise TypeError(f"state0 must be a jaxrb.State, got {type(state0).__name__}")
    n_batch = _batch_size(state0)
    if throw:
        if n_batch is not None:
            check_batch_inputs(state0)
        check_concrete_inputs(state0, ts)
    if solver is None:
        free = scene.floor is None and stepsize_controller is None
        solver = default_solver(rtol, n_batch is not None) if free else dfx.Tsit5()
    settings = solver_settings(
        solver=solver,
        rtol=rtol,
        atol=atol,
        dt0=dt0,
        max_steps=max_steps,
        stepsize_controller=stepsize_controller,
        adjoint=adjoint,
        progress_meter=progress_meter,
        throw=throw,
        dtype=ts.dtype,
    )
    if scene.floor is not None:
        contact = ContactOptions.from_shortcuts(contact, max_impacts, rest_speed)

        return simulate_contact(
            scene, state0, ts, settings, throw=throw, options=contact, members=n_batch is not None
        )
    state0 = jax.tree.map(lambda x: jnp.asarray(x, ts.dtype), state0)
    if n_batch is None:
        traj = _simulate_smooth(scene, state0, ts, settings)
    else:
        settings = eqx.tree_at(
            lambda s: s.controller, settings, batch_controller(settings.controller)
        )
        traj = simulate_batched(scene, state0, ts, settings)
    if throw:  # outside the compiled function: throw=True/False share one compilation
        traj = raise_if_failed(traj)
    return traj


def batch_controller(controller):
    """A `PIDController` with diffrax's default norm gets the batch norm (the worst member's
    RMS norm); any other controller is used as given."""
    if isinstance(controller, dfx.PIDController) and controller.norm is optx.rms_norm:
        return eqx.tree_at(lambda c: c.norm, controller, batch_rms_norm)
    return controller


@entry_point
def _simulate_smooth(scene, state0, ts, settings):
    """One body, no floor: one diffrax solve in the scene's coordinates (`settings`: a
    `SolverSettings`)."""
    coords = coordinates_for(scene)
    result = input_result(scene, state0, ts, settings.ok)
    run_ts = safe_times(ts, result == RESULTS.successful)
    ys, num_steps, solver_result = solve(
        lambda t, y: coords.rates(scene, t, y, state0),
        coords.reduce(scene, state0),
        run_ts,
        settings,
    )
    states = coords.states(scene, ys, run_ts, state0)
    drift = jnp.max(jnp.abs(coords.raw_quat_norm(scene, ys) - 1))
    ok = result == RESULTS.successful
    return Trajectory(
        ts=ts,
        states=states,
        result=RESULTS.where(ok, RESULTS.promote(solver_result), result),
        quat_norm_drift=drift,
        num_steps=num_steps,
    )
