"""Curved surfaces a ball rolls, slides and bounces on: the inside of a spherical bowl, of
an upright cone (a funnel, as a roulette wheel's inclined track), and a roulette wheel's
stator (that track bounded by its outer wall).

A surface gives, for a point x (world, m), its signed distance above the surface `gap(x)`
(negative below it) and, for a ball centred at x, the frame of its contact: the unit normal
n = grad gap (pointing out of the surface into the space the ball moves in) and a tangent
basis t1, t2 with t1 x t2 = n (`frame_at`). The contact engine evaluates the frame at the
ball's centre and differentiates it along the centre's velocity, so only a `Sphere` meets a
curved surface; any shape meets a plane (`Floor`).

A surface of several parts (`Wheel`: track and wall) gives each part's gap and frame
(`part_gaps`, `part_frames`): a ball then has one contact point per part, and touching two
parts at once is a two-point contact (docs/contact.md, section 11).
"""

import equinox as eqx
import jax.numpy as jnp

from ._checks import Requirement, finite, finite_nonnegative, finite_positive, raise_unmet
from ._floor import contact_requirements, set_contact_coefficients
from ._quaternion import _safe_norm, quat_rotate
from ._shapes import Sphere


def _tangents(n):
    """t1: the world x axis projected onto the plane normal to n (the y axis where n is
    nearly along x), t2 = n x t1."""
    eye = jnp.eye(3, dtype=n.dtype)
    seed = jnp.where(jnp.abs(n[0]) < 0.9, eye[0], eye[1])
    t1 = seed - (seed @ n) * n
    t1 = t1 / _safe_norm(t1)
    return t1, jnp.cross(n, t1)


class AbstractCurvedSurface(eqx.Module):
    """A static curved surface with Newton's restitution, Coulomb friction and rolling and
    spin resistance (the same meaning as a `Floor`'s), met by a `Sphere` only."""

    restitution: eqx.AbstractVar[jnp.ndarray]
    friction: eqx.AbstractVar[jnp.ndarray]
    rolling_resistance: eqx.AbstractVar[jnp.ndarray]
    spin_resistance: eqx.AbstractVar[jnp.ndarray]

    curved = True  # the contact frame depends on where the ball is
    parts = 1  # the parts a ball can touch at once, each with its own frame (`Wheel`: 2)

    def __check_init__(self):
        raise_unmet(type(self).__name__, self.requirements())

    def requirements(self) -> tuple[Requirement, ...]:
        """Conditions on the surface's parameters: a ValueError naming the field for
        concrete values where it is made, a result flag in `simulate` for traced ones."""
        return contact_requirements(self)

    def gap(self, points, side=None):
        """Signed distance (m) of world `points` (..., 3) above the surface; `side` (a mode's
        +1 or -1) picks the part of a surface of several (see `region`), None the part
        each point is over."""
        raise NotImplementedError

    def frame_at(self, centre, side=None):
        """The unit normal n and tangents t1, t2 (world) of the contact of a ball centred
        at `centre` (3,): n points from the surface towards the centre (`side` as in
        `gap`)."""
        raise NotImplementedError

    def region(self, centre):
        """Where the surface's curvature jumps, the sign of this margin changes with the part
        a ball centred at `centre` touches (the contact engine ends a segment there, so that
        no step straddles the jump); 1 for a surface of one smooth part."""
        return jnp.ones((), centre.dtype)

    def body_distance(self, shape, pos, quat):
        """Signed distance (m) of a ball's surface above this one; `pos` the mass centre
        (world), `quat` the unit attitude quaternion."""
        if not isinstance(shape, Sphere):
            raise ValueError(
                f"a {type(self).__name__} meets only a Sphere (got a {type(shape).__name__}); "
                "any shape meets a Floor"
            )
        centre = pos + quat_rotate(quat, shape.offset.astype(pos.dtype))
        return self.gap(centre) - shape.radius


class Bowl(AbstractCurvedSurface):
    """The inside of a sphere of radius `radius` (m) whose lowest point is (0, 0, `height`):
    its centre is at (0, 0, height + radius), and a ball moves inside it.

    A ball of radius r rolling without slipping near the bottom oscillates like a pendulum
    of length 7 (radius - r) / 5.
    """

    restitution: jnp.ndarray
    friction: jnp.ndarray
    rolling_resistance: jnp.ndarray
    spin_resistance: jnp.ndarray
    radius: jnp.ndarray
    height: jnp.ndarray

    def __init__(
        self,
        restitution,
        friction=0.0,
        radius=1.0,
        height=0.0,
        rolling_resistance=0.0,
        spin_resistance=0.0,
    ):
        set_contact_coefficients(self, restitution, friction, rolling_resistance, spin_resistance)
        self.radius = jnp.asarray(radius, dtype=float)
        self.height = jnp.asarray(height, dtype=float)

    def requirements(self):
        return (
            *super().requirements(),
            Requirement("radius", self.radius, "finite and > 0", finite_positive(self.radius)),
            Requirement("height", self.height, "finite", finite(self.height)),
        )

    def centre(self, dtype=float):
        return jnp.stack([0.0, 0.0, self.height + self.radius]).astype(dtype)

    def gap(self, points, side=None):
        return self.radius.astype(points.dtype) - _safe_norm(
            points - self.centre(points.dtype), axis=-1
        )

    def frame_at(self, centre, side=None):
        n = self.centre(centre.dtype) - centre
        n = n / _safe_norm(n)
        return (n, *_tangents(n))


