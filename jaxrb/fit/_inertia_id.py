"""Inertia identification from observed body angular velocity and/or attitude time series."""

import warnings

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .. import inertia as _inertia
from .._body import RigidBody
from .._quaternion import quat_conjugate, quat_multiply, quat_normalize
from .._scene import Scene
from .._simulate import simulate
from .._state import State
from ._least_squares import (
    FitResult,
    IdentifiabilityWarning,
    check_series,
    check_times,
    check_tolerances,
    least_squares_fit,
    nan_unless_solved,
    require_samples,
)
from ._parameterisation import inertia_to_log_cholesky, log_cholesky_to_inertia, perturb_quat

_LC_NAMES = ("log L00", "log L11", "log L22", "L10", "L20", "L21")


def _attitude_error(q_model, q_data):
    """Small-angle rotation vector (rad, body frame) taking `q_data` to `q_model`; sign-safe."""
    dq = quat_multiply(quat_conjugate(q_data), q_model)
    sign = jnp.where(dq[..., :1] < 0, -1.0, 1.0)
    return 2.0 * sign * dq[..., 1:]


class _InertiaResiduals(eqx.Module):
    ts: jnp.ndarray
    omega_data: jnp.ndarray | None
    quat_data: jnp.ndarray | None
    omega_weight: jnp.ndarray
    quat_weight: jnp.ndarray
    mass: jnp.ndarray
    forces: tuple
    quat_ref: jnp.ndarray
    omega_ref: jnp.ndarray
    d0: jnp.ndarray
    trace: jnp.ndarray
    fix_scale: bool = eqx.field(static=True)
    fit_omega0: bool = eqx.field(static=True)
    fit_quat0: bool = eqx.field(static=True)
    sim_tol: jnp.ndarray  # (rtol, atol) of the adaptive integrator
    sim_kwargs: tuple = eqx.field(static=True)

    def split(self, z):
        if self.fix_scale:
            theta, i = jnp.concatenate([self.d0[None], z[:5]]), 5
        else:
            theta, i = z[:6], 6
        inertia = log_cholesky_to_inertia(theta)
        if self.fix_scale:
            inertia = inertia * (self.trace / jnp.trace(inertia))
        omega0 = self.omega_ref
        if self.fit_omega0:
            omega0, i = omega0 + z[i : i + 3], i + 3
        quat0 = self.quat_ref
        if self.fit_quat0:
            quat0, i = perturb_quat(self.quat_ref, z[i : i + 3]), i + 3
        return inertia, omega0, quat0

    def physical(self, z):
        return self.split(z)

    def simulation(self, z):
        inertia, omega0, quat0 = self.split(z)
        scene = Scene(RigidBody(self.mass, inertia), forces=self.forces)
        zero = jnp.zeros(3, dtype=z.dtype)
        state0 = State(zero, quat0, zero, omega0)
        return simulate(
            scene,
            state0,
            self.ts,
            adjoint=dfx.ForwardMode(),
            rtol=self.sim_tol[0],
            atol=self.sim_tol[1],
            throw=False,
            **dict(self.sim_kwargs),
        )

    def __call__(self, z, args):
        traj = self.simulation(z)
        parts = []
        if self.omega_data is not None:
            parts.append(jnp.ravel((traj.states.omega - self.omega_data) * self.omega_weight))
        if self.quat_data is not None:
            err = _attitude_error(traj.states.quat, self.quat_data)
            parts.append(jnp.ravel(err * self.quat_weight))
        return nan_unless_solved(traj, jnp.concatenate(parts))


