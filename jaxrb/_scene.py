"""A scene: one body, the forces on it, and optionally a floor or a joint."""

import equinox as eqx

from ._body import RigidBody
from ._floor import Floor
from ._forces import AbstractForce
from ._joints import AbstractJoint
from ._surfaces import AbstractCurvedSurface


class Scene(eqx.Module):
    """What is simulated: a `RigidBody`, a tuple of forces, an optional floor or joint.

    The floor is the surface the body meets: a plane (`Floor`), or for a `Sphere` the
    inside of a `Bowl` or a `Cone`, or a roulette `Wheel` (track and wall).

    The pytree structure (which forces, which joint) is static; the parameters inside
    (mass, inertia, drag coefficients, restitution...) are differentiable array leaves.
    A scene with no drag force has no drag terms in its compiled right-hand side.
    """

    body: RigidBody
    forces: tuple[AbstractForce, ...] = ()
    floor: Floor | AbstractCurvedSurface | None = None
    joint: AbstractJoint | None = None

    def __check_init__(self):
        if not isinstance(self.body, RigidBody):
            raise TypeError(f"body must be a RigidBody, got {type(self.body).__name__}")
        if not isinstance(self.forces, tuple):
            raise TypeError("forces must be a tuple of forces, e.g. (jaxrb.Gravity(),)")
        for i, force in enumerate(self.forces):
            if not isinstance(force, AbstractForce):
                raise TypeError(f"forces[{i}] is not a force model: {type(force).__name__}")
        if self.floor is not None and not isinstance(self.floor, (Floor, AbstractCurvedSurface)):
            raise TypeError(
                f"floor must be a Floor, Bowl, Cone or Wheel, got {type(self.floor).__name__}"
            )
        if self.floor is not None and self.joint is not None:
            raise ValueError("a scene may have a floor or a joint, not both")


def with_inertia_inverse(scene: Scene) -> Scene:
    """`scene` with its body's J^-1 computed once (`RigidBody.with_inertia_inverse`), not in
    every evaluation of the equations inside the solver's loops."""
    return eqx.tree_at(lambda s: s.body, scene, scene.body.with_inertia_inverse())