class AbstractConeTrack(AbstractCurvedSurface):
    """The inside of an upright cone about the world z axis, its apex at (0, 0, `height`),
    rising outwards at `inclination` (rad, in (0, pi/2)) from the horizontal, the apex
    rounded by `tip_radius` (m): the geometry `Cone` is and `Wheel` bounds by a wall."""

    restitution: jnp.ndarray
    friction: jnp.ndarray
    rolling_resistance: jnp.ndarray
    spin_resistance: jnp.ndarray
    inclination: jnp.ndarray
    height: jnp.ndarray
    tip_radius: jnp.ndarray

    def _set_cone(self, inclination, height, tip_radius):
        """Store the cone's dimensions as float arrays (called from `__init__`)."""
        self.inclination = jnp.asarray(inclination, dtype=float)
        self.height = jnp.asarray(height, dtype=float)
        self.tip_radius = jnp.asarray(tip_radius, dtype=float)

    def requirements(self):
        d, tip = self.inclination, self.tip_radius
        return (
            *super().requirements(),
            Requirement("inclination", d, "in (0, pi/2) rad", (d > 0) & (d < jnp.pi / 2)),
            Requirement("height", self.height, "finite", finite(self.height)),
            Requirement("tip_radius", tip, "finite and >= 0", finite_nonnegative(tip)),
        )

    def _radial(self, x):
        """The horizontal unit vector e_rho from the axis towards x (e_x on the axis)."""
        horizontal = x * jnp.array([1.0, 1.0, 0.0], x.dtype)
        rho = _safe_norm(horizontal, axis=-1, keepdims=True)
        on_axis = rho <= jnp.finfo(x.dtype).eps
        e_x = jnp.array([1.0, 0.0, 0.0], x.dtype)
        return jnp.where(on_axis, e_x, horizontal / jnp.where(on_axis, 1.0, rho)), rho[..., 0]

    def _tip(self, x, side=None):
        """The rounded tip's centre O (on the axis, tip_radius / cos d above the apex), x - O,
        and whether x lies where the tip is the nearest part (within d of -e_z seen from O;
        or, given `side`, whether it is +1)."""
        d = self.inclination.astype(x.dtype)
        tip = self.tip_radius.astype(x.dtype)
        centre = jnp.stack([0.0 * tip, 0.0 * tip, self.height.astype(x.dtype) + tip / jnp.cos(d)])
        u = x - centre
        if side is not None:
            return u, jnp.broadcast_to(side > 0, u.shape[:-1])
        return u, -u[..., 2] >= _safe_norm(u, axis=-1) * jnp.cos(d)

    def gap(self, points, side=None):
        """Signed distance (m) of world `points` (..., 3) above the track."""
        d = self.inclination.astype(points.dtype)
        _, rho = self._radial(points)
        cone = (points[..., 2] - self.height.astype(points.dtype)) * jnp.cos(d) - rho * jnp.sin(d)
        u, on_tip = self._tip(points, side)
        return jnp.where(
            on_tip, self.tip_radius.astype(points.dtype) - _safe_norm(u, axis=-1), cone
        )

    def region(self, centre):
        """Positive where a ball centred at `centre` touches the rounded tip, negative where
        it touches the cone: cos(angle of centre - O from -e_z) - cos(d)."""
        u, _ = self._tip(centre)
        d = self.inclination.astype(centre.dtype)
        return -u[2] / jnp.maximum(_safe_norm(u), jnp.finfo(centre.dtype).tiny) - jnp.cos(d)

    def frame_at(self, centre, side=None):
        """The frame (n, t1, t2, world) of a ball centred at `centre` on the track."""
        d = self.inclination.astype(centre.dtype)
        e_rho, _ = self._radial(centre)
        e_z = jnp.array([0.0, 0.0, 1.0], centre.dtype)
        u, on_tip = self._tip(centre, side)
        n = jnp.where(on_tip, -u / _safe_norm(u), -jnp.sin(d) * e_rho + jnp.cos(d) * e_z)
        e_phi = jnp.cross(e_z, e_rho)
        return n, jnp.cross(e_phi, n), e_phi


