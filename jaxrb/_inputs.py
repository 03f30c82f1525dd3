"""Input checks of `simulate`, shared by the smooth and the contact paths: a traceable result
code per batch member, and early errors for concrete bad input."""

import jax
import jax.numpy as jnp
import numpy as np

from . import inertia as _inertia
from ._checks import is_concrete
from ._results import RESULTS
from ._state import State


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


def check_concrete_inputs(state0: State, ts) -> None:
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
