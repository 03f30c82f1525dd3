"""`Trajectory`: what `simulate` returns, for every kind of scene."""

import equinox as eqx
import jax

from ._results import RESULTS
from ._state import State


class Trajectory(eqx.Module):
    """The result of `simulate`.

    **Fields:**

    - `ts`: save times (s), shape (T,).
    - `states`: a `State` whose leaves have a leading time axis (T, ...); unit quaternions.
    - `result`: a `jaxrb.RESULTS` code (per batch member under vmap);
      `RESULTS.successful` if all went well.
    - `quat_norm_drift`: max over the save times of ||q| - 1| before normalisation: how far
      the integrator let the quaternion norm wander (the exact flow keeps it at 1).
    - `num_steps`: accepted solver steps.
    - `impacts`: a `jaxrb.contact.ImpactRecord` for scenes with a floor, else None.
    - `contact`: a `jaxrb.contact.ContactLog` for scenes with a floor (events, the contact
      mode at each save time, last-resort counts), else None.
    """

    ts: jax.Array
    states: State
    result: RESULTS
    quat_norm_drift: jax.Array
    num_steps: jax.Array
    impacts: "ImpactRecord | None" = None  # noqa: F821 (jaxrb.contact.ImpactRecord)
    contact: "ContactLog | None" = None  # noqa: F821 (jaxrb.contact.ContactLog)
