"""The floor: a plane that bodies bounce, slide, roll and rest on; level, or tilted by its
normal."""

import equinox as eqx
import jax.numpy as jnp

from . import _host
from ._checks import Requirement, as_float_array, finite, finite_nonnegative, raise_unmet
from ._linalg import dot


def set_contact_coefficients(surface, restitution, friction, rolling, spin):
    """Store a surface's contact coefficients as float arrays (called from `__init__`)."""
    surface.restitution = jnp.asarray(restitution, dtype=float)
    surface.friction = jnp.asarray(friction, dtype=float)
    surface.rolling_resistance = jnp.asarray(rolling, dtype=float)
    surface.spin_resistance = jnp.asarray(spin, dtype=float)


def contact_requirements(surface) -> tuple[Requirement, ...]:
    """The conditions every surface's contact coefficients meet."""
    e, mu = surface.restitution, surface.friction
    mu_r, mu_s = surface.rolling_resistance, surface.spin_resistance
    return (
        Requirement("restitution", e, "in [0, 1]", (e >= 0) & (e <= 1)),
        Requirement("friction", mu, "finite and >= 0", finite_nonnegative(mu)),
        Requirement("rolling_resistance", mu_r, "finite and >= 0", finite_nonnegative(mu_r)),
        Requirement("spin_resistance", mu_s, "finite and >= 0", finite_nonnegative(mu_s)),
    )


class Floor(eqx.Module):
    """The plane through (0, 0, `height`) with the unit normal `normal` (world frame; default
    up: the level floor z = `height`), with Newton's restitution and Coulomb friction. Bodies
    stay on the side the normal points to; gravity keeps its own direction (a tilted floor is
    an incline).

    **Arguments:**

    - `restitution`: Newton's coefficient chi in [0, 1]: the contact point's normal velocity
      after impact is -chi times the one before.
    - `friction`: Coulomb coefficient mu >= 0 for the tangential impulse (|j_t| <= mu j_n).
    - `height`: (m) the world z where the plane crosses the z axis.
    - `normal`: the plane's normal (any non-zero length; stored unit), pointing out of the
      floor into the space the body moves in. A plane tilted by the angle theta about the y
      axis, rising towards -x, is `normal=(sin theta, 0, cos theta)`.
    - `rolling_resistance`, `spin_resistance`: dimensionless coefficients mu_r, mu_s >= 0
      (default 0) of the couples that resist a ball's (`Sphere`'s) rolling and spinning:
      mu_r r N against the angular velocity's part along the surface and mu_s r N against
      its part about the normal (N m; r the ball's radius, N the normal force). A ball of
      radius r rolling on a level floor slows at 5 mu_r g / 7. See `resisting_couple`.
    """

    restitution: jnp.ndarray
    friction: jnp.ndarray
    height: jnp.ndarray
    normal: jnp.ndarray
    rolling_resistance: jnp.ndarray
    spin_resistance: jnp.ndarray

    curved = False  # one frame for every contact (a curved surface's depends on the ball)
    parts = 1  # one part: every contact point has the plane's frame

    def __init__(
        self,
        restitution,
        friction=0.0,
        height=0.0,
        normal=(0.0, 0.0, 1.0),
        rolling_resistance=0.0,
        spin_resistance=0.0,
    ):
        set_contact_coefficients(self, restitution, friction, rolling_resistance, spin_resistance)
        self.height = jnp.asarray(height, dtype=float)
        normal = as_float_array(normal, "normal", (3,))
        unit = _host.unit_vector(normal)  # NaN for a zero normal: flagged by `requirements`
        raise_unmet(
            "Floor", (Requirement("normal", normal, "a finite non-zero direction", finite(unit)),)
        )
        self.normal = unit

    def requirements(self) -> tuple[Requirement, ...]:
        """Conditions on the floor's parameters: a ValueError naming the field for concrete
        values where the floor is made, a result flag in `simulate` for traced ones."""
        h, n = self.height, self.normal
        return (
            *contact_requirements(self),
            Requirement("height", h, "finite", finite(h)),
            Requirement("normal", n, "a finite non-zero direction", jnp.all(finite(n))),
        )

    def __check_init__(self):
        raise_unmet("Floor", self.requirements())

    def frame(self, dtype=float):
        """The unit normal n and a tangent basis t1, t2 (world, t1 x t2 = n): t1 is the world
        x axis projected onto the plane (the y axis where the normal is nearly along x), so
        the level floor has (e_z, e_x, e_y)."""
        n = self.normal.astype(dtype)
        eye = jnp.eye(3, dtype=dtype)
        seed = jnp.where(jnp.abs(n[0]) < 0.9, eye[0], eye[1])
        t1 = seed - (seed @ n) * n
        t1 = t1 / jnp.linalg.norm(t1)
        return n, t1, jnp.cross(n, t1)

    def frame_at(self, centre, side=None):
        """The frame of a contact of a body centred at `centre`: the plane's, everywhere."""
        return self.frame(centre.dtype)

    def body_distance(self, shape, pos, quat):
        """Signed distance (m) of the shape's lowest point above the plane; `pos` the mass
        centre (world), `quat` the unit attitude quaternion."""
        return shape.floor_distance(pos, quat, self.height, self.normal)

    def region(self, centre):
        """Which part of the surface a body centred at `centre` touches (a plane has one:
        always 1; see `Cone.region`)."""
        return jnp.ones((), centre.dtype)

    def gap(self, points, side=None):
        """Signed distance (m) of world `points` (..., 3) above the plane (negative below);
        `side` is for surfaces of several parts (`Cone`), here unused."""
        n = self.normal.astype(points.dtype)
        return dot(points, n) - n[2] * self.height.astype(points.dtype)
