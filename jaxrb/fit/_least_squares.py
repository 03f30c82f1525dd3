"""Shared Levenberg–Marquardt driver, Gauss–Newton uncertainty and the convergence report.

The optimiser works on an unconstrained internal vector `z` (see `_parameterisation`); the
user sees physical values `theta = to_physical(z)`.

Levenberg–Marquardt with Marquardt's scaling (`D` = the largest column norms of the
Jacobian seen so far): each trial step `h` minimises `|J h + r|^2 + mu |D h|^2`. A trial
point is accepted when its residuals and Jacobian are finite and the cost `|r|^2 / 2` falls
by at least 1e-4 of the drop the linear model predicts; otherwise it is rejected, `mu` grows
and the step is retried from the last accepted point. A model that cannot be evaluated at a
trial point (a failed simulation, an invalid parameter, an overflow) returns NaN there, so
such a step is rejected like any other, never an abort. Convergence, at an accepted point:

- `small_step`: the Gauss–Newton step is small, `|h_GN| <= atol + rtol |z|`;
- `stationary`: the residual is orthogonal to the model's tangent space: no step reduces the
  cost by more than `rtol` of itself to first order (`|P r|^2 <= rtol |r|^2`, `P` the
  projection onto the range of `J`).

At the solution, with residual Jacobian `J = dr/dz`, `n` residuals and `p` free parameters:

- `sigma^2 = |r|^2 / (n - p)` (residual variance; data assumed i.i.d. Gaussian),
- `Cov(z) = sigma^2 (J^T J)^-1`, propagated to the physical values with the delta method
  `Cov(theta) = G Cov(z) G^T`, `G = dtheta/dz` (invariant to the choice of chart),
- identifiability: the condition number of the column-scaled `J` (scaled so each column has
  unit norm, so units do not count); above `cond_warn` a `IdentifiabilityWarning` names the
  parameters in the least-determined direction.
"""

import dataclasses
import warnings
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._persistent import entry_point
from .._results import RESULTS
from .._solve import checks_without_host_callbacks

DEFAULT_COND_WARN = 1e8

_ACCEPT = 1e-4  # least ratio of actual to predicted cost reduction of an accepted step
_MU0 = 1e-3  # initial damping, relative to the squared column scales

RESOLUTION_EPS = 100
"""The least-squares `rtol` is at least this many machine epsilons of the working
precision: a relative step test much finer than the numbers cannot be met."""

FLOAT32_SIM_TOL = 1e-6
"""The fits' default `sim_rtol` and `sim_atol` in float32: their float64 defaults (1e-10,
1e-11) are below float32's resolution (1.2e-7), where a simulation with a floor can run out
of steps and a fit then stops at its initial guess."""

REASONS = {
    "small_step": "the Gauss-Newton step fell below atol + rtol |z|",
    "stationary": "no step can reduce the cost by more than rtol of itself",
    "max_steps": "the budget of max_steps trial steps was used up",
    "no_progress": "no trial step reduced the cost, down to steps at round-off",
    "invalid_start": "the model cannot be evaluated at the initial guess (non-finite "
    "residuals or Jacobian, e.g. a failed simulation)",
}
_CODES = tuple(REASONS)  # reason code i + 1 in the solver loop; 0 = still running


class IdentifiabilityWarning(UserWarning):
    """The data cannot separate some parameters (near-singular Gauss–Newton Hessian)."""


class ConvergenceWarning(UserWarning):
    """The least-squares solver stopped without meeting its tolerances."""


