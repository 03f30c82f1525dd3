"""Shared Levenberg–Marquardt driver, Gauss–Newton uncertainty and the convergence report.

The optimiser works on an unconstrained internal vector `z` (see `_parameterisation`); the
user sees physical values `theta = to_physical(z)`. At the solution, with residual Jacobian
`J = dr/dz`, `n` residuals and `p` free parameters:

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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

DEFAULT_COND_WARN = 1e8


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
    - `num_steps`: solver iterations.
    - `message`: the solver's result message.
    - `warnings`: the warnings raised (identifiability, convergence, notes).
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

    @property
    def cost(self) -> float:
        """Half the sum of squared residuals."""
        return 0.5 * float(np.sum(self.residuals**2))

    def report(self) -> str:
        """A human-readable convergence and uncertainty report."""
        lines = [
            f"converged: {self.converged} after {self.num_steps} steps ({self.message})",
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


@eqx.filter_jit
def _solve(fn, z0, rtol, atol, max_steps):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol = optx.least_squares(fn, solver, z0, None, max_steps=max_steps, throw=False)
    return sol.value, sol.result, sol.stats["num_steps"]


@eqx.filter_jit
def _linearise(fn, to_physical, z):
    r = fn(z, None)
    jac = jax.jacfwd(fn)(z, None)
    flat = lambda zz: jnp.concatenate([jnp.ravel(v) for v in to_physical(zz)])  # noqa: E731
    return r, jac, to_physical(z), jax.jacfwd(flat)(z)


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
) -> FitResult:
    """Minimise `|fn(z)|^2` with Levenberg–Marquardt and report values, errors, identifiability.

    **Arguments:**

    - `fn`: `fn(z, None) -> (n,)` residuals; pure and jittable. An `eqx.Module` holding the
      data as array fields is best: a new data set of the same shapes then reuses the
      compiled solver.
    - `z0`: (p,) initial internal parameters.
    - `to_physical`: `z -> tuple of arrays`, the physical values named `names`.
    - `internal_names`: a label per entry of `z` (for identifiability warnings).
    - `rtol`, `atol`: optimistix Levenberg–Marquardt tolerances.
    - `max_steps`: iteration budget.
    - `cond_warn`: condition-number threshold of the identifiability warning.
    - `notes`: facts to attach to `FitResult.warnings` without emitting them (e.g. that the
      scale was fixed by the caller's choice).

    **Returns:** a `FitResult`.
    """
    z0 = jnp.asarray(z0)
    z, result, num_steps = _solve(fn, z0, rtol, atol, max_steps)
    r, jac, values_flat, grad_phys = _linearise(fn, to_physical, z)
    r, jac, grad_phys = np.asarray(r), np.asarray(jac), np.asarray(grad_phys)
    values_flat = [np.asarray(v) for v in values_flat]
    n, p = jac.shape
    dof = n - p
    sigma2 = float(np.sum(r**2) / dof)

    found = list(notes)
    converged = bool(result == optx.RESULTS.successful)
    message = optx.RESULTS[result] if not converged else "successful"
    if not converged:
        found.append(f"least squares did not converge: {message}")
        warnings.warn(found[-1], ConvergenceWarning, stacklevel=3)

    col = np.linalg.norm(jac, axis=0)
    col = np.where(col > 0, col, 1.0)
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    s_scaled = np.linalg.svd(jac / col, compute_uv=False)
    cond = float(s_scaled[0] / s_scaled[-1]) if s_scaled[-1] > 0 else float("inf")
    if not np.all(np.isfinite(jac)):
        raise FloatingPointError("the residual Jacobian at the solution is not finite")
    if cond > cond_warn:
        _, _, vt_scaled = np.linalg.svd(jac / col, full_matrices=False)
        weak = vt_scaled[-1]
        order = np.argsort(-np.abs(weak))
        involved = [internal_names[i] for i in order if abs(weak[i]) > 0.2 * abs(weak[order[0]])]
        found.append(
            f"poorly identifiable: condition number {cond:.2e} of the scaled Jacobian exceeds "
            f"{cond_warn:.0e}; the data barely constrain the combination of {', '.join(involved)}"
        )
        warnings.warn(found[-1], IdentifiabilityWarning, stacklevel=3)

    # Cov(z) = sigma^2 V diag(1/s^2) V^T, singular directions dropped (pseudo-inverse).
    tol = s[0] * max(n, p) * np.finfo(float).eps if s.size else 0.0
    inv_s2 = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0) ** 2, 0.0)
    cov_z = sigma2 * (vt.T * inv_s2) @ vt
    cov = grad_phys @ cov_z @ grad_phys.T
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
        num_steps=int(num_steps),
        message=message,
        warnings=tuple(found),
    )


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
