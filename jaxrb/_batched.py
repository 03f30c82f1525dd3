"""A batch of bodies as one diffrax solve with batch-wide step-size control.

`jax.vmap(jaxrb.simulate)` runs diffrax's machinery (stage loop, step-size controller,
saving) once per body, each member with its own steps; for small right-hand sides such as
one rigid body's 7 or 13 numbers that machinery costs more than the physics. Here the batch's
coordinates are one pytree whose leaves have the member axis last (quat (4, N): each
coordinate a contiguous row of N numbers), the one-body right-hand side is mapped over it
(`jax.vmap`, or written row-wise for a free body's rotation), and a single
`diffrax.diffeqsolve` integrates it: its fixed cost per step is shared by the whole batch.
One step-size controller serves all members: a step is accepted when the worst member's
error norm (`batch_rms_norm`) is <= 1. On a CPU a batch larger than `CPU_PART` runs as
consecutive solves of that many members, whose buffers stay in a core's cache.

`simulate` takes this path for a batched `State`; `simulate_batch` adds one set of scene
parameters per member and splitting the batch over devices.
"""

import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import as_computed, is_concrete
from ._coordinates import ROTATION, coordinates_for
from ._fused_rotation_step import BLOCK, fused_rotation_solver, member_rows, on_gpu
from ._inputs import check_concrete_inputs, input_result, safe_times
from ._persistent import entry_point
from ._results import RESULTS, raise_if_failed
from ._scene import with_inertia_inverse
from ._solve import DEFAULT_MAX_STEPS, default_solver, solve
from ._solver_settings import solver_settings
from ._state import State
from ._trajectory import Trajectory
from ._unrolled_stages import batch_solver


def batch_rms_norm(tree, member_axis: int = -1) -> jax.Array:
    """The worst member's RMS norm: every leaf has the member axis at `member_axis` (last, as
    the batch's coordinates in the solve); the RMS is taken over each member's entries of
    all leaves, then the largest over the members. Step-size control only (no gradient flows
    through it)."""
    leaves = [
        jnp.moveaxis(jax.lax.stop_gradient(x), member_axis, -1) for x in jax.tree.leaves(tree)
    ]
    squares = sum(jnp.sum(jnp.reshape(x * x, (-1, x.shape[-1])), axis=0) for x in leaves)
    size = sum(math.prod(x.shape[:-1]) for x in leaves)
    return jnp.max(jnp.sqrt(squares / size))


def check_batch_inputs(states0: State) -> None:
    """Raise a ValueError naming the field and the first bad member for concrete non-finite
    values or a zero quaternion."""
    for name in ("pos", "quat", "vel", "omega"):
        x = getattr(states0, name)
        if is_concrete(x):
            bad = ~np.all(np.isfinite(np.asarray(x)), axis=-1)
            if np.any(bad):
                raise ValueError(
                    f"state0.{name} contains non-finite values (NaN or inf) in batch member "
                    f"{int(np.argmax(bad))}"
                )
    if is_concrete(states0.quat):
        zero = np.all(as_computed(states0.quat) == 0, axis=-1)
        if np.any(zero):
            raise ValueError(f"state0.quat has zero norm in batch member {int(np.argmax(zero))}")


def _where_members(valid, tree, other):
    """Per member (leading axis N): `tree` where `valid`, else `other` (broadcast)."""
    return jax.tree.map(
        lambda x, o: jnp.where(valid.reshape((-1,) + (1,) * (x.ndim - 1)), x, o), tree, other
    )


def _padded(x, total):
    """(N, ...) -> (total, ...): the last member repeated to fill."""
    pad = total - x.shape[0]
    return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]) if pad else x


def _per_member(traj, fn, ts):
    """`traj` with `fn` applied to each per-member leaf (leading axis: the members) and `ts`
    as its save times."""
    return Trajectory(
        ts=ts,
        states=jax.tree.map(fn, traj.states),
        result=jax.tree.map(fn, traj.result),
        quat_norm_drift=fn(traj.quat_norm_drift),
        num_steps=fn(traj.num_steps),
    )


