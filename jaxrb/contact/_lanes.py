"""Many throws of a scene with a floor, in lanes that are refilled as throws finish.

`jax.vmap(jaxrb.simulate)` runs a batch of bodies in lockstep: every pass of its segment loop
applies one event map and integrates one smooth segment for every member, and the loop runs
until the member with the most events is done, so a batch of dice costs as much as its
longest throw times the batch size. `simulate_throws` runs N throws in L lanes (L <= N): a
lane whose throw has finished writes its trajectory and takes the next throw not yet
started, so that every lane keeps working until the throws run out, and a throw with few
events costs few passes. Each lane runs exactly the passes of `jaxrb.simulate` (the same
`ContactProgram`), so every throw's trajectory is the one `simulate` gives, to roundoff.

With one lane (the default on a CPU) the throws run one after another, each through the
program `simulate` compiles for one throw (`run_throw`), in a `jax.lax.map`: on a CPU that
costs the least per throw, and it compiles what a single `simulate` compiles. Where the
process has several CPU devices the throws are split over them (`map_throws`), each device
running its share on a core of its own. On a CPU a
batch gains little from running lanes side by side, since each of the program's many small
operations costs about the same for a few lanes as for one, while a batch does the work
that any one lane needs (an impact, a search for a slip direction) for all of them.
"""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from .._checks import as_float_array
from .._inputs import save_times
from .._persistent import entry_point
from .._scene import with_inertia_inverse
from .._solver_settings import solver_settings
from .._state import State
from ._driver import check_contact_scene, contact_program, run_throw
from ._modes import tree_index
from ._options import ContactOptions

DEFAULT_LANES = 64  # on a GPU


def one_after_another() -> bool:
    """Whether batches of throws run one after another rather than side by side: where
    JAX's default backend is the CPU (measured there: one throw at a time is the cheapest
    per throw, side by side costs more). `default_lanes` and `simulate` of a batch of
    states with a floor follow it."""
    return jax.default_backend() == "cpu"


def map_throws(fn, xs):
    """`jax.lax.map(fn, xs)` (`xs`: a pytree of arrays with a leading axis of N throws), the
    throws split evenly over the process's CPU devices where there are several (JAX shows
    K when the process starts with `XLA_FLAGS=--xla_force_host_platform_device_count=K`):
    each device runs its share one after another, and the devices run side by side, one
    core each (on a 2-core x86 CPU `simulate_throws` of B4's 16 dice took 1.6-2.6x less
    time per die on two devices than `simulate` of the batch on one). The throws are padded
    to a multiple of the devices' number with copies of the first, whose results are
    dropped. Each throw's result is its own `fn`'s, to roundoff."""
    n = jax.tree.leaves(xs)[0].shape[0]
    devices = jax.local_devices()
    k = min(len(devices), n)
    if k <= 1 or devices[0].platform != "cpu":
        return jax.lax.map(fn, xs)
    pad = -n % k
    padded = jax.tree.map(
        lambda x: jnp.concatenate([x, jnp.broadcast_to(x[:1], (pad,) + x.shape[1:])]), xs
    )
    mesh = Mesh(np.array(devices[:k]), ("throws",))
    run = jax.shard_map(
        lambda part: jax.lax.map(fn, part),
        mesh=mesh,
        in_specs=PartitionSpec("throws"),
        out_specs=PartitionSpec("throws"),
        check_vma=False,
    )
    return jax.tree.map(lambda x: x[:n], run(padded))


def default_lanes(n: int) -> int:
    """The default number of lanes for `n` throws: 1 where throws run `one_after_another`,
    else `min(n, DEFAULT_LANES)`."""
    return 1 if one_after_another() else min(n, DEFAULT_LANES)


