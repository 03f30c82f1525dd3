"""`SolverSettings`: the diffrax settings of one simulation, resolved from `simulate`'s
keyword arguments once and passed whole to the compiled cores (the smooth solve, the batch
as one solve, the contact engine and its lanes)."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from ._checks import all_met
from ._inputs import check_solver_settings


class SolverSettings(eqx.Module):
    """How a simulation is integrated.

    - `solver`: the diffrax solver.
    - `controller`: the step-size controller (a `PIDController` with array tolerances
      unless the user passed one).
    - `adjoint`: how the solve is differentiated (reverse mode by default).
    - `dt0`: the initial step (s, in the save times' dtype), or None: the controller's choice.
    - `max_steps`: the solver's step budget per solve (static: it sizes the saved steps).
    - `progress_meter`: a diffrax progress meter.
    - `ok`: whether the settings met their checks (a traced flag; a run with bad settings
      takes no step and is flagged `invalid_tolerances`).
    """

    solver: dfx.AbstractSolver
    controller: dfx.AbstractStepSizeController
    adjoint: dfx.AbstractAdjoint
    dt0: jax.Array | None
    max_steps: int = eqx.field(static=True)
    progress_meter: dfx.AbstractProgressMeter
    ok: jax.Array

    def solve_kwargs(self) -> dict:
        """The keyword arguments of `diffrax.diffeqsolve` these settings fix."""
        return dict(
            solver=self.solver,
            stepsize_controller=self.controller,
            adjoint=self.adjoint,
            dt0=self.dt0,
            max_steps=self.max_steps,
            progress_meter=self.progress_meter,
        )


def solver_settings(
    *,
    solver,
    rtol,
    atol,
    dt0,
    max_steps,
    stepsize_controller,
    adjoint,
    progress_meter,
    throw,
    dtype,
) -> SolverSettings:
    """`SolverSettings` from `simulate`'s keyword arguments; `solver` must already be chosen.

    Raises a ValueError for a `max_steps` that is not a Python int >= 1, and, if `throw`,
    for concrete bad tolerances or dt0 (naming the setting). A given `stepsize_controller`
    replaces rtol and atol, which are then neither checked nor used. The default controller
    is a `PIDController(rtol, atol)` whose tolerances are arrays: new values need no
    recompilation. `dtype`: the save times' (dt0 is cast to it).
    """
    own = stepsize_controller is None
    reqs = check_solver_settings(rtol if own else 1.0, atol if own else 1.0, dt0, max_steps, throw)
    if own:
        stepsize_controller = dfx.PIDController(rtol=jnp.asarray(rtol), atol=jnp.asarray(atol))
    return SolverSettings(
        solver=solver,
        controller=stepsize_controller,
        adjoint=dfx.RecursiveCheckpointAdjoint() if adjoint is None else adjoint,
        dt0=None if dt0 is None else jnp.asarray(dt0, dtype),
        max_steps=max_steps,
        progress_meter=dfx.NoProgressMeter() if progress_meter is None else progress_meter,
        ok=jnp.asarray(all_met(reqs)),
    )
