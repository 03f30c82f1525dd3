"""A rigid body: mass, inertia tensor about the mass centre, optional shape."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from . import _host, inertia as _inertia
from ._checks import as_computed, is_concrete
from ._linalg import inverse3
from ._shapes import AbstractShape
from ._typing import Mat3


class RigidBody(eqx.Module):
    """Mass (kg) and inertia (kg m^2, about the mass centre, body axes) of a rigid body.

    **Arguments:**

    - `mass`: positive scalar.
    - `inertia`: either the full 3x3 tensor J = integral (r.r 1 - r r^T) dm, products of
      inertia allowed (off-diagonal entries are -J_xy etc.), or the three principal moments
      (shape (3,)) when the body axes are principal axes. The principal form selects the
      cheaper Euler equations in the right-hand side. For a batch of bodies given in
      principal moments with explicit leading axes, pass `principal=True`.
    - `shape`: optional `Sphere`, `Box`, `Cylinder` or `ConvexPolyhedron` for contact and
      plotting; if `inertia` is None it is computed from the shape as a uniform solid (about
      the shape's centre: give `inertia` for a shape with an `offset`).

    `inertia_inverse` is None unless `with_inertia_inverse()` cached J^-1 (the contact engine
    and the batched free rotation do, once per simulation, instead of inverting J at every
    evaluation of the equations): the full 3x3 tensor, or for principal moments their
    reciprocals (shape (3,)).

    `mass` and `inertia` are array leaves: differentiate or vmap over them freely. Concrete
    values are validated on construction (mass > 0, finite; inertia symmetric, positive
    definite, triangle inequality); traced values are checked by `simulate`'s result flag.
    """

    mass: jnp.ndarray
    inertia: jnp.ndarray
    shape: AbstractShape | None = None
    principal: bool = eqx.field(static=True, default=False)
    inertia_inverse: jnp.ndarray | None = eqx.field(default=None, repr=False)

    def __init__(self, mass, inertia=None, shape=None, principal=None):
        self.mass = jnp.asarray(mass, dtype=float) if not hasattr(mass, "dtype") else mass
        if inertia is None:
            if shape is None:
                raise ValueError("RigidBody needs `inertia` or a `shape` to compute it from")
            inertia = _host.shape_inertia(shape, self.mass)  # one program
        inertia = jnp.asarray(inertia) if not hasattr(inertia, "dtype") else inertia
        if not jnp.issubdtype(inertia.dtype, jnp.floating):
            inertia = inertia.astype(float)
        if principal is None:
            principal = inertia.ndim == 1
        if principal and inertia.shape[-1:] != (3,):
            raise ValueError(
                f"inertia: principal moments must have shape (..., 3), got {inertia.shape}"
            )
        if not principal and inertia.shape[-2:] != (3, 3):
            raise ValueError(
                "inertia must be a (..., 3, 3) tensor or (3,) principal moments, "
                f"got shape {inertia.shape}"
            )
        self.inertia = inertia
        self.shape = shape
        self.principal = bool(principal)
        self.inertia_inverse = None

    def __check_init__(self):
        if is_concrete(self.mass) and np.ndim(self.mass) >= 0:
            m = as_computed(self.mass)  # a subnormal mass is 0, as in the simulation
            if not np.all(np.isfinite(m)):
                raise ValueError(f"mass must be finite, got {m}")
            if np.any(m <= 0):
                given = np.asarray(self.mass)
                subnormal = " (subnormal: it computes as 0)" if np.any(given != m) else ""
                raise ValueError(f"mass must be > 0, got {given}{subnormal}")
        if is_concrete(self.inertia):
            _inertia.check_inertia(self.inertia_matrix, name="inertia")

    def with_inertia_inverse(self) -> "RigidBody":
        """This body with J^-1 (kg^-1 m^-2, body axes) cached in `inertia_inverse`: inverted
        once here, where the caller's program would otherwise invert J at every evaluation.
        Only for a body whose `inertia` is not changed afterwards (the cache would be stale).
        Principal moments cache their reciprocals 1 / J_i (3,)."""
        inverse = 1.0 / self.inertia if self.principal else inverse3(self.inertia)
        return eqx.tree_at(lambda b: b.inertia_inverse, self, inverse, is_leaf=lambda x: x is None)

    @property
    def inertia_matrix_inverse(self) -> Mat3:
        """J^-1 as a full 3x3 tensor (kg^-1 m^-2, body axes): the cached `inertia_inverse`
        if there is one, else inverted here."""
        if self.inertia_inverse is None:
            return inverse3(self.inertia_matrix)
        if self.principal:
            inverse = self.inertia_inverse
            return inverse[..., :, None] * jnp.eye(3, dtype=inverse.dtype)
        return self.inertia_inverse

    @property
    def inertia_matrix(self) -> Mat3:
        """The full 3x3 tensor (diagonal when given as principal moments)."""
        if self.principal:
            return self.inertia[..., :, None] * jnp.eye(3, dtype=self.inertia.dtype)
        return self.inertia
