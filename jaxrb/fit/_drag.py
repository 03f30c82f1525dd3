"""Drag-coefficient fitting from a tracked flight trajectory (mass-centre positions)."""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._body import RigidBody
from .._forces import Gravity, LinearDrag, QuadraticDrag
from .._scene import Scene
from .._simulate import simulate
from .._state import State
from ._least_squares import (
    FitResult,
    check_series,
    check_times,
    check_tolerances,
    least_squares_fit,
    nan_unless_solved,
    require_samples,
)
from ._parameterisation import unconstrained_to_positive

_MODELS = {"quadratic": QuadraticDrag, "linear": LinearDrag}


class _DragResiduals(eqx.Module):
    ts: jnp.ndarray
    pos_data: jnp.ndarray
    vel_data: jnp.ndarray | None
    vel_weight: jnp.ndarray
    mass: jnp.ndarray
    g: jnp.ndarray
    pos_ref: jnp.ndarray
    vel_ref: jnp.ndarray
    model: str = eqx.field(static=True)
    fit_initial: bool = eqx.field(static=True)
    sim_tol: jnp.ndarray  # (rtol, atol) of the adaptive integrator
    sim_kwargs: tuple = eqx.field(static=True)

    def physical(self, z):
        coefficient = unconstrained_to_positive(z[0])
        if self.fit_initial:
            return coefficient, self.pos_ref + z[1:4], self.vel_ref + z[4:7]
        return coefficient, self.pos_ref, self.vel_ref

    def simulation(self, z):
        coefficient, pos0, vel0 = self.physical(z)
        body = RigidBody(self.mass, jnp.ones(3, dtype=z.dtype))
        scene = Scene(body, forces=(Gravity(self.g), _MODELS[self.model](coefficient)))
        quat = jnp.array([1.0, 0.0, 0.0, 0.0], dtype=z.dtype)
        state0 = State(pos0, quat, vel0, jnp.zeros(3, dtype=z.dtype))
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
        res = jnp.ravel(traj.states.pos - self.pos_data)
        if self.vel_data is not None:
            res = jnp.concatenate(
                [res, jnp.ravel((traj.states.vel - self.vel_data) * self.vel_weight)]
            )
        return nan_unless_solved(traj, res)


def fit_drag(
    ts,
    pos,
    *,
    mass,
    drag0,
    model: str = "quadratic",
    vel=None,
    pos0=None,
    vel0=None,
    fit_initial: bool = True,
    g=(0.0, 0.0, -9.81),
    vel_noise_ratio: float = 1.0,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 100,
    sim_rtol: float | None = None,
    sim_atol: float | None = None,
    solver=None,
    stepsize_controller=None,
    dt0=None,
) -> FitResult:
    """Fit a drag coefficient to a tracked flight (mass centre under gravity and drag).

    The model is `jaxrb.simulate` with `Gravity(g)` and `QuadraticDrag(k)` (F = -k |v| v,
    k = rho C_D A / 2 in kg/m) or `LinearDrag(c)` (F = -c v, N s/m); the coefficient is
    parameterised as exp(z) so every iterate is positive. Drag enters the motion only
    through coefficient / mass, so `mass` must be known.

    **Arguments:**

    - `ts`: (T,) strictly increasing sample times (s).
    - `pos`: (T, 3) observed mass-centre positions (m, world frame, z up).
    - `mass`: body mass (kg).
    - `drag0`: initial guess of the coefficient (> 0).
    - `model`: "quadratic" or "linear".
    - `vel`: optional (T, 3) observed velocities (m/s), weighted by `1 / vel_noise_ratio`
      relative to positions.
    - `pos0`, `vel0`: initial state (guesses when `fit_initial`); default `pos[0]` and the
      finite difference of the first two samples (or `vel[0]`).
    - `fit_initial`: also fit the initial position and velocity (nuisance parameters).
    - `g`: gravity (m/s^2, world frame).
    - `rtol`, `atol`, `max_steps`: Levenberg–Marquardt settings; `sim_rtol`, `sim_atol`,
      `solver`, `stepsize_controller`, `dt0`: passed to `simulate`. Default `sim_rtol` and
      `sim_atol`: 1e-11 in float64, 1e-6 in float32.

    **Returns:** a `FitResult` with values `drag` (scalar), `pos0` (3,), `vel0` (3,).
    """
    if model not in _MODELS:
        raise ValueError(f"model must be 'quadratic' or 'linear', got {model!r}")
    ts = check_times(ts)
    n = ts.size
    pos = check_series(pos, "pos", (3,), n)
    vel = None if vel is None else check_series(vel, "vel", (3,), n)
    drag0 = float(drag0)
    if not (np.isfinite(drag0) and drag0 > 0):
        raise ValueError(f"drag0 must be a finite positive number, got {drag0}")
    if not (np.isfinite(float(mass)) and float(mass) > 0):
        raise ValueError(f"mass must be finite and > 0, got {mass}")
    if pos0 is None:
        pos0 = pos[0]
    if vel0 is None:
        vel0 = vel[0] if vel is not None else (pos[1] - pos[0]) / (ts[1] - ts[0])
    pos0 = check_series(np.asarray(pos0, dtype=float)[None], "pos0", (3,))[0]
    vel0 = check_series(np.asarray(vel0, dtype=float)[None], "vel0", (3,))[0]
    z0 = np.concatenate([[np.log(drag0)], np.zeros(6 if fit_initial else 0)])
    internal = ("log drag",) + (
        ("pos0_x", "pos0_y", "pos0_z", "vel0_x", "vel0_y", "vel0_z") if fit_initial else ()
    )
    require_samples(pos.size + (0 if vel is None else vel.size), z0.size, "the tracked positions")
    sim_kwargs = dict(
        solver=solver,
        stepsize_controller=stepsize_controller,
        dt0=dt0,
    )
    fn = _DragResiduals(
        ts=jnp.asarray(ts),
        pos_data=jnp.asarray(pos),
        vel_data=None if vel is None else jnp.asarray(vel),
        vel_weight=jnp.asarray(1.0 / vel_noise_ratio),
        mass=jnp.asarray(float(mass)),
        g=jnp.asarray(g, dtype=float),
        pos_ref=jnp.asarray(pos0),
        vel_ref=jnp.asarray(vel0),
        model=model,
        fit_initial=bool(fit_initial),
        sim_tol=check_tolerances(sim_rtol, sim_atol, default=1e-11),
        sim_kwargs=tuple(sim_kwargs.items()),
    )
    return least_squares_fit(
        fn,
        z0,
        fn.physical,
        ("drag", "pos0", "vel0"),
        internal,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
    )