class Cone(AbstractConeTrack):
    """The inside of an upright cone with the world z axis as its axis, its apex at
    (0, 0, `height`) and its surface rising outwards at `inclination` (rad, in (0, pi/2))
    from the horizontal: z = height + tan(inclination) rho, rho the distance from the axis.
    A roulette wheel's inclined ball track is such a cone.

    The frame of a contact at azimuth phi: n = -sin(d) e_rho + cos(d) e_z (d the
    inclination), t1 = cos(d) e_rho + sin(d) e_z (up the slope), t2 = e_phi. A ball rolling
    without slipping and without spin about n on a horizontal circle of centre radius rho
    goes round at Omega^2 = 5 g tan(d) / (7 rho) (docs/contact.md, section 8).

    `tip_radius` (m, >= 0) rounds the apex: the bottom is then the spherical cap of that
    radius tangent to the cone (a funnel). A ball of radius r < tip_radius rolls smoothly
    through the bottom; at a sharp apex (the default, 0) a ball whose centre comes within
    r sin(d) of the axis would touch the cone along a ring, which is not modelled (the
    contact jumps from one side to the other: expect inconsistent events there).
    """

    def __init__(
        self,
        restitution,
        friction=0.0,
        inclination=0.3,
        height=0.0,
        rolling_resistance=0.0,
        spin_resistance=0.0,
        tip_radius=0.0,
    ):
        set_contact_coefficients(self, restitution, friction, rolling_resistance, spin_resistance)
        self._set_cone(inclination, height, tip_radius)


class Wheel(AbstractConeTrack):
    """A roulette wheel's stator, for a ball: the inclined track, the inside of an upright
    cone about the world z axis (as `Cone`: apex at (0, 0, `height`), rising outwards at
    `inclination`, rad, apex rounded by `tip_radius`), bounded by the outer wall, the inside
    of the vertical cylinder of radius `wall_radius` (m) about the same axis.

    Part 0 is the track, part 1 the wall: a ball has one contact point on each, and rolls
    or slides on the track, presses against the wall, or both at once (a two-point
    contact). The wall's frame at azimuth phi: n = -e_rho (towards the axis), t1 = e_z,
    t2 = e_phi. `gap` is the nearer part's and `frame_at` the track's (each part's:
    `part_gaps`, `part_frames`).

    The wall is smooth: it pushes along its normal only, and `restitution` applies at both
    parts while `friction`, `rolling_resistance` and `spin_resistance` are the track's. (A
    rigid ball held by friction at both contacts of a groove has statically indeterminate
    forces: the pair of internal forces along the line through the two contacts changes
    both normal forces, so rigid contact cannot say when it leaves the wall.)

    A ball of radius r rolling on the track against the wall (its centre at rho = wall_radius
    - r) without spin about the track's normal leaves the wall when its centre's speed
    falls to v^2 = (5/7) g rho tan(inclination) (docs/contact.md, section 11).
    """

    wall_radius: jnp.ndarray

    parts = 2

    def __init__(
        self,
        restitution,
        friction=0.0,
        inclination=0.3,
        wall_radius=0.4,
        height=0.0,
        rolling_resistance=0.0,
        spin_resistance=0.0,
        tip_radius=0.0,
    ):
        set_contact_coefficients(self, restitution, friction, rolling_resistance, spin_resistance)
        self._set_cone(inclination, height, tip_radius)
        self.wall_radius = jnp.asarray(wall_radius, dtype=float)

    def requirements(self):
        R = self.wall_radius
        return (
            *super().requirements(),
            Requirement(
                "wall_radius", R, "finite and > tip_radius", finite(R) & (R > self.tip_radius)
            ),
        )

    def part_gaps(self, points, side=None):
        """Signed distances (m) (..., 2) of world `points` (..., 3) above the track and inside
        the wall."""
        rho = _safe_norm(points[..., :2], axis=-1)
        wall = self.wall_radius.astype(points.dtype) - rho
        return jnp.stack([super().gap(points, side), wall], axis=-1)

    def gap(self, points, side=None):
        """Signed distance (m) of world `points` above the nearer part (the smaller gap)."""
        return jnp.min(self.part_gaps(points, side), axis=-1)

    def part_frames(self, centre, side=None):
        """Normals n, tangents t1, t2 (each (2, 3), world) of a ball centred at `centre` on the
        track (row 0) and on the wall (row 1)."""
        n, t1, t2 = self.frame_at(centre, side)  # the track's
        e_rho, _ = self._radial(centre)
        e_z = jnp.array([0.0, 0.0, 1.0], centre.dtype)
        e_phi = jnp.cross(e_z, e_rho)
        return jnp.stack([n, -e_rho]), jnp.stack([t1, e_z]), jnp.stack([t2, e_phi])

    def part_coefficients(self):
        """Friction, rolling and spin resistance of each part (2,): the wall's are zero."""
        zero = jnp.zeros_like(self.friction)
        return (
            jnp.stack([self.friction, zero]),
            jnp.stack([self.rolling_resistance, zero]),
            jnp.stack([self.spin_resistance, zero]),
        )