@dataclasses.dataclass(frozen=True)
class FitResult:
    """What a fit returns. All arrays are NumPy (the fit is finished, nothing is traced).

    **Fields:**

    - `values`: dict name -> fitted physical value (NumPy arrays, SI units).
    - `std`: dict name -> one-sigma standard error of each value (same shapes), from
      `covariance`.
    - `covariance`: (P, P) covariance of the flattened physical values, in the order of
      `names` (each value flattened row-major); rank-deficient where the parameterisation
      fixes a direction (e.g. the trace of a torque-free inertia).
    - `names`: the value names, in order.
    - `residuals`: (n,) weighted residuals at the solution (model - data).
    - `sigma2`: residual variance `|r|^2 / (n - p)`.
    - `dof`: `n - p`.
    - `jacobian`: (n, p) residual Jacobian in the internal coordinates.
    - `condition_number`: of the column-scaled Jacobian (inf when singular).
    - `converged`: the solver met its tolerances within `max_steps`.
    - `num_steps`: trial steps taken (model evaluations after the initial guess), accepted
      and rejected.
    - `message`: why the solver stopped, in words.
    - `warnings`: the warnings raised (identifiability, convergence, notes).
    - `reason`: why the solver stopped, a key of `REASONS` ("small_step", "stationary":
      converged; "max_steps", "no_progress", "invalid_start": not converged).
    - `num_rejected`: trial steps rejected (the cost did not fall enough, or the model
      could not be evaluated there).
    - `num_invalid`: of those, the ones where the model could not be evaluated (non-finite
      residuals or Jacobian: a failed simulation, an invalid parameter).
    """

    values: dict
    std: dict
    covariance: np.ndarray
    names: tuple
    residuals: np.ndarray
    sigma2: float
    dof: int
    jacobian: np.ndarray
    condition_number: float
    converged: bool
    num_steps: int
    message: str
    warnings: tuple = ()
    reason: str = ""
    num_rejected: int = 0
    num_invalid: int = 0

    @property
    def cost(self) -> float:
        """Half the sum of squared residuals."""
        return 0.5 * float(np.sum(self.residuals**2))

    def report(self) -> str:
        """A human-readable convergence and uncertainty report."""
        lines = [
            f"converged: {self.converged} after {self.num_steps} steps, "
            f"{self.num_rejected} rejected ({self.message})",
            f"residuals: n = {self.residuals.size}, dof = {self.dof}, "
            f"rms = {np.sqrt(np.mean(self.residuals**2)):.3e}, sigma^2 = {self.sigma2:.3e}",
            f"condition number (column-scaled J): {self.condition_number:.3e}",
        ]
        for name in self.names:
            v, s = np.ravel(self.values[name]), np.ravel(self.std[name])
            vals = ", ".join(f"{a:.8g} +- {b:.2g}" for a, b in zip(v, s, strict=True))
            lines.append(f"{name}: {vals}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def __str__(self):
        return self.report()


class _Loop(NamedTuple):
    z: jax.Array  # the last accepted point, its residuals, Jacobian, cost
    r: jax.Array
    jac: jax.Array
    cost: jax.Array
    scale: jax.Array  # Marquardt's column scales D
    mu: jax.Array  # damping
    nu: jax.Array  # growth factor of mu on rejection
    trial: jax.Array  # the point evaluated next
    pred: jax.Array  # the cost drop the linear model predicts for it
    num_steps: jax.Array
    num_rejected: jax.Array
    num_invalid: jax.Array
    reason: jax.Array  # 0 while running, else 1 + index into _CODES


def _code(name: str) -> int:
    return 1 + _CODES.index(name)


@entry_point
def _solve(fn, to_physical, z0, rtol, atol, max_steps, jacobian="batched"):
    """Levenberg–Marquardt from `z0` (see the module docstring); one compiled evaluation of
    the residuals and their Jacobian (forward mode, `jacobian` as in `least_squares_fit`)
    per trial point."""
    z0 = jnp.asarray(z0)
    dtype = z0.dtype
    eps = jnp.finfo(dtype).eps
    r_struct = jax.eval_shape(lambda z: fn(z, None), z0)
    n, p = r_struct.shape[0], z0.shape[0]
    # a relative tolerance finer than the working precision could never be met
    rtol = jnp.maximum(jnp.asarray(rtol, dtype), RESOLUTION_EPS * eps)
    atol = jnp.asarray(atol, dtype)
    one, zero = jnp.ones((), dtype), jnp.zeros((), dtype)

    def residuals(z):
        return jnp.asarray(fn(z, None), dtype)

    def evaluate(z):
        if jacobian == "columns":  # forward mode along one unit vector at a time, in a loop
            column = lambda direction: jax.jvp(residuals, (z,), (direction,))  # noqa: E731
            rs, columns = jax.lax.map(column, jnp.eye(p, dtype=dtype))
            return rs[0], columns.T
        jac, r = jax.jacfwd(lambda zz: (residuals(zz),) * 2, has_aux=True)(z)
        return r, jac

    def body(s: _Loop) -> _Loop:
        first = s.reason < 0
        r_t, jac_t = evaluate(s.trial)
        valid = jnp.all(jnp.isfinite(r_t)) & jnp.all(jnp.isfinite(jac_t))
        cost_t = jnp.where(valid, 0.5 * jnp.sum(jnp.where(valid, r_t, zero) ** 2), jnp.inf)
        rho = jnp.where(s.pred > 0, (s.cost - cost_t) / s.pred, -jnp.inf)
        accept = valid & (first | (rho > _ACCEPT))
        z = jnp.where(accept, s.trial, s.z)
        r = jnp.where(accept, r_t, s.r)
        jac = jnp.where(accept, jac_t, s.jac)
        cost = jnp.where(accept, cost_t, s.cost)
        col = jnp.linalg.norm(jac, axis=0)
        scale = jnp.where(accept, jnp.maximum(jnp.where(first, zero, s.scale), col), s.scale)
        scale = jnp.where(scale > 0, scale, one)
        grow = jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        mu = jnp.where(first, _MU0, jnp.where(accept, s.mu * grow, s.mu * s.nu))
        nu = jnp.where(accept, 2.0 * one, 2.0 * s.nu)

        # in the scaled variables y = D h: J_s = J D^-1 = U diag(sv) V^T
        u, sv, vt = jnp.linalg.svd(jac / scale, full_matrices=False)
        utr = u.T @ r
        keep = sv > sv[0] * eps * max(n, p)
        safe_sv = jnp.where(keep, sv, one)
        stationary = jnp.sum(jnp.where(keep, utr, zero) ** 2) <= rtol * 2.0 * cost
        h_gn = -(vt.T @ jnp.where(keep, utr / safe_sv, zero)) / scale
        small = jnp.linalg.norm(h_gn) <= atol + rtol * jnp.linalg.norm(z)
        coef = sv / (sv**2 + mu)
        y = -(vt.T @ (coef * utr))
        pred = 0.5 * jnp.sum((sv * coef * utr) ** 2) + mu * jnp.sum(y**2)
        h = y / scale

        num_steps = s.num_steps + jnp.where(first, 0, 1)
        num_rejected = s.num_rejected + jnp.where(accept | first, 0, 1)
        num_invalid = s.num_invalid + jnp.where(valid | first, 0, 1)
        stuck = ~accept & (jnp.linalg.norm(h) <= eps * (jnp.linalg.norm(z) + eps))
        reason = jnp.select(
            [
                first & ~valid,
                accept & small,
                accept & stationary,
                stuck | ~jnp.isfinite(mu),
                num_steps >= max_steps,
            ],
            [
                _code("invalid_start"),
                _code("small_step"),
                _code("stationary"),
                _code("no_progress"),
                _code("max_steps"),
            ],
            0,
        ).astype(jnp.int32)
        return _Loop(
            z=z,
            r=r,
            jac=jac,
            cost=cost,
            scale=scale,
            mu=mu,
            nu=nu,
            trial=z + h,
            pred=pred,
            num_steps=num_steps,
            num_rejected=num_rejected,
            num_invalid=num_invalid,
            reason=reason,
        )

    count = jnp.zeros((), jnp.asarray(max_steps).dtype)
    init = _Loop(
        z=z0,
        r=jnp.zeros((n,), dtype),
        jac=jnp.zeros((n, p), dtype),
        cost=jnp.asarray(jnp.inf, dtype),
        scale=jnp.ones((p,), dtype),
        mu=jnp.asarray(_MU0, dtype),
        nu=2.0 * one,
        trial=z0,
        pred=one,
        num_steps=count,
        num_rejected=count,
        num_invalid=count,
        reason=-jnp.ones((), jnp.int32),
    )
    s = jax.lax.while_loop(lambda s: s.reason <= 0, body, init)
    flat = lambda zz: jnp.concatenate([jnp.ravel(v) for v in to_physical(zz)])  # noqa: E731
    return s, to_physical(s.z), jax.jacfwd(flat)(s.z)


def least_squares_fit(
    fn: Callable,
    z0,
    to_physical: Callable,
    names: tuple[str, ...],
    internal_names: tuple[str, ...],
    *,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 200,
    cond_warn: float = DEFAULT_COND_WARN,
    notes: tuple[str, ...] = (),
    jacobian: str = "batched",
) -> FitResult:
    """Minimise `|fn(z)|^2` with Levenberg–Marquardt and report values, errors, identifiability.

    Never raises for a model that fails during the fit: a trial point where `fn` or its
    Jacobian is not finite is rejected (the damping grows and a shorter step is tried), and
    a fit that stops without meeting its tolerances says so (`converged`, `reason`,
    `message`, and a `ConvergenceWarning`).

    **Arguments:**

    - `fn`: `fn(z, None) -> (n,)` residuals; pure and jittable; NaN where the model cannot be
      evaluated (e.g. a failed simulation). If it has a method `simulation(z)` returning
      the model's `Trajectory` (as the fits through `simulate` do), a fit that cannot start
      names that simulation's result (e.g. "The maximum number of solver steps was
      reached").
      An `eqx.Module` holding the data as array fields is best: a new data set or start of
      the same shapes then reuses the compiled solver.
    - `z0`: (p,) initial internal parameters.
    - `to_physical`: `z -> tuple of arrays`, the physical values named `names`.
    - `internal_names`: a label per entry of `z` (for identifiability warnings).
    - `rtol`, `atol`: convergence tolerances (module docstring): the Gauss–Newton step
      `|h| <= atol + rtol |z|`, or the relative first-order cost reduction `<= rtol`. An
      `rtol` below `RESOLUTION_EPS` machine epsilons of the working precision (float32,
      JAX's default: 1.2e-5; float64: 2.2e-14) is raised to that: a step test much finer
      than the numbers cannot pass, and the fit would stop unconverged at a solution it has
      found (in float32, an inertia fit's steps stalled between 1e-6 and 1e-5 of |z|).
    - `max_steps`: budget of trial steps (each evaluates `fn` and its Jacobian once).
    - `cond_warn`: condition-number threshold of the identifiability warning.
    - `notes`: facts to attach to `FitResult.warnings` without emitting them (e.g. that the
      scale was fixed by the caller's choice).
    - `jacobian`: how forward mode gives the residuals' Jacobian. `"batched"` (default):
      `jax.jacfwd`, batched over the p parameters, one evaluation of the residuals per
      trial point. `"columns"`: `jax.jvp` along one parameter at a time in a loop, the
      residuals evaluated p times; for a simulation with a floor and few parameters it
      traces and compiles in about 3/4 of the time (`fit_contact`: first call 22-27 s
      against 30-37 s), while a fit of many parameters over a long simulation runs slower
      (`fit_inertia`, 11 parameters over 200 s: 4.9 against 2.2 s per fit); docs/contact.md,
      "Derivatives through contact".

    **Returns:** a `FitResult`.
    """
    z0 = jnp.asarray(z0)
    for name, tol in (("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(tol) and tol >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {tol}")
    if int(max_steps) != max_steps or max_steps < 0:
        raise ValueError(f"max_steps must be an integer >= 0, got {max_steps}")
    if jacobian not in ("batched", "columns"):
        raise ValueError(f"jacobian must be 'batched' or 'columns', got {jacobian!r}")
    # compiled (traced, differentiated and lowered) inside the scope: the derivative of each
    # event time carries a checked linear solve, whose host callback would keep the
    # program out of JAX's persistent cache
    with checks_without_host_callbacks():
        state, values_flat, grad_phys = _solve(
            fn,
            to_physical,
            z0,
            jnp.asarray(rtol),
            jnp.asarray(atol),
            jnp.asarray(int(max_steps)),
            jacobian,
        )
    r, jac, grad_phys = np.asarray(state.r), np.asarray(state.jac), np.asarray(grad_phys)
    values_flat = [np.asarray(v) for v in values_flat]
    reason = _CODES[int(state.reason) - 1]
    message = REASONS[reason]
    simulation = getattr(fn, "simulation", None)
    if reason == "invalid_start" and simulation is not None:
        cause = failure_message(simulation(z0))
        if cause:
            message = f"{message}; the simulation at the initial guess: {cause}"
    converged = reason in ("small_step", "stationary")
    if reason == "invalid_start":  # nothing was accepted: no residuals to show
        r, jac = np.full_like(r, np.nan), np.full_like(jac, np.nan)
    n, p = jac.shape
    dof = n - p

    found = list(notes)
    if not converged:
        found.append(f"least squares did not converge: {message}")
        warnings.warn(found[-1], ConvergenceWarning, stacklevel=3)

    # finiteness first: SVD cannot take NaN (only an invalid start leaves them)
    finite = bool(np.all(np.isfinite(r)) and np.all(np.isfinite(jac)))
    if finite:
        sigma2 = float(np.sum(r**2) / dof)
        col = np.linalg.norm(jac, axis=0)
        col = np.where(col > 0, col, 1.0)
        u, s, vt = np.linalg.svd(jac, full_matrices=False)
        _, s_scaled, vt_scaled = np.linalg.svd(jac / col, full_matrices=False)
        cond = float(s_scaled[0] / s_scaled[-1]) if s_scaled[-1] > 0 else float("inf")
        # Cov(z) = sigma^2 V diag(1/s^2) V^T, singular directions dropped (pseudo-inverse).
        tol = s[0] * max(n, p) * np.finfo(float).eps if s.size else 0.0
        inv_s2 = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0) ** 2, 0.0)
        cov_z = sigma2 * (vt.T * inv_s2) @ vt
        cov = grad_phys @ cov_z @ grad_phys.T
    else:
        sigma2, cond = float("nan"), float("nan")
        cov = np.full((grad_phys.shape[0],) * 2, np.nan)
    if finite and cond > cond_warn:
        weak = vt_scaled[-1]
        order = np.argsort(-np.abs(weak))
        involved = [internal_names[i] for i in order if abs(weak[i]) > 0.2 * abs(weak[order[0]])]
        found.append(
            f"poorly identifiable: condition number {cond:.2e} of the scaled Jacobian exceeds "
            f"{cond_warn:.0e}; the data barely constrain the combination of {', '.join(involved)}"
        )
        warnings.warn(found[-1], IdentifiabilityWarning, stacklevel=3)
    std_flat = np.sqrt(np.clip(np.diagonal(cov), 0.0, None))

    values, std, i = {}, {}, 0
    for name, v in zip(names, values_flat, strict=True):
        values[name] = v
        std[name] = std_flat[i : i + v.size].reshape(v.shape)
        i += v.size
    return FitResult(
        values=values,
        std=std,
        covariance=cov,
        names=tuple(names),
        residuals=r,
        sigma2=sigma2,
        dof=dof,
        jacobian=jac,
        condition_number=cond,
        converged=converged,
        num_steps=int(state.num_steps),
        message=message,
        warnings=tuple(found),
        reason=reason,
        num_rejected=int(state.num_rejected),
        num_invalid=int(state.num_invalid),
    )


