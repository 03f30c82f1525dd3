"""`simulate`: integrate a scene with diffrax and return full `State`s at the save times."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from ._checks import all_met, as_float_array
from ._dynamics import vector_field
from ._inputs import check_concrete_inputs, check_solver_settings, input_result, safe_times
from ._quaternion import quat_normalize
from ._results import RESULTS
from ._state import State
from ._trajectory import Trajectory
from .contact import ContactOptions
from .contact._driver import simulate_contact

DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-8
DEFAULT_MAX_STEPS = 100_000


class _Free(eqx.Module):
    """Coordinates of a free body: the full state (13 numbers)."""

    def reduce(self, state0):
        return State(state0.pos, quat_normalize(state0.quat), state0.vel, state0.omega)

    def expand(self, y, state0):
        return State(y.pos, quat_normalize(y.quat), y.vel, y.omega)

    def coordinate_rates(self, y, rates):
        return rates

    def raw_quat_norm(self, y):
        return jnp.linalg.norm(y.quat, axis=-1)


def _coordinates(scene):
    return _Free() if scene.joint is None else scene.joint


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
    - `state0`: the initial `State` (unbatched; use `jax.vmap` for batches). The quaternion
      is normalised (any non-zero norm is accepted). For a jointed scene only `quat` and
      `omega` matter (plus `pos` to place the anchor): the velocity follows from the joint,
      and a hinge keeps only the component of `omega` along its axis.
    - `ts`: increasing save times (s), shape (T,); the solve runs from ts[0] to ts[-1].
    - `solver`: any diffrax solver; default `diffrax.Tsit5()` (5th order, adaptive).
    - `rtol`, `atol`: tolerances of the default PID step-size controller (default 1e-8 each;
      with float32, use about 1e-5).
    - `dt0`: initial step (s); default: chosen by the controller.
    - `max_steps`: the solver's step budget; hitting it is an error (see `throw`).
    - `stepsize_controller`: replaces the default `PIDController(rtol, atol)`; pass
      `ConstantStepSize()` with `dt0` for fixed steps.
    - `adjoint`: diffrax adjoint; default `RecursiveCheckpointAdjoint()` (reverse mode). For
      forward-mode differentiation (`jax.jacfwd`) pass `diffrax.ForwardMode()`.
    - `progress_meter`: e.g. `diffrax.TqdmProgressMeter()` for long runs.
    - `throw`: if True (default) raise on bad input or solver failure (concrete bad values
      raise a ValueError naming the field before anything is compiled); if False, return a
      per-trajectory `result` code instead, for concrete and traced input alike (use this
      under `jax.vmap`: a bad member is flagged and takes no solver steps, the others are
      computed). Structural mistakes (wrong shapes or types) always raise.
    - `max_impacts`, `rest_speed`: scenes with a floor only: shortcuts for the options of the
      same names in `contact` (the bound on the number of impacts, default 64; the speed below
      which a bounce series is replaced by its limit, default 1e-2 m/s).
    - `contact`: scenes with a floor only: a `jaxrb.contact.ContactOptions` (bounds and
      tolerances of the contact engine; docs/contact.md).

    **Returns:** a `Trajectory` with full `State`s at `ts`.

    Quaternion-norm policy: the right-hand side normalises q before rotating vectors, the
    kinematics preserve |q| up to the solver's error, and saved quaternions are normalised;
    `Trajectory.quat_norm_drift` reports the drift the solver allowed.
    """
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"ts must be a 1-D array of save times, got shape {ts.shape}")
    if not jnp.issubdtype(ts.dtype, jnp.floating):
        ts = ts.astype(float)
    if not isinstance(state0, State):
        raise TypeError(f"state0 must be a jaxrb.State, got {type(state0).__name__}")
    for name, n in (("pos", 3), ("quat", 4), ("vel", 3), ("omega", 3)):
        as_float_array(getattr(state0, name), f"state0.{name}", (n,))
    if throw:
        check_concrete_inputs(state0, ts)
    settings_ok = all_met(
        check_solver_settings(
            rtol if stepsize_controller is None else 1.0,
            atol if stepsize_controller is None else 1.0,
            dt0,
            max_steps,
            throw,
        )
    )
    if solver is None:
        solver = dfx.Tsit5()
    if stepsize_controller is None:
        # tolerances as arrays, so that new values do not trigger a recompilation
        stepsize_controller = dfx.PIDController(rtol=jnp.asarray(rtol), atol=jnp.asarray(atol))
    if dt0 is not None:
        dt0 = jnp.asarray(dt0, ts.dtype)
    if adjoint is None:
        adjoint = dfx.RecursiveCheckpointAdjoint()
    if scene.floor is not None:
        if contact is None:
            shortcuts = dict(max_impacts=max_impacts, rest_speed=rest_speed)
            contact = ContactOptions(**{k: v for k, v in shortcuts.items() if v is not None})
        elif max_impacts is not None or rest_speed is not None:
            raise ValueError("give max_impacts and rest_speed inside `contact`, not beside it")
        return simulate_contact(
            scene,
            state0,
            ts,
            solver=solver,
            stepsize_controller=stepsize_controller,
            adjoint=adjoint,
            dt0=dt0,
            max_steps=max_steps,
            throw=throw,
            options=contact,
            settings_ok=settings_ok,
        )
    if progress_meter is None:
        progress_meter = dfx.NoProgressMeter()
    state0 = jax.tree.map(lambda x: jnp.asarray(x, ts.dtype), state0)
    return _simulate_smooth(
        scene,
        state0,
        ts,
        solver,
        stepsize_controller,
        adjoint,
        progress_meter,
        dt0,
        max_steps,
        throw,
        settings_ok,
    )


@eqx.filter_jit
def _simulate_smooth(
    scene,
    state0,
    ts,
    solver,
    stepsize_controller,
    adjoint,
    progress_meter,
    dt0,
    max_steps,
    throw,
    settings_ok,
):
    coords = _coordinates(scene)
    y0 = coords.reduce(state0)
    result = input_result(scene, state0, ts, settings_ok)
    run_ts = safe_times(ts, result == RESULTS.successful)

    def rhs(t, y, args):
        state = coords.expand(y, state0)
        return coords.coordinate_rates(y, vector_field(t, state, scene))

    sol = dfx.diffeqsolve(
        dfx.ODETerm(rhs),
        solver,
        t0=run_ts[0],
        t1=run_ts[-1],
        dt0=dt0,
        y0=y0,
        saveat=dfx.SaveAt(ts=run_ts),
        stepsize_controller=stepsize_controller,
        adjoint=adjoint,
        max_steps=max_steps,
        progress_meter=progress_meter,
        throw=False,
    )
    states = jax.vmap(lambda y: coords.expand(y, state0))(sol.ys)
    drift = jnp.max(jnp.abs(jax.vmap(coords.raw_quat_norm)(sol.ys) - 1))
    result = RESULTS.where(result == RESULTS.successful, RESULTS.promote(sol.result), result)
    traj = Trajectory(
        ts=ts,
        states=states,
        result=result,
        quat_norm_drift=drift,
        num_steps=sol.stats["num_accepted_steps"],
    )
    if throw:
        traj = result.error_if(traj, result != RESULTS.successful)
    return traj
