"""The floor: a horizontal plane z = height that bodies bounce on."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import is_concrete


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

    def __check_init__(self):
        if is_concrete(self.restitution):
            e = np.asarray(self.restitution)
            if not np.all((e >= 0) & (e <= 1)):
                raise ValueError(f"restitution must be in [0, 1], got {e}")
        if is_concrete(self.friction):
            mu = np.asarray(self.friction)
            if not np.all((mu >= 0) & np.isfinite(mu)):
                raise ValueError(f"friction must be finite and >= 0, got {mu}")
        if is_concrete(self.height) and not np.all(np.isfinite(np.asarray(self.height))):
            raise ValueError(f"height must be finite, got {self.height}")