def _unit_inertia_unless(ok, scene):
    """`scene` with its body's inertia replaced by the unit one (kg m^2) unless `ok`."""
    body = scene.body
    unit = jnp.ones(3) if body.principal else jnp.eye(3)
    inertia = jnp.where(ok, body.inertia, unit.astype(body.inertia.dtype))
    return eqx.tree_at(lambda s: s.body.inertia, scene, inertia)


CPU_PART = 1024
"""Members per solve on a CPU. A larger batch runs as consecutive solves of this many
members (`jax.lax.map`), each with its own step control: a part's stage buffers (about
17 x 7 x 1024 numbers for a free rotation with Dopri8, 1 MB in float64) stay in a core's
cache. B1 at N = 1e5 on a 2-core x86 CPU (L2 2 MB per core): 46 us per body as one solve,
18 us in parts of 1000, 20-27 us in parts of 2000-20000."""


def default_part_size(n: int) -> int:
    """Members per solve for a batch of `n`: all of them, except on a CPU (`CPU_PART`)."""
    return min(n, CPU_PART) if jax.default_backend() == "cpu" else n


@entry_point
def simulate_batched(scene, states0, ts, settings, batched_scene=False, part=None):
    """`simulate` for a batch (no floor): one solve of all members' coordinates, with the
    `SolverSettings` `settings` (its controller's norm is the batch's); on a CPU, one solve
    per part of `part` members (default: `default_part_size`), one after the other.

    A member with bad input starts from rest at the identity attitude with zero rates: it
    takes no part in the step control (its error is zero) and is flagged in `result`.
    `batched_scene`: every array leaf of `scene` has a leading axis N (one scene per member).
    """
    n = states0.pos.shape[0]
    part = default_part_size(n) if part is None else min(part, n)
    if part == n:
        return _solve_part(scene, states0, ts, settings, batched_scene)
    parts = -(-n // part)

    def split(x):  # (N, ...) -> (parts, part, ...), the last member repeated as padding
        return _padded(x, parts * part).reshape((parts, part) + x.shape[1:])

    scene_arrays, scene_rest = eqx.partition(scene, eqx.is_array)
    scene_parts = jax.tree.map(split, scene_arrays) if batched_scene else None

    def one(args):
        states_part, arrays = args
        scene_part = eqx.combine(arrays, scene_rest) if batched_scene else scene
        return _solve_part(scene_part, states_part, ts, settings, batched_scene)

    traj = jax.lax.map(one, (jax.tree.map(split, states0), scene_parts))

    def merge(x):  # (parts, part, ...) -> (N, ...)
        return x.reshape((parts * part,) + x.shape[2:])[:n]

    return _per_member(traj, merge, traj.ts[0])


def _solve_part(scene, states0, ts, settings, batched_scene):
    """One solve of all members of `states0` (see `simulate_batched`). Off a CPU, an explicit
    Runge-Kutta solver takes its steps with the stages written out (`batch_solver`); on a
    GPU, for the free rotation of bodies sharing one scene or each with its own inertia
    (`batched_scene`), each step is one kernel (`_fused_rotation_step.py`)."""
    coords = coordinates_for(scene)
    scene_axes = 0 if batched_scene else None
    dtype = ts.dtype
    member = jax.vmap(input_result, in_axes=(scene_axes, 0, None, None))(
        scene, states0, ts, settings.ok
    )
    valid = member == RESULTS.successful
    times_ok = jnp.all(jnp.isfinite(ts)) & jnp.all(jnp.diff(ts) >= 0) & settings.ok
    run_ts = safe_times(ts, times_ok)
    rest = State(
        jnp.zeros(3, dtype),
        jnp.array([1.0, 0.0, 0.0, 0.0], dtype),
        jnp.zeros(3, dtype),
        jnp.zeros(3, dtype),
    )
    states0 = _where_members(valid, states0, rest)
    # A member at rest takes no part in the step control if its rates are zero: they are
    # masked. The rotation of a free body at rest (omega = 0, no moment) has exactly zero
    # rates already, for any valid inertia; with one scene for all members a bad scene
    # flags every member, and a unit inertia stands in for its own. So the mask, 15 % of
    # B1's batched solve, is left out there.
    masked = batched_scene or coords is not ROTATION
    if masked:
        rates_scene = scene
    else:  # J^-1 once, before the solve: XLA leaves loop-invariant code in the loop on a CPU
        rates_scene = with_inertia_inverse(_unit_inertia_unless(jnp.any(valid), scene))

    def member_rates(scene_, t, y, state0, ok):
        rates = coords.rates(scene_, t, y, state0)
        return jax.tree.map(lambda r: jnp.where(ok, r, jnp.zeros_like(r)), rates)

    if masked:
        batch_rates = jax.vmap(member_rates, in_axes=(scene_axes, None, -1, 0, 0), out_axes=-1)
    else:
        batch_rates = lambda scene_, t, y, *_: coords.member_last_rates(scene_, y)  # noqa: E731
    n = states0.pos.shape[0]
    blocks = -(-n // BLOCK) * BLOCK  # whole kernel blocks: the last member repeated
    fused = None
    if on_gpu() and coords is ROTATION:  # a step as one kernel (free rotation, a GPU)
        if batched_scene:  # each member's J, J^-1 and validity as rows beside its state
            body = scene.body
            inverse = jax.vmap(lambda b: b.with_inertia_inverse().inertia_inverse)(body)
            rows = member_rows(body.inertia, inverse, valid)
            rows = _padded(rows.T, blocks).T
            fused = fused_rotation_solver(settings.solver, body, members=rows)
        else:
            fused = fused_rotation_solver(settings.solver, rates_scene.body)
    solver = batch_solver(settings.solver) if fused is None else fused
    settings = eqx.tree_at(lambda s: s.solver, settings, solver)
    # the members the solve integrates, padded to whole kernel blocks for the fused step
    # (the copies' error is the last member's: the step control is unchanged); a batched
    # scene is its own rates' scene (masked)
    solved_states, solved_valid, solved_scene = states0, valid, scene
    if fused is not None:
        pad = lambda tree: jax.tree.map(lambda x: _padded(x, blocks), tree)  # noqa: E731
        solved_states, solved_valid = pad((states0, valid))
        solved_scene = pad(scene) if batched_scene else scene
    solved_rates_scene = solved_scene if batched_scene else rates_scene
    y0 = jax.vmap(coords.reduce, in_axes=(scene_axes, 0), out_axes=-1)(solved_scene, solved_states)
    ys, num_steps, solver_result = solve(
        lambda t, y: batch_rates(solved_rates_scene, t, y, solved_states, solved_valid),
        y0,
        run_ts,
        settings,
    )
    ys = jax.tree.map(lambda y: y[..., :n], ys)
    ys = jax.tree.map(lambda y: jnp.moveaxis(y, -1, 0), ys)  # (T, ..., N) -> (N, T, ...)
    states = jax.vmap(coords.states, in_axes=(scene_axes, 0, None, 0))(scene, ys, run_ts, states0)
    states = _where_members(
        valid, states, jax.tree.map(lambda x: jnp.full_like(x, jnp.nan), states)
    )
    raw = jax.vmap(coords.raw_quat_norm, in_axes=(scene_axes, 0))(scene, ys)
    solver_result = RESULTS.promote(solver_result)
    return Trajectory(
        ts=ts,
        states=states,
        result=jax.vmap(lambda ok, m: RESULTS.where(ok, solver_result, m))(valid, member),
        quat_norm_drift=jnp.max(jnp.abs(raw - 1), axis=1),
        num_steps=jnp.broadcast_to(num_steps, (n,)),
    )


def simulate_batch(
    scene,
    states0: State,
    ts,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    dt0: float | None = None,
    max_steps: int = DEFAULT_MAX_STEPS,
    solver: dfx.AbstractSolver | None = None,
    adjoint: dfx.AbstractAdjoint | None = None,
    batched_scene: bool = False,
    devices=None,
    part_size: int | None = None,
    throw: bool = True,
) -> Trajectory:
    """Integrate a batch of bodies as one diffrax solve (`simulate` with a batched `state0`),
    with one scene per member if asked and the batch split over devices.

    **Arguments:**

    - `scene`: a `Scene` without a floor (free body or a joint), shared by the whole batch;
      or, with `batched_scene=True`, a scene whose every array leaf has a leading batch axis N
      (e.g. one inertia per body: build it with `jax.vmap` or `principal=True`).
    - `states0`: a `State` whose leaves have a leading batch axis N (pos (N, 3), quat (N, 4),
      vel (N, 3), omega (N, 3)); quaternions scalar first, body -> world, normalised on entry.
    - `ts`: increasing save times (s), shape (T,); all bodies share them.
    - `rtol`, `atol`: the step-size controller's tolerances (the step is accepted when the
      worst body's RMS error norm is <= 1). Defaults 1e-10: an error of about 1e-9 over tens
      of rotations (see benchmarks/). For float32 use ~1e-6.
    - `dt0`: initial step (s); default: diffrax's heuristic, batch-wide.
    - `max_steps`: the solver's step budget, batch-wide.
    - `solver`: any diffrax solver; default as `simulate` for a batch: `diffrax.Dopri8()`
      below rtol 1e-5 (and for a traced rtol), else `diffrax.Tsit5()`. Off a CPU a
      `Tsit5`, `Dopri5` or `Dopri8` takes its steps with the stages written out (the same
      method and steps; `jaxrb/_unrolled_stages.py`); on a GPU, for torque-free bodies
      sharing one scene or each with its own inertia (`batched_scene`), each step is one
      kernel (`jaxrb/_fused_rotation_step.py`; the per-member kernel is checked on the CPU in
      Pallas's interpreter, its speed not yet measured on a GPU).
    - `adjoint`: as `simulate`: reverse mode by default, `diffrax.ForwardMode()` for forward
      mode.
    - `batched_scene`: see `scene`.
    - `devices`: the batch is split evenly over these devices (padded to a multiple of their
      number), each part running its own solve, in parallel. Default: all of
      `jax.local_devices()` on GPUs; on a CPU, all of them for a free body under gravity
      only (whose right-hand side runs on one core per device) and the first one otherwise
      (the general path's compiled code already spreads over the cores); in either case at
      most one device per 50 bodies. On a CPU, JAX shows one device unless the process
      starts with `XLA_FLAGS=--xla_force_host_platform_device_count=K` (set before JAX is
      imported): then K cores can share the batch. The benchmarks set K to the number of
      cores.
    - `part_size`: members per solve. A device's share of the batch runs as consecutive
      solves of this many members, each with its own step control. Default: all of them on
      a GPU; `CPU_PART` (1024) on a CPU, where a larger solve's buffers no longer fit in a
      core's cache (B1: 46 us per body at N = 1e5 as one solve, 18 us in parts of 1000).
    - `throw`: raise if the input is bad or `max_steps` is hit; else return per-body
      `result` codes: a bad body is flagged (it takes no part in the step control, its
      states are NaN) while the others are computed.

    **Returns:** a `jaxrb.Trajectory` whose `states` leaves have shape (N, T, ...) (as
    `jax.vmap(simulate)` returns), `ts` (T,), and `result`, `quat_norm_drift`, `num_steps`
    of shape (N,) (`num_steps`: the steps of the member's part).

    All bodies of a part take the same steps, so one stiff or fast body sets the step for
    all: batch bodies of similar time scales together (the benchmarks do).
    """
    if scene.floor is not None:
        raise ValueError(
            "simulate_batch: scenes with a floor (impacts) are not supported; use simulate"
        )
    if not isinstance(states0, State):
        raise TypeError(f"states0 must be a jaxrb.State, got {type(states0).__name__}")
    for name, n in (("pos", 3), ("quat", 4), ("vel", 3), ("omega", 3)):
        x = jnp.asarray(getattr(states0, name))
        if x.ndim != 2 or x.shape[-1] != n:
            raise ValueError(f"states0.{name} must have shape (N, {n}), got {x.shape}")
    n_batch = {jnp.shape(getattr(states0, k))[0] for k in ("pos", "quat", "vel", "omega")}
    if len(n_batch) != 1:
        raise ValueError(f"states0 leaves have different batch sizes {sorted(n_batch)}")
    if part_size is not None and (
        isinstance(part_size, bool) or not isinstance(part_size, int) or part_size < 1
    ):
        raise ValueError(f"part_size must be a positive int or None, got {part_size!r}")
    dtype = jnp.result_type(*[getattr(states0, k) for k in ("pos", "quat", "vel", "omega")])
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"ts must be a 1-D array of save times, got shape {ts.shape}")
    ts = ts.astype(dtype)
    states0 = jax.tree.map(lambda x: jnp.asarray(x, dtype), states0)
    if throw:
        check_batch_inputs(states0)
        check_concrete_inputs(states0, ts)
    settings = solver_settings(
        solver=default_solver(rtol, batch=True) if solver is None else solver,
        rtol=rtol,
        atol=atol,
        dt0=dt0,
        max_steps=max_steps,
        stepsize_controller=None,
        adjoint=adjoint,
        progress_meter=None,
        throw=throw,
        dtype=dtype,
    )
    # tolerances are traced values: changing them does not recompile
    rtol, atol = jnp.asarray(rtol, dtype), jnp.asarray(atol, dtype)
    n_bodies = states0.pos.shape[0]
    devices = list(_default_devices(scene, n_bodies) if devices is None else devices)
    if not devices:
        raise ValueError("devices must name at least one device")

    def run(scene_part, states_part, rtol, atol, ok):
        controller = dfx.PIDController(rtol=rtol, atol=atol, norm=batch_rms_norm)
        part_settings = eqx.tree_at(lambda s: (s.controller, s.ok), settings, (controller, ok))
        return simulate_batched(
            scene_part, states_part, ts, part_settings, batched_scene, part_size
        )

    args = (rtol, atol, settings.ok)
    if len(devices) == 1:
        traj = run(scene, states0, *args)
    else:
        traj = _sharded(run, scene, states0, args, batched_scene, devices)
    if throw:  # outside the compiled function: throw=True/False share one compilation
        traj = raise_if_failed(traj)
    return traj


_MIN_BODIES_PER_DEVICE = 50  # below this, a part's fixed per-step cost outweighs the split


def _default_devices(scene, n_bodies):
    devices = jax.local_devices()
    if devices[0].platform == "cpu" and coordinates_for(scene) is not ROTATION:
        return devices[:1]
    return devices[: max(1, min(len(devices), n_bodies // _MIN_BODIES_PER_DEVICE))]


def _sharded(run, scene, states0, args, batched_scene, devices):
    """`run` on equal parts of the batch, one per device, with `jax.shard_map`."""
    n = states0.pos.shape[0]
    total = n + (-n) % len(devices)

    def padded(x):  # repeat the last body to fill the last part
        return _padded(x, total)

    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    part, whole = jax.sharding.PartitionSpec("batch"), jax.sharding.PartitionSpec()
    scene_arrays, scene_rest = eqx.partition(scene, eqx.is_array)
    if batched_scene:
        scene_arrays = jax.tree.map(padded, scene_arrays)

    def one_part(states, arrays, *args):
        return run(eqx.combine(arrays, scene_rest), states, *args)

    out_specs = Trajectory(ts=whole, states=part, result=part, quat_norm_drift=part, num_steps=part)
    traj = jax.shard_map(
        one_part,
        mesh=mesh,
        in_specs=(part, part if batched_scene else whole) + (whole,) * len(args),
        out_specs=out_specs,
        check_vma=False,  # ts comes back identical from every part
    )(jax.tree.map(padded, states0), scene_arrays, *args)
    if total > n:
        traj = _per_member(traj, lambda x: x[:n], traj.ts)
    return traj
