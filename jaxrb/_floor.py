"""The floor: a horizontal plane z = height that bodies bounce on."""

import equinox as eqx
import jax.numpy as jnp

from ._checks import Requirement, finite, finite_nonnegative, raise_unmet


class Floor(eqx.Module):
    """A horizontal plane z = `height` (m) with Newton's restitution and Coulomb friction.

    **Arguments:**

    - `restitution`: Newton's coefficient chi in [0, 1]: the contact point's normal velocity
      after impact is -chi times the one before.
    - `friction`: Coulomb coefficient mu >= 0 for the tangential impulse (|j_t| <= mu j_n).
    - `height`: the floor's world z (m).
    """

    restitution: jnp.ndarray
    friction: jnp.ndarray
    height: jnp.ndarray

    def __init__(self, restitution, friction=0.0, height=0.0):
        self.restitution = jnp.asarray(restitution, dtype=float)
        self.friction = jnp.asarray(friction, dtype=float)
        self.height = jnp.asarray(height, dtype=float)

    def requirements(self) -> tuple[Requirement, ...]:
        """Conditions on the floor's parameters: a ValueError naming the field for concrete
        values where the floor is made, a result flag in `simulate` for traced ones."""
        e, mu, h = self.restitution, self.friction, self.height
        return (
            Requirement("restitution", e, "in [0, 1]", (e >= 0) & (e <= 1)),
            Requirement("friction", mu, "finite and >= 0", finite_nonnegative(mu)),
            Requirement("height", h, "finite", finite(h)),
        )

    def __check_init__(self):
        raise_unmet("Floor", self.requirements())
