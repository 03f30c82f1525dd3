"""Contact with the floor: persistent contact with Coulomb friction (rolling, rocking,
pivoting, sliding), impacts at all touching points at once, events for every mode change.

The formulation is in docs/contact.md. One concern per file:

- `_options.py`: `ContactOptions` (bounds and tolerances, checked once);
- `_record.py`: `ImpactRecord`, `ContactLog` (what a run reports);
- `_features.py`: the per-shape contact models (points, pairs, faces), in one table;
- `_modes.py`: modes, constraint rows and the constrained Newton-Euler equations;
- `_events.py`: the conditions that end a segment;
- `_step_end.py`, `_step_limit.py`: the event function and step limit carried at step ends,
  and the steps cut to that limit;
- `_event_root.py`: the event's time on the last step's dense output, and its cause;
- `_resting.py`: which points touch, rest and have stopped slipping at an event;
- `_select.py`: the next mode at an event (enumeration of candidate modes);
- `_impact_law.py`: Newton's restitution with Coulomb friction at all touching points;
- `_projection.py`: positions and velocities projected onto the active constraints;
- `_transition.py`: what happens at an event;
- `_driver.py`: the segment loop;
- `_lanes.py`: many throws in lanes refilled as throws finish (`jaxrb.simulate_throws`).

Small linear systems are solved by `jaxrb._linalg` (plain jnp, no LAPACK).
"""

from ._features import (
    CONTACT_MODELS as CONTACT_MODELS,
    AbstractContactModel as AbstractContactModel,
    contact_model as contact_model,
)
from ._impact_law import solve_impacts as solve_impacts
from ._lanes import default_lanes as default_lanes
from ._modes import KIND_NAMES as KIND_NAMES
from ._options import ContactOptions as ContactOptions
from ._record import CAUSES as CAUSES, ContactLog as ContactLog, ImpactRecord as ImpactRecord
