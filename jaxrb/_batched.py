"""A lean batched integrator: Dormand-Prince 8(5,3) over a whole batch as one array program.

`jax.vmap(jaxrb.simulate)` runs diffrax's general machinery (pytree solver state, dense
interpolation, event and progress hooks, per-member step sizes) once per body; for small
right-hand sides such as one rigid body's 13 states that machinery costs more than the
physics. `simulate_batch` integrates the batch as a single set of arrays with leading batch
axis N: every stage is one call of `jaxrb.vector_field` on (N, ...) arrays, and a batch-wide
step-size controller (the worst body's error decides) runs in one `jax.lax.while_loop`.
Only what the scene needs is integrated: when every force is uniform gravity (or there is
none) and there is no joint, the mass centre's motion is the exact parabola and only the
rotation (quaternion and body-frame omega) goes through the integrator.

The scheme is Hairer's DOP853 (explicit Runge-Kutta of order 8 with Hairer's 5th- and
3rd-order error estimators; E. Hairer, S. P. Norsett, G. Wanner, Solving Ordinary
Differential Equations I, 2nd ed., section II.10), the same scheme as scipy's
`solve_ivp(method="DOP853")`; the coefficients are Hairer's.

The same `Scene`, `State` and `Trajectory` types as `jaxrb.simulate` are used (free bodies and
jointed scenes; no floor), so the two are interchangeable in user code: the returned states
have leaves of shape (N, T, ...), exactly as `jax.vmap(simulate)` gives.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._dynamics import vector_field
from ._forces import Gravity
from ._inputs import check_concrete_inputs, check_solver_settings, input_result, safe_times
from ._quaternion import quat_normalize
from ._results import RESULTS
from ._simulate import _coordinates
from ._state import State
from ._trajectory import Trajectory

# Hairer's DOP853 tableau (12 stages), the 5th- and 3rd-order error weights.
_C = (
    0.0,
    0.05260015195876773,
    0.0789002279381516,
    0.1183503419072274,
    0.2816496580927726,
    0.3333333333333333,
    0.25,
    0.3076923076923077,
    0.6512820512820513,
    0.6,
    0.8571428571428571,
    1.0,
)
_A = (
    (),
    (0.05260015195876773,),
    (0.0197250569845379, 0.0591751709536137),
    (0.02958758547680685, 0.0, 0.08876275643042054),
    (0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792),
    (0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242),
    (0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125),
    (
        0.03709200011850479,
        0.0,
        0.0,
        0.17038392571223998,
        0.10726203044637328,
        -0.015319437748624402,
        0.008273789163814023,
    ),
    (
        0.6241109587160757,
        0.0,
        0.0,
        -3.3608926294469414,
        -0.868219346841726,
        27.59209969944671,
        20.154067550477894,
        -43.48988418106996,
    ),
    (
        0.47766253643826434,
        0.0,
        0.0,
        -2.4881146199716677,
        -0.590290826836843,
        21.230051448181193,
        15.279233632882423,
        -33.28821096898486,
        -0.020331201708508627,
    ),
    (
        -0.9371424300859873,
        0.0,
        0.0,
        5.186372428844064,
        1.0914373489967295,
        -8.149787010746927,
        -18.52006565999696,
        22.739487099350505,
        2.4936055526796523,
        -3.0467644718982196,
    ),
    (
        2.273310147516538,
        0.0,
        0.0,
        -10.53449546673725,
        -2.0008720582248625,
        -17.9589318631188,
        27.94888452941996,
        -2.8589982771350235,
        -8.87285693353063,
        12.360567175794303,
        0.6433927460157636,
    ),
)
_B = (
    0.054293734116568765,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    0.3111643669578199,
    -0.1521609496625161,
    0.20136540080403034,
    0.04471061572777259,
)
_E3 = (
    -0.18980075407240762,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    -0.4226823213237919,
    -0.1521609496625161,
    0.20136540080403034,
    0.02265179219836082,
    0.0,
)
_E5 = (
    0.01312004499419488,
    0.0,
    0.0,
    0.0,
    0.0,
    -1.2251564463762044,
    -0.4957589496572502,
    1.6643771824549864,
    -0.35032884874997366,
    0.3341791187130175,
    0.08192320648511571,
    -0.022355307863886294,
    0.0,
)


class _BallisticFree(eqx.Module):
    """Coordinates of a free body whose mass centre feels uniform gravity or nothing: the
    translation is the exact parabola p0 + v0 t + g t^2 / 2, so only the rotation (quat,
    omega: 7 numbers instead of 13) is integrated. Chosen when every force is `Gravity`
    (which exerts no moment about the mass centre) and there is no joint."""

    g: jax.Array  # (3,) or (N, 3) world frame, m/s^2

    def reduce(self, state0):
        return (quat_normalize(state0.quat), state0.omega)

    def expand(self, y, state0):
        """The state with the *initial* translation (see `translation`)."""
        quat, omega = y
        return State(state0.pos, quat_normalize(quat), state0.vel, omega)

    def coordinate_rates(self, y, rates):
        return (rates.quat, rates.omega)

    def raw_quat_norm(self, y):
        return jnp.linalg.norm(y[0], axis=-1)

    def translation(self, states0, elapsed):
        """(pos, vel) of shape (N, T, 3) at times `elapsed` (T,) after the start."""
        g = self.g.astype(states0.pos.dtype)[..., None, :]
        dt = elapsed[:, None]
        pos = states0.pos[:, None, :] + states0.vel[:, None, :] * dt + 0.5 * g * dt**2
        return pos, states0.vel[:, None, :] + g * dt


def _batch_coordinates(scene):
    """Integration coordinates: rotation only when the translation is ballistic."""
    if scene.joint is None and all(isinstance(f, Gravity) for f in scene.forces):
        dtype = jnp.result_type(float)
        g = sum((f.g for f in scene.forces), jnp.zeros(3, dtype))
        return _BallisticFree(g)
    return _coordinates(scene)


_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERROR_EXPONENT = -1.0 / 8.0


def _per_body_sum(tree, batch_axis):
    """Sum over every axis but the batch axis (0 or -1), over all leaves: shape (N,)."""
    leaves = [jnp.moveaxis(x, batch_axis, 0) for x in jax.tree.leaves(tree)]
    return sum(jnp.sum(x.reshape(x.shape[0], -1), axis=1) for x in leaves)


def _per_body_size(tree, batch_axis) -> int:
    return sum(int(np.prod(np.delete(x.shape, batch_axis))) for x in jax.tree.leaves(tree))


def _axpy(y, h, ks, weights):
    """y + h * sum_i w_i k_i over pytrees, skipping zero weights (resolved at trace time)."""
    terms = [(w, k) for w, k in zip(weights, ks, strict=False) if w != 0.0]
    if not terms:
        return y

    def combine(y_leaf, *k_leaves):
        acc = terms[0][0] * k_leaves[0]
        for (w, _), k in zip(terms[1:], k_leaves[1:], strict=True):
            acc = acc + w * k
        return y_leaf + h * acc

    return jax.tree.map(combine, y, *[k for _, k in terms])


def dop853_step(rhs, t, y, h):
    """One DOP853 step of size h (scalar) for a batched pytree y.

    **Returns:** `(y_new, err5, err3)`: the 8th-order solution and the two error estimates
    (pytrees like y, without the factor h).
    """
    ks = []
    for i in range(12):
        yi = _axpy(y, h, ks, _A[i])
        ks.append(rhs(t + _C[i] * h, yi))
    y_new = _axpy(y, h, ks, _B)
    err5 = _axpy(jax.tree.map(jnp.zeros_like, y), 1.0, ks, _E5[:12])
    err3 = _axpy(jax.tree.map(jnp.zeros_like, y), 1.0, ks, _E3[:12])
    return y_new, err5, err3


def _error_norm(y0, y1, err5, err3, h, rtol, atol, batch_axis):
    """Hairer's combined DOP853 error norm per body (shape (N,)); <= 1 means acceptable."""
    scale = jax.tree.map(lambda a, b: atol + rtol * jnp.maximum(jnp.abs(a), jnp.abs(b)), y0, y1)
    e5 = _per_body_sum(jax.tree.map(lambda e, s: (e / s) ** 2, err5, scale), batch_axis)
    e3 = _per_body_sum(jax.tree.map(lambda e, s: (e / s) ** 2, err3, scale), batch_axis)
    n = _per_body_size(y0, batch_axis)
    denom = e5 + 0.01 * e3
    safe = jnp.where(denom > 0, denom, 1.0)
    return jnp.where(denom > 0, jnp.abs(h) * e5 / jnp.sqrt(safe * n), 0.0)


