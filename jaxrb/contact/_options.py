"""Contact options: bounds and tolerances, checked once where they are made."""

import math

import equinox as eqx
import jax.numpy as jnp

DEFAULT_MAX_IMPACTS = 64
# the blend speed (`Tolerances.slip_blend`) per stop speed. Friction's direction follows a
# slip within the blend speed at about mu g / blend (an explicit solver's steps near
# blend / (mu g)): at a tenth of the stop speed, a coin's brief slides from rest while it
# rolls took 90 % of its steps (benchmarks/README.md); a turn-back at -blend / 2 still ends
# inside the band the mode choice counts as at rest (|s| < slip_stop)
BLEND_PER_STOP = 1.0
DEFAULT_REST_SPEED = 1e-2
# at an event's mode choice, the conditions' tolerance grows by this much of the candidate's
# largest force per unit mass: the event time is located to `event_tol`, and where the
# forces are large and change fast (a coin rolling fast on its rim: 2000-3000 m/s^2 per
# unit mass, changing at about 1e7 m/s^3) the conditions at the located time are off by
# up to 4e-9 of them, past `force_tol` (benchmarks/README.md)
FORCE_TOL_PER_FORCE = 1e-8


def _positive(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    return value


class ContactOptions(eqx.Module):
    """How a scene with a floor is integrated across contact events (docs/contact.md).

    **Arguments:**

    - `max_impacts`: static bound on the number of impacts (the size of
      `Trajectory.impacts`); reaching it before the end time gives
      `RESULTS.max_impacts_reached`.
    - `max_events`: static bound on the number of events of any kind (impacts, lift-offs,
      stick/slip changes, tipping); default 4 max_impacts + 16. Reaching it is
      `RESULTS.max_events_reached`.
    - `rest_speed`: (m/s) when after an impact every touching point leaves the floor slower
      than this while the forces press the body onto it, the series of ever smaller bounces
      or rocks that would follow is replaced by its limit (the body stays on the touching
      feature). Default 1e-2.
    - `slip_stop`: (m/s) at an event, a contact whose slip is below this counts as not
      sliding (the rest is removed by the friction impulse of the last instant), and a
      touching point whose normal speed is below it counts as resting. It is also the
      blend speed below which friction that starts from rest turns smoothly to the slip's
      direction. Default 1e-5.
    - `contact_tol`: (m) gap below which a point counts as touching at an event; default
      1e-9 in float64, 1e-5 in float32.
    - `flat_tol`: (m) how close to the floor a cap's highest rim point must come for the
      cap to count as flat (the end of a coin rolling on its rim); default 1e-7 in float64,
      1e-5 in float32.
    - `force_tol`: (m/s^2) tolerance of the sign and cone conditions, on forces per unit
      mass; default 1e-7 in float64, 1e-3 in float32. At an event's choice of mode it grows
      by 1e-8 of the candidate's largest force per unit mass (`FORCE_TOL_PER_FORCE`: the
      error of the located event time where large forces change fast).
    - `stabilisation`: (1/s) rate at which constraint residuals (drift) decay inside a
      segment (Baumgarte); default 20.
    - `event_tol`: (s) tolerance of the event-time root find; default 1e-12 in float64,
      64 machine epsilons in float32.
    """

    max_impacts: int = eqx.field(static=True)
    max_events: int = eqx.field(static=True)
    rest_speed: float = eqx.field(static=True)
    slip_stop: float = eqx.field(static=True)
    contact_tol: float | None = eqx.field(static=True)
    flat_tol: float | None = eqx.field(static=True)
    force_tol: float | None = eqx.field(static=True)
    stabilisation: float = eqx.field(static=True)
    event_tol: float | None = eqx.field(static=True)

    def __init__(
        self,
        max_impacts: int = DEFAULT_MAX_IMPACTS,
        max_events: int | None = None,
        rest_speed: float = DEFAULT_REST_SPEED,
        slip_stop: float = 1e-5,
        contact_tol: float | None = None,
        flat_tol: float | None = None,
        force_tol: float | None = None,
        stabilisation: float = 20.0,
        event_tol: float | None = None,
    ):
        for name, value in (("max_impacts", max_impacts), ("max_events", max_events)):
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a Python int >= 1, got {value!r}")
        self.max_impacts = max_impacts
        self.max_events = 4 * max_impacts + 16 if max_events is None else max_events
        self.rest_speed = _positive("rest_speed", rest_speed)
        self.slip_stop = _positive("slip_stop", slip_stop)
        self.contact_tol = None if contact_tol is None else _positive("contact_tol", contact_tol)
        self.flat_tol = None if flat_tol is None else _positive("flat_tol", flat_tol)
        self.force_tol = None if force_tol is None else _positive("force_tol", force_tol)
        self.stabilisation = _positive("stabilisation", stabilisation) if stabilisation else 0.0
        self.event_tol = None if event_tol is None else _positive("event_tol", event_tol)

    @classmethod
    def from_shortcuts(cls, contact, max_impacts=None, rest_speed=None) -> "ContactOptions":
        """`contact` (a `ContactOptions` or None) with `simulate`'s shortcut arguments: the
        options they give when `contact` is None; a ValueError when both are given."""
        if contact is None:
            shortcuts = dict(max_impacts=max_impacts, rest_speed=rest_speed)
            return cls(**{k: v for k, v in shortcuts.items() if v is not None})
        if max_impacts is not None or rest_speed is not None:
            raise ValueError("give max_impacts and rest_speed inside `contact`, not beside it")
        return contact

    def resolved(self, dtype) -> "Tolerances":
        """The tolerances for a computation in `dtype`."""
        double = jnp.finfo(dtype).bits >= 64
        pick = lambda given, d64, d32: float(
            given if given is not None else (d64 if double else d32)
        )  # noqa: E731
        eps = float(jnp.finfo(dtype).eps)
        return Tolerances(
            contact=pick(self.contact_tol, 1e-9, 1e-5),
            flat=pick(self.flat_tol, 1e-7, 1e-5),
            force=pick(self.force_tol, 1e-7, 1e-3),
            event=pick(self.event_tol, 1e-12, 64 * eps),
            penetration=1e-12 if double else 1e-6,
            velocity=1e-10 if double else 1e-5,
            slip_stop=self.slip_stop,
            slip_blend=self.slip_stop * BLEND_PER_STOP,
            rest_speed=self.rest_speed,
            stabilisation=self.stabilisation,
        )


class Tolerances(eqx.Module):
    """Resolved tolerances (Python floats, static). `penetration` (m): how far a touching
    point may go under before its gap event fires (its gap starts at the boundary);
    `velocity` (m/s): tolerance of the velocity-level (impact) conditions; `slip_blend`
    (m/s): a sliding contact's friction opposes s + slip_blend s0 (s the slip, s0 the unit
    direction it started in), so that sliding from rest starts in a definite direction.
    """

    contact: float = eqx.field(static=True)
    flat: float = eqx.field(static=True)
    force: float = eqx.field(static=True)
    event: float = eqx.field(static=True)
    penetration: float = eqx.field(static=True)
    velocity: float = eqx.field(static=True)
    slip_stop: float = eqx.field(static=True)
    slip_blend: float = eqx.field(static=True)
    rest_speed: float = eqx.field(static=True)
    stabilisation: float = eqx.field(static=True)
