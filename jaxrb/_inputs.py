"""Input checks of `simulate`, shared by the smooth and the contact paths: a traceable result
code per batch member, and early errors for concrete bad input."""

import jax
import jax.numpy as jnp
import numpy as np

from . import inertia as _inertia
from ._checks import (
    Requirement,
    all_met,
    as_computed,
    finite_nonnegative,
    finite_positive,
    is_concrete,
    nonzero_rows,
    raise_unmet,
)
from ._results import RESULTS
from ._state import State


def solver_requirements(rtol, atol, dt0) -> tuple[Requirement, ...]:
    """Conditions on the step-size controller's tolerances and the initial step."""
    rtol, atol = jnp.asarray(rtol), jnp.asarray(atol)
    reqs = [
        Requirement("rtol", rtol, "finite and >= 0", finite_nonnegative(rtol)),
        Requirement("atol", atol, "finite and >= 0", finite_nonnegative(atol)),
        Requirement("rtol + atol", rtol + atol, "> 0", rtol + atol > 0),
    ]
    if dt0 is not None:
        dt0 = jnp.asarray(dt0)
        reqs.append(Requirement("dt0", dt0, "finite and > 0", finite_positive(dt0)))
    return tuple(reqs)


def check_solver_settings(rtol, atol, dt0, max_steps, throw=True) -> tuple[Requirement, ...]:
    """Raise a ValueError for concrete bad settings (values only if `throw`); return the
    requirements for the result flag."""
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"max_steps must be a Python int >= 1, got {max_steps!r}")
    reqs = solver_requirements(rtol, atol, dt0)
    if throw:
        raise_unmet("simulate", reqs)
    return reqs


def save_times(ts) -> jax.Array:
    """`ts` as a 1-D floating array of save times (s); a ValueError for any other shape."""
    ts = jnp.asarray(ts)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"ts must be a 1-D array of save times, got shape {ts.shape}")
    return ts if jnp.issubdtype(ts.dtype, jnp.floating) else ts.astype(float)


def _floor_checks(floor):
    codes = {
        "restitution": RESULTS.invalid_restitution,
        "friction": RESULTS.invalid_friction,
        "height": RESULTS.invalid_floor_height,
        "normal": RESULTS.invalid_floor_normal,
        "rolling_resistance": RESULTS.invalid_resistance,
        "spin_resistance": RESULTS.invalid_resistance,
        "radius": RESULTS.invalid_surface,
        "inclination": RESULTS.invalid_surface,
        "tip_radius": RESULTS.invalid_surface,
        "wall_radius": RESULTS.invalid_surface,
    }
    return [(jnp.all(r.ok), codes[r.field]) for r in floor.requirements()]


def input_result(scene, state0: State, ts, settings_ok=True) -> RESULTS:
    """The first bad-input problem found (traceable), or `RESULTS.successful`.

    `settings_ok`: whether the solver settings meet their requirements
    (`check_solver_settings`).
    """
    body = scene.body
    checks = [
        (jnp.all(finite_positive(body.mass)), RESULTS.invalid_mass),
        (_inertia.is_valid_inertia(body.inertia_matrix), RESULTS.invalid_inertia),
        (
            jnp.all(jnp.array([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(state0)])),
            RESULTS.nonfinite_state,
        ),
        (jnp.all(nonzero_rows(state0.quat)), RESULTS.zero_quaternion),
        (jnp.all(jnp.isfinite(ts)), RESULTS.nonfinite_times),
        (jnp.all(jnp.diff(ts) >= 0), RESULTS.decreasing_times),
        (settings_ok, RESULTS.invalid_tolerances),
    ]
    if body.shape is not None:
        checks.append((all_met(body.shape.requirements()), RESULTS.invalid_shape))
    checks.append(
        (all_met([r for f in scene.forces for r in f.requirements()]), RESULTS.invalid_force)
    )
    if scene.joint is not None:
        checks.append((all_met(scene.joint.requirements()), RESULTS.invalid_joint))
    if scene.floor is not None:
        checks.extend(_floor_checks(scene.floor))
    result = RESULTS.successful
    for ok, code in reversed(checks):
        result = RESULTS.where(jnp.all(ok), result, code)
    return result


def safe_times(ts, valid):
    """`ts` for a member whose input is valid, else all zeros: a bad member's solve then
    has zero length (no steps) instead of running into its step budget, and never trips
    diffrax's own checks on the save times, which would raise for the whole batch."""
    return jnp.where(valid, ts, jnp.zeros_like(ts))


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
    if is_concrete(state0.quat) and np.any(np.all(as_computed(state0.quat) == 0, axis=-1)):
        raise ValueError("state0.quat has zero norm")
