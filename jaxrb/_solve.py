"""One diffrax solve from ts[0] to ts[-1] saving at ts, and the default solver settings of
`simulate` (one body or a batch as one solve) and `simulate_batch`."""

import contextlib

import diffrax as dfx
import equinox as eqx
import numpy as np

from ._checks import is_concrete

DEFAULT_RTOL = 1e-8
DEFAULT_ATOL = 1e-8
DEFAULT_MAX_STEPS = 100_000

# Below these rtols the 8th-order Dopri8 reaches a given error at less cost than the
# 5th-order Tsit5, measured on benchmark B1 (the torque-free body; benchmarks/README.md): for
# one body (also per member under jax.vmap), and for a batch integrated as one solve, whose
# fixed cost per step is shared by the batch, so that fewer, costlier steps pay sooner.
HIGH_ORDER_RTOL = 1e-9
HIGH_ORDER_RTOL_BATCH = 1e-5


def default_solver(rtol, batch: bool = False) -> dfx.AbstractSolver:
    """`diffrax.Dopri8()` for rtol below `HIGH_ORDER_RTOL` (`HIGH_ORDER_RTOL_BATCH` for a
    batch as one solve), else `diffrax.Tsit5()`. A traced rtol (its value unknown when the
    solver is chosen) gets the choice for the default rtol, `DEFAULT_RTOL`."""
    value = float(np.max(np.asarray(rtol))) if is_concrete(rtol) else DEFAULT_RTOL
    if value < (HIGH_ORDER_RTOL_BATCH if batch else HIGH_ORDER_RTOL):
        return dfx.Dopri8()
    return dfx.Tsit5()


@contextlib.contextmanager
def checks_without_host_callbacks():
    """While tracing a `diffrax.diffeqsolve` of jaxrb's: its checks of the save times (sorted,
    between t0 and t1) and of dt0, which jaxrb makes itself before the solve (and flags per
    trajectory), return NaN where they fail instead of raising through a host callback; so
    does the check of the linear solve in the derivative of an event time (singular only
    where the event condition grazes zero, where the event time has no derivative). JAX's
    persistent compilation cache keeps no program with a host callback: without this, no
    compiled simulation could be cached. Only equinox's default `EQX_ON_ERROR=raise` is
    changed; any other setting (e.g. `breakpoint` for debugging) is left as it is. equinox
    keeps each traced check for reuse (per array shapes), and a checked linear solve is
    traced again whenever a program is lowered: the kept checks are dropped on entering and
    on leaving, so that neither form leaks into programs traced or lowered on the other side
    of the scope."""
    if equinox_checks_mode() != "raise":
        yield
        return
    set_equinox_checks("nan")
    try:
        yield
    finally:
        set_equinox_checks("raise")


def equinox_checks_mode() -> str | None:
    """How equinox's run-time checks are traced now (its `EQX_ON_ERROR`: "raise", "nan",
    "breakpoint" or "off"); None for an equinox without that setting."""
    return getattr(getattr(eqx, "_errors", None), "EQX_ON_ERROR", None)


def set_equinox_checks(mode: str) -> None:
    """Trace equinox's run-time checks in `mode` from now on, and drop the traces equinox
    keeps of its check (per array shapes; cheap to trace again), so that none traced in the
    other mode is reused."""
    errors = eqx._errors
    errors.EQX_ON_ERROR = mode
    cached = getattr(getattr(errors, "branched_error_if_impl_jit", None), "_cached", None)
    if hasattr(cached, "clear_cache"):
        cached.clear_cache()


def save_at(ts) -> dfx.SaveAt:
    """Save at `ts` (shape (T,)): the end points are the solve's own t0 and t1 (no
    interpolation there), the times between them are interpolated."""
    if ts.shape[0] == 1:
        return dfx.SaveAt(t0=True)
    if ts.shape[0] == 2:
        return dfx.SaveAt(t0=True, t1=True)
    return dfx.SaveAt(t0=True, ts=ts[1:-1], t1=True)


def solve(rhs, y0, ts, settings):
    """Integrate dy/dt = rhs(t, y) from ts[0] to ts[-1] (any pytree y) with the
    `SolverSettings` `settings`.

    **Returns:** `(ys, num_accepted_steps, result)`: `ys` like y0 with a leading time axis
    (T, ...) holding y at `ts`; the diffrax result code. Never raises (throw=False): the
    caller decides.
    """
    with checks_without_host_callbacks():
        sol = dfx.diffeqsolve(
            dfx.ODETerm(lambda t, y, args: rhs(t, y)),
            t0=ts[0],
            t1=ts[-1],
            y0=y0,
            saveat=save_at(ts),
            throw=False,
            **settings.solve_kwargs(),
        )
    return sol.ys, sol.stats["num_accepted_steps"], sol.result
