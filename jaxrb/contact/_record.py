"""What a contact simulation reports besides the states: its impacts and its events."""

import equinox as eqx
import jax
import jax.numpy as jnp


class ImpactRecord(eqx.Module):
    """The impacts of one trajectory (leading axis: impact slot, `max_impacts` long).

    **Fields:**

    - `time`: impact times (s); `inf` in unused slots.
    - `point`: world point (m) where the impulse acts (on the floor plane).
    - `impulse`: total impulse (N s, world frame) the floor gave the body, summed over all
      the contacts that took part.
    - `normal_speed`: the largest approach speed (m/s, > 0) of a touching point.
    - `energy_lost`: kinetic + potential energy (J) lost at that impact (>= 0).
    - `count`: number of impacts recorded.
    - `rest_time`: for the last bounce series replaced by its limit (a Zeno merge, see
      `ContactLog`), the time (s) at which that series would have ended; `inf` if none.
    """

    time: jax.Array
    point: jax.Array
    impulse: jax.Array
    normal_speed: jax.Array
    energy_lost: jax.Array
    count: jax.Array
    rest_time: jax.Array

    @property
    def valid(self) -> jax.Array:
        """Mask of the used slots."""
        return jnp.arange(self.time.shape[-1], dtype=self.count.dtype) < self.count[..., None]


def empty_impacts(max_impacts: int, dtype) -> ImpactRecord:
    M = max_impacts
    return ImpactRecord(
        time=jnp.full(M, jnp.inf, dtype),
        point=jnp.zeros((M, 3), dtype),
        impulse=jnp.zeros((M, 3), dtype),
        normal_speed=jnp.zeros(M, dtype),
        energy_lost=jnp.zeros(M, dtype),
        count=jnp.array(0, jnp.int32),
        rest_time=jnp.array(jnp.inf, dtype),
    )


def add_impact(rec: ImpactRecord, do, t, point, impulse, speed, lost, rest_time) -> ImpactRecord:
    k = jnp.minimum(rec.count, rec.time.shape[0] - 1)

    def put(buf, val):
        return buf.at[k].set(jnp.where(do, val, buf[k]))

    return ImpactRecord(
        time=put(rec.time, t),
        point=put(rec.point, point),
        impulse=put(rec.impulse, impulse),
        normal_speed=put(rec.normal_speed, speed),
        energy_lost=put(rec.energy_lost, lost),
        count=rec.count + do.astype(rec.count.dtype),
        rest_time=jnp.where(do & jnp.isfinite(rest_time), rest_time, rec.rest_time),
    )


class ContactLog(eqx.Module):
    """How the contact simulation went (one trajectory).

    **Fields:**

    - `events`: number of events (impacts, lift-offs, stick/slip changes, tipping, ...).
    - `zeno_merges`: how often a bounce (or rocking) series was replaced by its limit, the
      documented last resort (docs/contact.md, section 5).
    - `energy_guards`: how often Newton's law with friction would have added energy and the
      frictionless impulse was used instead.
    - `inconsistent`: how often no candidate mode satisfied every contact condition (the
      least inconsistent one was taken: a boundary case; where it is the Painlevé paradox,
      the run stops with `RESULTS.painleve_paradox`).
    - `ambiguous`: how often a sliding contact's normal force problem had two solutions
      (the other side of the Painlevé paradox) and the contact lifting off was taken.
    - `max_energy_rise`: the largest rise (J) of the energy across any event (roundoff).
    - `max_penetration`: the deepest (m) any contact point was below the floor at an event.
    - `kind`: (T,) the contact mode at each save time: 0 flight, 1 point, 2 pair (an edge or
      a cylinder's side), 3 face.
    - `sliding`: (T,) whether the contact slid at each save time.
    - `event_time`: (max_events,) the time (s) of each event, `inf` in unused slots.
    - `event_cause`: (max_events,) what ended the segment before it (`CAUSES`).
    - `event_kind`, `event_sliding`: (max_events,) the mode after it.
    - `event_inconsistent`: (max_events,) whether it is one of those counted in
      `inconsistent` (no candidate mode, or no impulse, met every condition).
    """

    events: jax.Array
    zeno_merges: jax.Array
    energy_guards: jax.Array
    inconsistent: jax.Array
    ambiguous: jax.Array
    max_energy_rise: jax.Array
    max_penetration: jax.Array
    kind: jax.Array
    sliding: jax.Array
    event_time: jax.Array
    event_cause: jax.Array
    event_kind: jax.Array
    event_sliding: jax.Array
    event_inconsistent: jax.Array


CAUSES = ("start", "touch", "flat", "lift-off", "slip starts", "slip stops", "tip", "junction")
"""The names of the event causes, indexed by the codes in `ContactLog.event_cause`."""