def failure_message(traj) -> str | None:
    """The message of the simulation `traj`'s result code (one run, concrete), or None
    where it succeeded."""
    code = int(np.asarray(traj.result._value))
    return None if code == RESULTS.successful._value else RESULTS._index_to_message[code]


def nan_unless_solved(traj, residuals):
    """`residuals` where the simulation `traj` succeeded, NaN where it failed (the driver
    then rejects the trial point)."""
    return jnp.where(traj.result == RESULTS.successful, residuals, jnp.nan)


def check_tolerances(rtol, atol, default: float) -> jax.Array:
    """`(rtol, atol)` of a model's adaptive integrator, checked (finite, >= 0, not both 0), as
    one array: new values reuse the compiled fit. None stands for `default` in float64 and
    for `FLOAT32_SIM_TOL` when JAX computes in float32 (its default, without x64)."""
    unset = FLOAT32_SIM_TOL if jnp.result_type(float) == jnp.float32 else default
    rtol = unset if rtol is None else rtol
    atol = unset if atol is None else atol
    for name, tol in (("sim_rtol", rtol), ("sim_atol", atol)):
        if not (np.isfinite(tol) and tol >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {tol}")
    if rtol == 0 and atol == 0:
        raise ValueError("sim_rtol and sim_atol must not both be 0")
    return jnp.asarray([rtol, atol], dtype=float)


def check_series(x, name: str, trailing: tuple[int, ...], n_times: int | None = None) -> np.ndarray:
    """Concrete float64 NumPy array with trailing shape `trailing`, finite, with `n_times` rows."""
    arr = np.asarray(x, dtype=float)
    want = "(T, " + ", ".join(str(t) for t in trailing) + ")" if trailing else "(T,)"
    if arr.ndim != 1 + len(trailing) or tuple(arr.shape[1:]) != trailing:
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    if n_times is not None and arr.shape[0] != n_times:
        raise ValueError(
            f"{name} has {arr.shape[0]} samples but ts has {n_times}: the time series must match"
        )
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr.reshape(arr.shape[0], -1)))[0, 0]
        raise ValueError(f"{name} contains NaN or inf (first at sample {bad})")
    return arr


def check_times(ts, name: str = "ts") -> np.ndarray:
    """Concrete, finite, strictly increasing 1-D sample times."""
    ts = check_series(ts, name, ())
    if np.any(np.diff(ts) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return ts


def require_samples(n_residuals: int, n_params: int, what: str) -> None:
    """Raise if the data cannot over-determine the parameters."""
    if n_residuals <= n_params:
        raise ValueError(
            f"too few samples: {what} gives {n_residuals} residuals for {n_params} free "
            "parameters; need more residuals than parameters (to fit and to estimate noise)"
        )
