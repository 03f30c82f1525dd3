"""Restitution and friction fitting from a tracked trajectory, through the impact simulation.

Unlike `fit_restitution` (closed forms of a ball dropped from rest), the model here is
`jaxrb.simulate` of the given scene with a floor: any shape, throw, spin and force model,
impacts located by events, and forward-mode derivatives across the impacts
(`diffrax.ForwardMode`; they include the shift of each impact time).
"""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._floor import Floor
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
from ._parameterisation import (
    positive_to_unconstrained,
    unconstrained_to_positive,
    unconstrained_to_unit,
    unit_to_unconstrained,
)


class _ContactResiduals(eqx.Module):
    ts: jnp.ndarray
    pos_data: jnp.ndarray
    omega_data: jnp.ndarray | None
    omega_weight: jnp.ndarray
    scene: Scene
    state0: State
    fit_friction: bool = eqx.field(static=True)
    sim_tol: jnp.ndarray  # (rtol, atol) of the adaptive integrator
    sim_kwargs: tuple = eqx.field(static=True)

    def physical(self, z):
        e = unconstrained_to_unit(z[0])
        mu = unconstrained_to_positive(z[1]) if self.fit_friction else self.scene.floor.friction
        return e, mu

    def simulation(self, z):
        e, mu = self.physical(z)
        old = self.scene.floor
        floor = Floor(e, mu, old.height, old.normal, old.rolling_resistance, old.spin_resistance)
        scene = Scene(self.scene.body, self.scene.forces, floor=floor)
        return simulate(
            scene,
            self.state0,
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
        if self.omega_data is not None:
            res = jnp.concatenate(
                [res, jnp.ravel((traj.states.omega - self.omega_data) * self.omega_weight)]
            )
        return nan_unless_solved(traj, res)


def fit_contact(
    scene: Scene,
    state0: State,
    ts,
    pos,
    *,
    omega=None,
    restitution0: float = 0.5,
    friction0: float | None = None,
    omega_weight: float = 1.0,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 100,
    sim_rtol: float | None = None,
    sim_atol: float | None = None,
    max_impacts: int = 16,
) -> FitResult:
    """Fit the floor's restitution (and friction) to a tracked trajectory with bounces.

    **Arguments:**

    - `scene`: a `Scene` with a body shape and a `Floor`; its floor's restitution (and, if
      fitted, friction) are replaced by the parameters, everything else is known.
    - `state0`: the known initial `State` at `ts[0]` (world pos/vel, body omega).
    - `ts`: (T,) strictly increasing sample times (s).
    - `pos`: (T, 3) observed mass-centre positions (m, world frame, z up).
    - `omega`: optional (T, 3) observed body-frame angular velocities (rad/s, gyro data),
      weighted by `omega_weight` (m per rad/s) relative to the positions.
    - `restitution0`: initial guess in (0, 1) (parameterised as a sigmoid: every iterate
      stays in (0, 1)).
    - `friction0`: initial guess (> 0) of the Coulomb coefficient, or None to keep the
      scene's friction fixed (parameterised as exp: every iterate is positive).
    - `rtol`, `atol`, `max_steps`: Levenberg–Marquardt settings; `sim_rtol`, `sim_atol`,
      `max_impacts`: passed to `simulate`. Default `sim_rtol` and `sim_atol`: 1e-10 in
      float64, 1e-6 in float32 (below its resolution a simulation can run out of steps).

    **Returns:** a `FitResult` with values `restitution` and `friction` (the fixed value when
    not fitted, with std 0). Friction is identifiable only if the contact slides at some
    impact; otherwise the result carries an identifiability warning.

    The first call compiles the contact simulation with its forward derivatives: for a ball,
    22-27 s on a 2-core x86 CPU with `jaxrb.speed_up_compilation()` called first, 42 s with
    XLA's defaults. Later calls with data of the same shapes reuse it (0.01-0.06 s).
    """
    if scene.floor is None or scene.floor.curved or scene.body.shape is None:
        raise ValueError("fit_contact needs a scene with a Floor (a plane) and a body shape")
    if not isinstance(state0, State):
        raise TypeError(f"state0 must be a jaxrb.State, got {type(state0).__name__}")
    ts = check_times(ts)
    n = ts.size
    pos = check_series(pos, "pos", (3,), n)
    omega = None if omega is None else check_series(omega, "omega", (3,), n)
    if not 0 < restitution0 < 1:
        raise ValueError(f"restitution0 must be in (0, 1), got {restitution0}")
    z0 = [unit_to_unconstrained(restitution0)]
    internal = ("logit restitution",)
    if friction0 is not None:
        if not (np.isfinite(friction0) and friction0 > 0):
            raise ValueError(f"friction0 must be a finite positive number, got {friction0}")
        z0.append(positive_to_unconstrained(float(friction0)))
        internal += ("log friction",)
    z0 = np.asarray(z0, dtype=float)
    require_samples(pos.size + (0 if omega is None else omega.size), z0.size, "the samples")
    sim_kwargs = dict(max_impacts=max_impacts)
    fn = _ContactResiduals(
        ts=jnp.asarray(ts),
        pos_data=jnp.asarray(pos),
        omega_data=None if omega is None else jnp.asarray(omega),
        omega_weight=jnp.asarray(float(omega_weight)),
        scene=scene,
        state0=state0,
        fit_friction=friction0 is not None,
        sim_tol=check_tolerances(sim_rtol, sim_atol, default=1e-10),
        sim_kwargs=tuple(sim_kwargs.items()),
    )
    return least_squares_fit(
        fn,
        z0,
        fn.physical,
        ("restitution", "friction"),
        internal,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        # the contact simulation's derivative batched over the parameters compiles slowly;
        # a column per parameter (one or two) costs a short run each (`least_squares_fit`'s
        # `jacobian`)
        jacobian="columns",
    )
