"""`simulate`: integrate a scene with diffrax and return full `State`s at the save times."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import inertia as _inertia
from ._checks import as_float_array, is_concrete
from ._dynamics import vector_field
from ._quaternion import quat_normalize
from ._results import RESULTS
from ._state import State

DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-8
DEFAULT_MAX_STEPS = 100_000


class Trajectory(eqx.Module):
    """The result of `simulate`.

    **Fields:**

    - `ts`: save times (s), shape (T,).
    - `states`: a `State` whose leaves have a leading time axis (T, ...); unit quaternions.
    - `result`: a `jaxrb.RESULTS` code (per batch member under vmap);
      `RESULTS.successful` if all went well.
    - `quat_norm_drift`: max over the save times of ||q| - 1| before normalisation: how far
      the integrator let the quaternion norm wander (the exact flow keeps it at 1).
    - `num_steps`: accepted solver steps.
    - `impacts`: impact records for scenes with a floor, else None.
    """

    ts: jax.Array
    states: State
    result: RESULTS
    quat_norm_drift: jax.Array
    num_steps: jax.Array
    impacts: object = None


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


def input_result(scene, state0: State, ts) -> RESULTS:
    """The first bad-input problem found (traceable), or `RESULTS.successful`."""
    body = scene.body
    checks = [
        (jnp.all(jnp.isfinite(body.mass) & (body.mass > 0)), RESULTS.invalid_mass),
        (_inertia.is_valid_inertia(body.inertia_matrix), RESULTS.invalid_inertia),
        (
            jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(state0)])),
            RESULTS.nonfinite_state,
        ),
        (jnp.all(jnp.linalg.norm(state0.quat, axis=-1) > 0), RESULTS.zero_quaternion),
        (jnp.all(jnp.diff(ts) >= 0), RESULTS.decreasing_times),
    ]
    if scene.floor is not None:
        e, mu = scene.floor.restitution, scene.floor.friction
        checks.append((jnp.all((e >= 0) & (e <= 1)), RESULTS.invalid_restitution))
        checks.append((jnp.all(jnp.isfinite(mu) & (mu >= 0)), RESULTS.invalid_friction))
    result = RESULTS.successful
    for ok, code in reversed(checks):
        result = RESULTS.where(jnp.all(ok), result, code)
    return result


def _check_concrete_inputs(state0: State, ts) -> None:
    """Raise ValueError early for concrete bad input (outside jit), naming the problem."""
    if is_concrete(ts):
        t = np.asarray(ts)
        if not np.all(np.isfinite(t)):
            raise ValueError("ts contains non-finite values")
        if np.any(np.diff(t) < 0):
            raise ValueError("ts must be non-decreasing (t1 < t0 is not allowed)")
    for name in ("pos", "quat", "vel", "omega"):
        x = getattr(state0, name)
        if is_concrete(x):
            if not np.all(np.isfinite(np.asarray(x))):
                raise ValueError(f"state0.{name} contains non-finite values (NaN or inf)")
    if is_concrete(state0.quat) and np.any(np.linalg.norm(np.asarray(state0.quat), axis=-1) == 0):
        raise ValueError("state0.quat has zero norm")


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
    max_impacts: int = 64,
    rest_speed: float = 1e-2,
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
    - `throw`: if True (default) raise on bad input or solver failure; if False, return a
      per-trajectory `result` code instead (use this under `jax.vmap`).
    - `max_impacts`: scenes with a floor only: the static bound on the number of impacts
      (the size of `Trajectory.impacts`); reaching it gives `RESULTS.max_impacts_reached`.
    - `rest_speed`: scenes with a floor only: outgoing normal speed (m/s) below which the
      remaining bounces are merged into resting contact (see `jaxrb/_impacts.py`).

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
    _check_concrete_inputs(state0, ts)
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
        from ._impacts import simulate_with_impacts

        return simulate_with_impacts(
            scene,
            state0,
            ts,
            solver=solver,
            stepsize_controller=stepsize_controller,
            adjoint=adjoint,
            atol=atol,
            dt0=dt0,
            max_steps=max_steps,
            throw=throw,
            max_impacts=max_impacts,
            rest_speed=rest_speed,
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
    )


@eqx.filter_jit
def _simulate_smooth(
    scene, state0, ts, solver, stepsize_controller, adjoint, progress_meter, dt0, max_steps, throw
):
    coords = _coordinates(scene)
    y0 = coords.reduce(state0)

    def rhs(t, y, args):
        state = coords.expand(y, state0)
        return coords.coordinate_rates(y, vector_field(t, state, scene))

    sol = dfx.diffeqsolve(
        dfx.ODETerm(rhs),
        solver,
        t0=ts[0],
        t1=ts[-1],
        dt0=dt0,
        y0=y0,
        saveat=dfx.SaveAt(ts=ts),
        stepsize_controller=stepsize_controller,
        adjoint=adjoint,
        max_steps=max_steps,
        progress_meter=progress_meter,
        throw=False,
    )
    states = jax.vmap(lambda y: coords.expand(y, state0))(sol.ys)
    drift = jnp.max(jnp.abs(jax.vmap(coords.raw_quat_norm)(sol.ys) - 1))
    result = input_result(scene, state0, ts)
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