def simulate_batch(
    scene,
    states0: State,
    ts,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    dt0: float | None = None,
    max_steps: int = 100_000,
    batched_scene: bool = False,
    devices=None,
    throw: bool = True,
) -> Trajectory:
    """Integrate a batch of bodies with one batch-wide adaptive DOP853 loop.

    **Arguments:**

    - `scene`: a `Scene` without a floor (free body or a joint), shared by the whole batch;
      or, with `batched_scene=True`, a scene whose every array leaf has a leading batch axis N
      (e.g. one inertia per body: build it with `jax.vmap` or `principal=True`).
    - `states0`: a `State` whose leaves have a leading batch axis N (pos (N, 3), quat (N, 4),
      vel (N, 3), omega (N, 3)); quaternions scalar first, body -> world, normalised on entry.
    - `ts`: increasing save times (s), shape (T,); all bodies share them.
    - `rtol`, `atol`: the controller's tolerances (per component, Hairer's DOP853 norm per
      body; the step is accepted when the worst body's norm is <= 1). Defaults 1e-10: an
      error of about 1e-8 over tens of rotations (see benchmarks/). For float32 use ~1e-6.
    - `dt0`: initial step (s); default: Hairer's first-step heuristic, batch-wide.
    - `max_steps`: bound on step attempts (accepted + rejected).
    - `batched_scene`: see `scene`.
    - `devices`: the batch is split evenly over these devices (padded to a multiple of their
      number), each part running its own adaptive loop, in parallel. Default: all of
      `jax.local_devices()` on GPUs; on a CPU, all of them for a free body under gravity
      only (whose right-hand side runs on one core per device) and the first one otherwise
      (the general path's compiled code already spreads over the cores: measured on 2 cores,
      splitting it made the heavy top 1.25x slower); in either case at most one device per
      50 bodies (measured: 10 bodies on 2 CPU devices took 1.4x longer than on one). On a
      CPU, JAX shows one device unless the process starts with
      `XLA_FLAGS=--xla_force_host_platform_device_count=K` (set before JAX is imported):
      then K cores can share the batch. The benchmarks set K to the number of cores.
    - `throw`: raise if the input is bad or `max_steps` is hit; else return per-body
      `result` codes: a bad body is flagged (and starts from rest, taking no part in the
      step control) while the others are computed.

    **Returns:** a `jaxrb.Trajectory` whose `states` leaves have shape (N, T, ...) (as
    `jax.vmap(simulate)` returns), and `result`, `quat_norm_drift`, `num_steps` of shape (N,).

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
    dtype = jnp.result_type(*[getattr(states0, k) for k in ("pos", "quat", "vel", "omega")])
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"ts must be a 1-D array of save times, got shape {ts.shape}")
    ts = ts.astype(dtype)
    states0 = jax.tree.map(lambda x: jnp.asarray(x, dtype), states0)
    if throw:
        check_concrete_inputs(states0, ts)
    check_solver_settings(rtol, atol, dt0, max_steps, throw)
    # tolerances and the step budget are traced values: changing them does not recompile
    rtol, atol = jnp.asarray(rtol, dtype), jnp.asarray(atol, dtype)
    max_steps = jnp.asarray(max_steps, jnp.int32)
    n_bodies = states0.pos.shape[0]
    devices = list(_default_devices(scene, n_bodies) if devices is None else devices)
    if not devices:
        raise ValueError("devices must name at least one device")
    if len(devices) == 1:
        traj = _simulate_batch(scene, states0, ts, rtol, atol, dt0, max_steps, batched_scene)
    else:
        traj = _simulate_sharded(
            scene, states0, ts, rtol, atol, dt0, max_steps, batched_scene, devices
        )
    if throw:  # outside the compiled loop: throw=True/False share one compilation
        traj = traj.result.error_if(traj, traj.result != RESULTS.successful)
    return traj


_MIN_BODIES_PER_DEVICE = 50  # below this, a part's fixed per-step cost outweighs the split


def _default_devices(scene, n_bodies):
    devices = jax.local_devices()
    if devices[0].platform == "cpu" and not isinstance(_batch_coordinates(scene), _BallisticFree):
        return devices[:1]
    return devices[: max(1, min(len(devices), n_bodies // _MIN_BODIES_PER_DEVICE))]


def _simulate_sharded(scene, states0, ts, rtol, atol, dt0, max_steps, batched_scene, devices):
    """`_simulate_batch` on equal parts of the batch, one per device, with `jax.shard_map`."""
    n = states0.pos.shape[0]
    pad = (-n) % len(devices)

    def padded(x):  # repeat the last body to fill the last part
        return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]) if pad else x

    mesh = jax.sharding.Mesh(np.array(devices), ("batch",))
    part, whole = jax.sharding.PartitionSpec("batch"), jax.sharding.PartitionSpec()
    scene_arrays, scene_rest = eqx.partition(scene, eqx.is_array)
    if batched_scene:
        scene_arrays = jax.tree.map(padded, scene_arrays)

    def one_part(states, arrays, rtol, atol, max_steps):
        scene_part = eqx.combine(arrays, scene_rest)
        return _simulate_batch(scene_part, states, ts, rtol, atol, dt0, max_steps, batched_scene)

    out_specs = Trajectory(ts=whole, states=part, result=part, quat_norm_drift=part, num_steps=part)
    traj = jax.shard_map(
        one_part,
        mesh=mesh,
        in_specs=(part, part if batched_scene else whole, whole, whole, whole),
        out_specs=out_specs,
        check_vma=False,  # ts comes back identical from every part
    )(jax.tree.map(padded, states0), scene_arrays, rtol, atol, max_steps)
    if pad:
        traj = Trajectory(
            ts=traj.ts,
            states=jax.tree.map(lambda x: x[:n], traj.states),
            result=jax.tree.map(lambda x: x[:n], traj.result),
            quat_norm_drift=traj.quat_norm_drift[:n],
            num_steps=traj.num_steps[:n],
        )
    return traj


@eqx.filter_jit
def _simulate_batch(scene, states0, ts, rtol, atol, dt0, max_steps, batched_scene):
    coords = _batch_coordinates(scene)
    n_save = ts.shape[0]
    dtype = ts.dtype

    # Per-body input checks. A bad body starts from rest at the identity and its rates are
    # zero, so it neither takes the batch's steps down with it nor stops the others.
    scene_axes = 0 if batched_scene else None
    member = jax.vmap(input_result, in_axes=(scene_axes, 0, None))(scene, states0, ts)
    valid = member == RESULTS.successful
    ts = safe_times(ts, jnp.all(jnp.isfinite(ts)) & jnp.all(jnp.diff(ts) >= 0))
    rest = State(
        jnp.zeros(3, dtype),
        jnp.array([1.0, 0.0, 0.0, 0.0], dtype),
        jnp.zeros(3, dtype),
        jnp.zeros(3, dtype),
    )
    states0 = jax.tree.map(
        lambda x, r: jnp.where(valid.reshape((-1,) + (1,) * (x.ndim - 1)), x, r), states0, rest
    )

    def rhs_one(t, y, state0, scene_, ok):
        rates = coords.coordinate_rates(y, vector_field(t, coords.expand(y, state0), scene_))
        return jax.tree.map(lambda r: jnp.where(ok, r, 0.0), rates)

    if isinstance(coords, _BallisticFree):
        # Rotation only, no forces in play: Euler's equations and the quaternion kinematics
        # broadcast over leading axes, so one call on (N, components) arrays evaluates the
        # whole batch as a few fused loops (measured: 1.4x faster per step than mapping the
        # one-body function over a batch axis).
        batch_axis = 0

        def rhs(t, y):
            return rhs_one(t, y, states0, scene, valid[:, None])
    else:
        # Any force model or joint: map the one-body right-hand side over the batch (which
        # every force supports) on a structure of arrays, each leaf (components..., N).
        batch_axis = -1
        rhs_soa = jax.vmap(rhs_one, in_axes=(None, -1, 0, scene_axes, 0), out_axes=-1)

        def rhs(t, y):
            return rhs_soa(t, y, states0, scene, valid)

    y0 = jax.tree.map(lambda x: jnp.moveaxis(x, 0, batch_axis), coords.reduce(states0))

    span = ts[-1] - ts[0]
    if dt0 is None:
        # Hairer's heuristic (first part): h = 0.01 |y0| / |f0| in the scaled norm, worst body.
        f0 = rhs(ts[0], y0)
        scale = jax.tree.map(lambda a: atol + rtol * jnp.abs(a), y0)
        n = _per_body_size(y0, batch_axis)
        d0 = jnp.sqrt(
            _per_body_sum(jax.tree.map(lambda a, s: (a / s) ** 2, y0, scale), batch_axis) / n
        )
        d1 = jnp.sqrt(
            _per_body_sum(jax.tree.map(lambda a, s: (a / s) ** 2, f0, scale), batch_axis) / n
        )
        h_body = jnp.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / jnp.maximum(d1, 1e-30))
        h0 = jnp.min(h_body)
    else:
        h0 = jnp.asarray(dt0, dtype)
    h0 = jnp.minimum(h0, jnp.where(span > 0, span, 1.0))

    buffer = jax.tree.map(lambda x: jnp.zeros((n_save,) + x.shape, x.dtype).at[0].set(x), y0)

    def cond(carry):
        _, _, _, _, idx, attempts, _ = carry
        return (idx < n_save) & (attempts < max_steps)

    def body(carry):
        t, h, y, ys, idx, attempts, accepted = carry
        t_next = ts[jnp.minimum(idx, n_save - 1)]
        remaining = t_next - t
        clipped = h >= remaining
        h_try = jnp.where(clipped, remaining, h)
        y_new, err5, err3 = dop853_step(rhs, t, y, h_try)
        err = jnp.max(_error_norm(y, y_new, err5, err3, h_try, rtol, atol, batch_axis))
        err = jnp.where(jnp.isfinite(err), err, jnp.inf)
        ok = (err <= 1.0) | (remaining <= 0)
        factor = jnp.where(
            err == 0, _MAX_FACTOR, _SAFETY * jnp.where(err > 0, err, 1.0) ** _ERROR_EXPONENT
        )
        factor = jnp.clip(factor, _MIN_FACTOR, jnp.where(ok, _MAX_FACTOR, 1.0))
        factor = jnp.where(jnp.isfinite(err), factor, _MIN_FACTOR)
        h_base = jnp.where(clipped & ok, jnp.maximum(h, h_try), h_try)
        h_new = jnp.where(ok & clipped, h_base, h_try * factor)
        h_new = jnp.where(ok & ~clipped, h_try * factor, h_new)
        t_new = jnp.where(ok, jnp.where(clipped, t_next, t + h_try), t)
        y_out = jax.tree.map(lambda a, b: jnp.where(ok, a, b), y_new, y)
        hit = ok & clipped
        ys = jax.tree.map(
            lambda buf, v: jax.lax.dynamic_update_index_in_dim(
                buf,
                jnp.where(hit, v, buf[jnp.minimum(idx, n_save - 1)]),
                jnp.minimum(idx, n_save - 1),
                0,
            ),
            ys,
            y_out,
        )
        idx = idx + hit.astype(idx.dtype)
        return t_new, h_new, y_out, ys, idx, attempts + 1, accepted + ok.astype(accepted.dtype)

    zero = jnp.asarray(0, jnp.int32)
    carry0 = (ts[0], h0, y0, buffer, jnp.asarray(1, jnp.int32), zero, zero)
    _, _, _, ys, idx, attempts, accepted = jax.lax.while_loop(cond, body, carry0)

    n_batch = jax.tree.leaves(y0)[0].shape[batch_axis]
    # ys leaves: (T, N, components...) or (T, components..., N) -> (N, T, components...)
    ys = jax.tree.map(lambda x: jnp.moveaxis(x, 1 if batch_axis == 0 else -1, 0), ys)
    states = jax.vmap(jax.vmap(coords.expand, in_axes=(0, None)), in_axes=(0, 0))(ys, states0)
    if isinstance(coords, _BallisticFree):
        pos, vel = coords.translation(states0, ts - ts[0])
        states = State(pos, states.quat, vel, states.omega)
    raw = jax.vmap(jax.vmap(coords.raw_quat_norm))(ys)
    drift = jnp.broadcast_to(jnp.max(jnp.abs(raw - 1), axis=1), (n_batch,))
    # the step-size controller is batch-wide, so max_steps is too
    finished = idx >= n_save
    solver_result = RESULTS.where(finished, RESULTS.successful, RESULTS.max_steps_reached)
    result = jax.vmap(lambda ok, m: RESULTS.where(ok, solver_result, m))(valid, member)
    traj = Trajectory(
        ts=ts,
        states=states,
        result=result,
        quat_norm_drift=drift,
        num_steps=jnp.broadcast_to(accepted, (n_batch,)),
    )
    return traj