def simulate_throws(
    scene,
    states0: State,
    ts,
    *,
    lanes: int | None = None,
    batched_scene: bool = False,
    solver: dfx.AbstractSolver | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    dt0: float | None = None,
    max_steps: int = 100_000,
    stepsize_controller: dfx.AbstractStepSizeController | None = None,
    max_impacts: int | None = None,
    rest_speed: float | None = None,
    contact: ContactOptions | None = None,
):
    """Simulate N throws of `scene` (a scene with a floor) from `states0`, saved at `ts`,
    in `lanes` lanes refilled as throws finish (module docstring).

    **Arguments:**

    - `scene`: a `Scene` with a floor; with `batched_scene=True` every array leaf of it has
      a leading axis N (one scene per throw: e.g. a restitution per throw), else it is
      shared.
    - `states0`: a `State` whose leaves have a leading axis N (quaternions of any non-zero
      norm).
    - `ts`: increasing save times (s), shape (T,), shared by every throw.
    - `lanes`: how many throws run at once (default `default_lanes(N)`: 1 on a CPU,
      `min(N, 64)` on a GPU). More lanes use a GPU's threads; on a CPU one lane, the throws
      one after another, costs the least (module docstring), and with several CPU devices
      (`XLA_FLAGS=--xla_force_host_platform_device_count=K` set before JAX starts) the
      throws are split over them, one core each.
    - `solver`, `rtol`, `atol`, `dt0`, `max_steps`, `stepsize_controller`, `max_impacts`,
      `rest_speed`, `contact`: as in `jaxrb.simulate`.

    **Returns:** a `Trajectory` whose leaves have a leading axis N, as `jax.vmap(simulate)`
    gives with `throw=False`: a throw with bad input or a failed solve is flagged in its
    `result`, and the others are computed.

    Not differentiable (the lanes' bookkeeping is a plain loop): for gradients, use
    `jax.vmap(jaxrb.simulate)`.
    """
    if scene.floor is None:
        raise ValueError("simulate_throws needs a scene with a floor; use jaxrb.simulate")
    ts = save_times(ts)
    if not isinstance(states0, State):
        raise TypeError(f"states0 must be a jaxrb.State, got {type(states0).__name__}")
    for name, k in (("pos", 3), ("quat", 4), ("vel", 3), ("omega", 3)):
        x = as_float_array(getattr(states0, name), f"states0.{name}", (k,))
        if x.ndim != 2:
            raise ValueError(f"states0.{name} must have shape (N, {k}), got {x.shape}")
    n = states0.pos.shape[0]
    if n < 1:
        raise ValueError("states0 holds no throw (N = 0)")
    if batched_scene:
        for leaf in jax.tree.leaves(eqx.filter(scene, eqx.is_array)):
            if leaf.ndim < 1 or leaf.shape[0] != n:
                raise ValueError(
                    f"with batched_scene=True every array of the scene needs a leading axis "
                    f"of N = {n}, found one of shape {leaf.shape}"
                )
    lanes = default_lanes(n) if lanes is None else int(lanes)
    if lanes < 1:
        raise ValueError(f"lanes must be >= 1, got {lanes}")
    lanes = min(lanes, n)
    contact = ContactOptions.from_shortcuts(contact, max_impacts, rest_speed)
    one_scene = jax.tree.map(lambda x: x[0], scene) if batched_scene else scene
    check_contact_scene(one_scene, contact)
    settings = solver_settings(
        solver=dfx.Tsit5() if solver is None else solver,
        rtol=rtol,
        atol=atol,
        dt0=dt0,
        max_steps=max_steps,
        stepsize_controller=stepsize_controller,
        adjoint=None,
        progress_meter=None,
        throw=False,
        dtype=ts.dtype,
    )
    states0 = jax.tree.map(lambda x: jnp.asarray(x, ts.dtype), states0)
    return _throws(
        scene, states0, ts, settings, contact, contact.resolved(ts.dtype), lanes, batched_scene
    )


@entry_point
def _throws(scene, states0, ts, settings, options, tol, lanes, batched_scene):
    n = states0.pos.shape[0]
    scene = with_inertia_inverse(scene)

    def scene_of(i):
        return tree_index(scene, i) if batched_scene else scene

    def program_of(s):
        return contact_program(s, settings, options, tol)

    def start(i):
        s = scene_of(i)
        return program_of(s).start(s, tree_index(states0, i), ts)

    def advance(i, carry):
        s = scene_of(i)
        return program_of(s).advance(s, carry)

    def trajectory(i, carry):
        return program_of(scene_of(i)).trajectory(carry, ts)

    if lanes == 1:  # one throw after another, each through `simulate`'s own program

        def one(i):
            state0 = tree_index(states0, i)
            return run_throw(scene_of(i), state0, ts, settings, options, tol, "lax")

        return map_throws(one, jnp.arange(n))

    first = jnp.arange(lanes)
    carries = jax.vmap(start)(first)
    # the trajectories of all N throws, filled as they finish
    shapes = jax.eval_shape(jax.vmap(trajectory), first, carries)
    out0 = jax.tree.map(lambda s: jnp.zeros((n,) + s.shape[1:], s.dtype), shapes)
    passes_allowed = options.max_events + 1  # the start, then one pass per event

    def running(loop):
        throw_of_lane = loop[1]
        return jnp.any(throw_of_lane < n)

    def step(loop):
        carries, throw_of_lane, next_throw, out = loop
        idle = throw_of_lane >= n
        index = jnp.minimum(throw_of_lane, n - 1)
        carries = jax.vmap(advance)(index, carries)
        finished = ~idle & (carries["done"] | (carries["passes"] >= passes_allowed))
        # write the finished throws' trajectories (the other lanes' rows are dropped)
        rows = jnp.where(finished, throw_of_lane, n)
        trajs = jax.vmap(trajectory)(index, carries)
        out = jax.tree.map(lambda o, t: o.at[rows].set(t, mode="drop"), out, trajs)
        # refill the finished lanes with the next throws
        new = next_throw + jnp.cumsum(finished) - 1
        refill = finished & (new < n)
        fresh = jax.vmap(start)(jnp.where(refill, new, 0))
        carries = jax.tree.map(
            lambda f, c: jnp.where(refill.reshape((-1,) + (1,) * (c.ndim - 1)), f, c),
            fresh,
            carries,
        )
        throw_of_lane = jnp.where(finished, jnp.where(refill, new, n), throw_of_lane)
        return carries, throw_of_lane, next_throw + jnp.sum(finished), out

    loop = (carries, first, jnp.asarray(lanes), out0)
    return jax.lax.while_loop(running, step, loop)[3]