def fit_inertia(
    ts,
    *,
    inertia0,
    omega=None,
    quat=None,
    forces=(),
    mass=1.0,
    omega0=None,
    quat0=None,
    fit_initial: bool = True,
    fix_scale: bool | None = None,
    omega_noise: float = 1.0,
    quat_noise: float = 1.0,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 100,
    sim_rtol: float | None = None,
    sim_atol: float | None = None,
    sim_max_steps: int = 100_000,
    solver=None,
    stepsize_controller=None,
    dt0=None,
) -> FitResult:
    """Identify the full inertia tensor (products included) from a tumbling body's motion.

    The model is `jaxrb.simulate` of a free body (no gravity unless given in `forces`); the
    tensor is parameterised by the log-Cholesky factor of its pseudo-inertia, so every
    iterate is symmetric positive definite and satisfies the triangle inequality.

    **Arguments:**

    - `ts`: (T,) strictly increasing sample times (s).
    - `inertia0`: initial guess, (3, 3) tensor or (3,) principal moments (kg m^2, body axes,
      about the mass centre); must be physically valid.
    - `omega`: (T, 3) observed body-frame angular velocity (rad/s), or None.
    - `quat`: (T, 4) observed attitude, scalar-first unit quaternions body -> world, or None.
      At least one of `omega`, `quat` is needed.
    - `forces`: known applied forces/torques (e.g. `jaxrb.Wrench(torque=...)`). With a
      non-zero known torque the absolute scale of the tensor is identifiable.
    - `mass`: body mass (kg); only matters for forces that depend on it.
    - `omega0`, `quat0`: initial state (guesses when `fit_initial`); default: the first sample
      of `omega` / `quat` (identity attitude when `quat` is not observed).
    - `fit_initial`: also fit the initial angular velocity (and initial attitude when `quat`
      is observed) as nuisance parameters; needed for unbiased estimates from noisy data.
    - `fix_scale`: torque-free motion determines the tensor only up to a positive scale. If
      True the trace is held at `trace(inertia0)` (the result is "the tensor up to scale",
      normalised to the guess's trace). Default: True when `forces` is empty. With False on
      torque-free data, the scale direction is reported as unidentifiable.
    - `omega_noise`, `quat_noise`: relative noise levels (rad/s, rad) weighting the two
      residual kinds; the overall sigma^2 is estimated from the residuals.
    - `rtol`, `atol`, `max_steps`: Levenberg–Marquardt settings.
    - `sim_rtol`, `sim_atol`, `sim_max_steps`, `solver`, `stepsize_controller`, `dt0`: passed
      to `simulate` (e.g. a fixed-step solver for speed). Default `sim_rtol` and
      `sim_atol`: 1e-11 in float64, 1e-6 in float32.

    **Returns:** a `FitResult` with values `inertia` (3, 3), `omega0` (3,), `quat0` (4,).
    Residuals: omega (rad/s) then the attitude error rotation vector (rad), each divided by
    its noise level.
    """
    ts = check_times(ts)
    n = ts.size
    if omega is None and quat is None:
        raise ValueError("fit_inertia needs observed `omega` and/or `quat`")
    omega = None if omega is None else check_series(omega, "omega", (3,), n)
    if quat is not None:
        quat = check_series(quat, "quat", (4,), n)
        if np.any(np.abs(np.linalg.norm(quat, axis=-1) - 1) > 1e-6):
            raise ValueError("quat must hold unit quaternions (|q| = 1 within 1e-6)")
    inertia0 = np.asarray(inertia0, dtype=float)
    if inertia0.shape == (3,):
        inertia0 = np.diag(inertia0)
    if inertia0.shape != (3, 3):
        raise ValueError(f"inertia0 must have shape (3, 3) or (3,), got {inertia0.shape}")
    _inertia.check_inertia(jnp.asarray(inertia0), name="inertia0")
    if not isinstance(forces, tuple):
        raise TypeError("forces must be a tuple of jaxrb forces")
    if fix_scale is None:
        fix_scale = len(forces) == 0

    if omega0 is None:
        if omega is None:
            raise ValueError(
                "give `omega0` (an initial angular velocity) when omega is not observed"
            )
        omega0 = omega[0]
    if quat0 is None:
        quat0 = quat[0] if quat is not None else np.array([1.0, 0.0, 0.0, 0.0])
    omega0 = check_series(np.asarray(omega0, dtype=float)[None], "omega0", (3,))[0]
    quat0 = np.asarray(
        quat_normalize(jnp.asarray(check_series(np.asarray(quat0)[None], "quat0", (4,))[0]))
    )
    fit_quat0 = fit_initial and quat is not None

    theta0 = np.asarray(inertia_to_log_cholesky(jnp.asarray(inertia0)))
    z0 = [theta0[1:] if fix_scale else theta0]
    internal = list(_LC_NAMES[1:] if fix_scale else _LC_NAMES)
    if fit_initial:
        z0.append(np.zeros(3))
        internal += ["omega0_x", "omega0_y", "omega0_z"]
    if fit_quat0:
        z0.append(np.zeros(3))
        internal += ["quat0_rx", "quat0_ry", "quat0_rz"]
    z0 = np.concatenate(z0)
    n_res = (0 if omega is None else omega.size) + (0 if quat is None else 3 * n)
    require_samples(n_res, z0.size, "the observed series")

    fn = _InertiaResiduals(
        ts=jnp.asarray(ts),
        omega_data=None if omega is None else jnp.asarray(omega),
        quat_data=None if quat is None else jnp.asarray(quat),
        omega_weight=jnp.asarray(1.0 / omega_noise),
        quat_weight=jnp.asarray(1.0 / quat_noise),
        mass=jnp.asarray(mass, dtype=float),
        forces=forces,
        quat_ref=jnp.asarray(quat0),
        omega_ref=jnp.asarray(omega0),
        d0=jnp.asarray(theta0[0]),
        trace=jnp.asarray(np.trace(inertia0)),
        fix_scale=bool(fix_scale),
        fit_omega0=bool(fit_initial),
        fit_quat0=bool(fit_quat0),
        sim_tol=check_tolerances(sim_rtol, sim_atol, default=1e-11),
        sim_kwargs=tuple(
            dict(
                max_steps=sim_max_steps,
                solver=solver,
                stepsize_controller=stepsize_controller,
                dt0=dt0,
            ).items()
        ),
    )
    notes = ()
    if not fix_scale and not forces:
        warnings.warn(
            "torque-free motion cannot determine the inertia tensor's scale (J and c J move "
            "alike); use fix_scale=True or give a known torque",
            IdentifiabilityWarning,
            stacklevel=2,
        )
    if fix_scale:
        notes = (
            "the absolute scale of the inertia tensor is not identifiable without a known "
            f"torque; it is fixed by trace(inertia) = trace(inertia0) = {np.trace(inertia0):.6g}",
        )
    return least_squares_fit(
        fn,
        z0,
        fn.physical,
        ("inertia", "omega0", "quat0"),
        tuple(internal),
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        notes=notes,
    )
