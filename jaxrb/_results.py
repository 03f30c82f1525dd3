"""Result codes of a simulation: diffrax's, plus bad-input codes (one per batch member)."""

import diffrax as dfx
import equinox as eqx

from ._solve import equinox_checks_mode


class RESULTS(dfx.RESULTS):  # pyright: ignore
    """`simulate`'s outcome. `RESULTS.successful` or the first problem found.

    Extends `diffrax.RESULTS` (max_steps_reached, dt_min_reached, ...) with input checks that
    also work on traced values under jit and vmap.
    """

    invalid_mass = "the body's mass must be finite and > 0."
    invalid_inertia = (
        "the inertia tensor must be finite, symmetric, positive definite and satisfy the "
        "triangle inequality."
    )
    nonfinite_state = "the initial state contains NaN or inf."
    zero_quaternion = "the initial quaternion has zero norm."
    decreasing_times = "the save times `ts` must be non-decreasing."
    nonfinite_times = "the save times `ts` must be finite."
    invalid_shape = "the body's shape dimensions must be finite and > 0."
    invalid_force = (
        "a force parameter is invalid (gravity and wrench values must be finite; drag and "
        "damping coefficients finite and >= 0)."
    )
    invalid_joint = "the joint's point must be finite and its axis a finite non-zero direction."
    invalid_floor_height = "the floor's height must be finite."
    invalid_floor_normal = "the floor's normal must be a finite non-zero direction."
    invalid_resistance = (
        "the floor's rolling and spin resistance must be finite and >= 0, and non-zero only "
        "for a ball (Sphere)."
    )
    invalid_surface = (
        "the curved surface's dimensions are invalid: a bowl's radius must be finite and "
        "> 0, a cone's or wheel's inclination in (0, pi/2) rad and its tip_radius >= 0, a "
        "wheel's wall_radius finite and > its tip_radius."
    )
    invalid_tolerances = (
        "the solver settings are invalid (rtol and atol must be finite and >= 0, not both 0; "
        "dt0 finite and > 0)."
    )
    invalid_restitution = "the floor's restitution must be in [0, 1]."
    invalid_friction = "the floor's friction coefficient must be finite and >= 0."
    max_impacts_reached = "the maximum number of impacts was reached before the end time."
    max_events_reached = "the maximum number of contact events was reached before the end time."
    painleve_paradox = (
        "the Painlevé paradox: a sliding contact's normal force problem has no solution "
        "(Coulomb friction too large for the body's attitude); the run stops there."
    )
    starts_below_floor = (
        "the body starts below the floor (its lowest point is under the floor plane)."
    )


def raise_if_failed(traj):
    """`throw=True`: `traj` unchanged, or an error naming its result code where that is not
    `successful` (at run time where the code is traced; for a batch, one member's message).
    Raises whatever equinox's `EQX_ON_ERROR` says (`nan` makes equinox's own checks quiet,
    and `throw=True` must not be), except that `breakpoint` is kept for debugging."""
    on_error = "default" if equinox_checks_mode() == "breakpoint" else "raise"
    result = traj.result
    return eqx.branched_error_if(
        traj,
        result != RESULTS.successful,
        result._value,
        RESULTS._index_to_message,
        on_error=on_error,
    )
