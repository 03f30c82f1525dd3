"""Contact modes, their constraint rows, and the constrained Newton-Euler equations.

A mode fixes, for a smooth segment, which feature carries the body (nothing, a point, a pair
of points, a face) and whether each of its contacts sticks or slides. With the mode fixed the
contact forces solve one linear system of at most 6 rows (docs/contact.md, section 2):

    (J M^-1 C) lambda = -(J a0 + b) - stabilisation,      u' = a0 + M^-1 C lambda,

with u = (v, w) (mass-centre velocity and angular velocity, both world frame),
M = diag(m 1, I_w), a0 the accelerations from the forces alone, J the constraint rows, b their
velocity-product terms and C the force columns (equal to J except where a sliding contact's
friction rides on its normal force). Rows a mode does not use are identity rows with zero
right-hand side, so every mode is the same fixed-size solve.

Row slots: points and pairs use 0: normal at a, 1: normal at b, 2-3: tangential at a,
4-5: tangential at b (a pair's tangential rows run across and along its line; a sticking pair
has only one row along the line, slot 3, since both ends move along it together); a face uses
0: normal at its centre, 1-2: tilt about t1, t2, 3-4: tangential at its centre, 5: spin (a
face turning about a vertex: 3-4 tangential at that vertex, no spin row).

A sliding face's friction is either its limit surface about its centre (an ellipsoid in the
slip twist), or, on a `support` of three of its vertices, each vertex's own Coulomb friction
opposing its own slip with the vertex's share of the normal load (docs/contact.md, section
2): the rows are the face's, only the force columns differ. One of a support's vertices, the
mode's point b, may be at rest: sticking, a face turning about it (`on_pivot`: its friction
is then that vertex's own tangential rows), or starting to slide from rest
(`support_vertex_starts`: its friction along the mode's direction from rest).
"""

import itertools

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np

from .._dynamics import accelerations
from .._linalg import cross, dot, inverse3, matmul, matvec, solve as small_solve, vecmat
from .._quaternion import _safe_norm, quat_normalize, quat_to_matrix
from .._rates import quat_rate
from .._state import State

FLIGHT, POINT, PAIR, FACE = 0, 1, 2, 3
KIND_NAMES = ("flight", "point", "pair", "face")
"""The names of the contact modes, indexed by the codes in `ContactLog.kind` and
`ContactLog.event_kind`."""
NUM_ROWS = 6


class Mode(eqx.Module):
    """A contact mode (traced: every member of a batch has its own).

    **Fields:**

    - `kind`: FLIGHT, POINT, PAIR or FACE (int).
    - `a`, `b`: contact point indices (POINT uses `a`; PAIR both).
    - `face`: face index (FACE).
    - `stick`: (2,) bool, whether point a / point b sticks (a face uses entry 0; a face on
      a support, entry 1 for its vertex `b`: a pivot).
    - `slide_dir`: (2, 3) world unit directions of the slip of points a, b, used while a
      sliding point's slip is zero (sliding from rest); zero means no friction at that instant.
    - `twist_dir`: (3,) the same for a sliding face's slip twist (v . t1, v . t2, rho w . n).
    - `from_rest`: (2,) bool, whether the slide of point a (or the face) / point b started
      from zero slip (its end is then detected as the slip turning back, not stopping).
    - `seed`: (3,) body-frame direction used for a rim point when its cap lies flat.
    - `side`: +1 or -1, the sign of the surface's `region` margin during the segment (a
      curved surface whose curvature jumps: which part the ball touches).
    - `support`: (3,) int, for a sliding face that rests on three of its vertices with
      their own friction, those vertices' point indices (ascending); -1 for every other
      mode. One of them may be its point `b`, at rest: sticking (`stick[1]`, a pivot) or
      starting to slide (`from_rest[1]`, along `slide_dir[1]`).
    """

    kind: jax.Array
    a: jax.Array
    b: jax.Array
    face: jax.Array
    stick: jax.Array
    slide_dir: jax.Array
    twist_dir: jax.Array
    from_rest: jax.Array
    seed: jax.Array
    side: jax.Array
    support: jax.Array


def face_supports(points) -> list[tuple[int, int, int]]:
    """The supports (`Mode.support`) of a face whose points are `points`: every set of three
    of them (point indices, ascending), none for a face of fewer than three points."""
    return list(itertools.combinations(sorted(points), 3))


def has_supports(model) -> bool:
    """Whether any face of the shape can slide on a support (static)."""
    return any(face_supports(points) for points in model.face_points)


def on_support(mode: Mode) -> jax.Array:
    """Whether `mode` is a face sliding on three of its vertices, each with its own friction
    (a support's mode made to stick is the face sticking), one of them possibly at rest
    (`on_pivot`, `support_vertex_starts`)."""
    return (mode.kind == FACE) & (mode.support[0] >= 0) & ~mode.stick[0]


def on_pivot(mode: Mode) -> jax.Array:
    """Whether `mode` is a face on a support one of whose vertices, its point `b` (the
    pivot), sticks while the other two slide, each with its own friction: a face turning
    about a vertex."""
    return on_support(mode) & mode.stick[1]


def support_vertex_starts(mode: Mode) -> jax.Array:
    """Whether `mode` is a face on a support one of whose vertices, its point `b`, starts
    to slide from rest (along `slide_dir[1]`) while the other two slide on."""
    return on_support(mode) & ~mode.stick[1] & mode.from_rest[1]


def support_vertex_b(mode: Mode) -> jax.Array:
    """(3,) which of a support's vertices is the mode's point `b` (the pivot, or the vertex
    starting from rest); all False off a support."""
    return on_support(mode) & (mode.support == mode.b)


def flight_mode(dtype) -> Mode:
    zero = jnp.array(0, jnp.int32)
    return Mode(
        kind=jnp.array(FLIGHT, jnp.int32),
        a=zero,
        b=zero,
        face=zero,
        stick=jnp.zeros(2, bool),
        slide_dir=jnp.zeros((2, 3), dtype),
        twist_dir=jnp.zeros(3, dtype),
        from_rest=jnp.zeros(2, bool),
        seed=jnp.array([1.0, 0.0, 0.0], dtype),
        side=jnp.ones((), dtype),
        support=jnp.full(3, -1, jnp.int32),
    )


class CandidateTable:
    """Every mode a shape can be in, in order of preference (more contact first, stick
    before slide), as static numpy arrays (C,): kind, a, b, face, stick (C, 2), support
    (C, 3), and the masks (C, P) of the points each one holds on the floor (`active`) and
    holds still (`sticking`). A face slides first with its limit surface, then on each
    set of three of its vertices (`Mode.support`, in the order of their indices) turning
    about one of them (`on_pivot`; the pivot is the mode's `b`), then on each such set.
    (A support one of whose vertices starts to slide from rest is the support's row, that
    vertex made its `b` at the event: `_select.py`.)

    `candidates`: the indices of the modes that can apply when the body rests on the floor
    with some of its points. All touching points of a convex body lie in one supporting
    plane, i.e. on one face (or on an edge or corner of it), so for a body with faces whose
    points are all corners (a box) only that face's modes need testing (its `groups` row);
    otherwise every mode is a candidate. When at most two points rest, only the modes that
    hold no other point can apply (`near`: a handful, against a face's two or three dozen).
    """

    def __init__(self, model):
        P = model.num_points
        # (kind, a, b, face, stick_a, stick_b, active points, sticking points, support)
        rows = []
        none = (-1, -1, -1)
        for f, pts in enumerate(model.face_points):
            for stick in (True, False):
                held = pts if stick else ()
                rows.append((FACE, pts[0], pts[0], f, stick, False, pts, held, none))
            for support in face_supports(pts):
                for p in support:
                    rows.append((FACE, pts[0], p, f, False, True, pts, (p,), support))
            for support in face_supports(pts):
                rows.append((FACE, pts[0], pts[0], f, False, False, pts, (), support))
        smooth = model.smooth_points  # these slide only
        for a, b in model.pairs:
            for sa, sb in ((True, True), (True, False), (False, True), (False, False)):
                if (sa and a in smooth) or (sb and b in smooth):
                    continue
                held = tuple(p for p, s in ((a, sa), (b, sb)) if s)
                rows.append((PAIR, a, b, 0, sa, sb, (a, b), held, none))
        for a in model.point_features:
            for stick in (True, False) if a not in smooth else (False,):
                rows.append((POINT, a, a, 0, stick, False, (a,), (a,) if stick else (), none))
        rows.append((FLIGHT, 0, 0, 0, False, False, (), (), none))

        def mask(points):
            m = np.zeros(P, bool)
            m[list(points)] = True
            return m

        self.kind = np.array([r[0] for r in rows], np.int32)
        self.a = np.array([r[1] for r in rows], np.int32)
        self.b = np.array([r[2] for r in rows], np.int32)
        self.face = np.array([r[3] for r in rows], np.int32)
        self.stick = np.array([(r[4], r[5]) for r in rows], bool)
        self.support = np.array([r[8] for r in rows], np.int32)
        self.active = np.stack([mask(r[6]) for r in rows])
        self.sticking = np.stack([mask(r[7]) for r in rows])
        faces = face_point_masks(model)[: model.num_faces]
        on_a_face = [np.any(np.all(~a | faces, axis=1)) for a in self.active]
        if model.num_faces and all(on_a_face):
            # per face: the modes whose points all lie on it (FLIGHT among them)
            groups = [np.flatnonzero(np.all(~self.active | f, axis=1)) for f in faces]
            self.group_faces = faces
        else:
            groups = [np.arange(len(rows))]
            self.group_faces = np.ones((1, P), bool)
        # near[p, q]: the modes that hold no point but p and q (p == q: one point), in the
        # table's order. Every list of candidates is tested `chunk` modes at a time, as
        # many as one point at rest has (stick, slide, flight): fewer chunks of more modes
        # test more modes that do not apply, more of fewer modes cost more passes (measured:
        # docs/contact.md, section 3)
        near = [
            [np.flatnonzero(np.all(~self.active | mask((p, q)), axis=1)) for q in range(P)]
            for p in range(P)
        ]
        size = max(len(g) for g in groups)
        self.chunk = min(max(len(near[p][p]) for p in range(P)), size)
        # every list padded with FLIGHT (the last mode) to the whole chunks of the longest
        whole = lambda n: -(-n // self.chunk)  # noqa: E731
        length = whole(max(size, *(len(g) for row in near for g in row))) * self.chunk

        def pad(g):
            return np.pad(g, (0, length - len(g)), constant_values=len(rows) - 1)

        self.near = np.stack([np.stack([pad(g) for g in row]) for row in near])
        self.near_chunks = np.array([[whole(len(g)) for g in row] for row in near], np.int32)
        self.groups = np.stack([pad(g) for g in groups])
        self.group_chunks = np.array([whole(len(g)) for g in groups], np.int32)

    def __len__(self):
        return len(self.kind)

    def candidates(self, resting) -> tuple[jax.Array, jax.Array]:
        """The modes to test when the points `resting` (P,) rest on the floor: their indices
        (traced, of a fixed length, a whole number of `chunk`s, in the table's order) and
        how many chunks of them to test (the others repeat FLIGHT). No point resting: none
        (FLIGHT is the only mode that applies); one or two: the modes that hold no other
        point; more: the group of the face holding most of them."""
        count = jnp.sum(jnp.asarray(self.group_faces) & resting, axis=1)
        g = jnp.argmax(count)
        group, chunks = jnp.asarray(self.groups)[g], jnp.asarray(self.group_chunks)[g]
        P = resting.shape[0]
        first, last = jnp.argmax(resting), P - 1 - jnp.argmax(resting[::-1])
        near = jnp.asarray(self.near)[first, last]
        near_chunks = jnp.asarray(self.near_chunks)[first, last]
        few = jnp.sum(resting) <= 2
        chunks = jnp.where(few, near_chunks, chunks)
        return jnp.where(few, near, group), jnp.where(jnp.any(resting), chunks, 0)

    def mode(self, i, like: Mode) -> Mode:
        """Candidate `i` (a traced index) as a `Mode`, its seed directions taken from `like`."""
        return Mode(
            kind=jnp.asarray(self.kind)[i],
            a=jnp.asarray(self.a)[i],
            b=jnp.asarray(self.b)[i],
            face=jnp.asarray(self.face)[i],
            stick=jnp.asarray(self.stick)[i],
            slide_dir=like.slide_dir,
            twist_dir=like.twist_dir,
            from_rest=like.from_rest,
            seed=like.seed,
            side=like.side,
            support=jnp.asarray(self.support)[i],
        )


def face_point_masks(model) -> np.ndarray:
    """(max(F, 1), P) mask of each face's points."""
    faces = np.zeros((max(model.num_faces, 1), model.num_points), bool)
    for f, pts in enumerate(model.face_points):
        faces[f, list(pts)] = True
    return faces


def active_points(model, mode: Mode) -> jax.Array:
    """Mask (P,) of the points the mode holds on the floor."""
    idx = jnp.arange(model.num_points, dtype=jnp.int32)
    on_pair = (idx == mode.a) | ((idx == mode.b) & (mode.kind == PAIR))
    on_face = jnp.asarray(face_point_masks(model))[mode.face]
    kind = mode.kind
    return jnp.where(kind == FACE, on_face, jnp.where(kind == FLIGHT, False, on_pair))


class Geometry(eqx.Module):
    """The contact kinematics of a state, world frame: each contact point's surface normal n
    and tangents t1, t2 (P, 3) and their rates (zero on a plane; every point has the same
    frame but on a surface of several parts, where point i has part i's); the rotation R and
    angular velocity w; the contact points' offsets r (P, 3) from the mass centre, their
    rates r' (P, 3), gaps g (P,), gap rates g' (P,) and slips (P, 3); `region`: the
    surface's region margin at the body's centre (see `Mode.side`); `per_point`: whether
    the rows of the frames differ (static)."""

    n: jax.Array
    t1: jax.Array
    t2: jax.Array
    n_dot: jax.Array
    t1_dot: jax.Array
    t2_dot: jax.Array
    R: jax.Array
    w: jax.Array
    r: jax.Array
    r_dot: jax.Array
    gap: jax.Array
    gap_rate: jax.Array
    slip: jax.Array
    region: jax.Array
    per_point: bool = eqx.field(static=True, default=False)

    def tangential(self, x):
        """The parts of vectors x (P, 3), one per contact point, along its surface."""
        return x - jnp.sum(x * self.n, axis=-1, keepdims=True) * self.n

    def frame_of(self, i):
        """(n, t1, t2) of contact point `i`."""
        if not self.per_point:  # one frame for all: no indexing by a traced point
            i = 0
        return self.n[i], self.t1[i], self.t2[i]


def surface_frame(state: State, scene, model, R, w, side=None):
    """The contact frames (n, t1, t2), each (P, 3) (a row per contact point), and their
    rates (world). On a plane they are the plane's; on a curved surface they are taken at
    the ball's centre, c = x + R offset, and differentiated along the centre's velocity
    c' = v + w x (R offset); `side` picks the part of the surface (None: the part the ball
    is over). On a surface of several parts, row i is part i's frame."""
    surface = scene.floor
    dtype = state.pos.dtype
    P = model.num_points
    per_point = lambda frame: tuple(jnp.broadcast_to(e, (P, 3)) for e in frame)  # noqa: E731
    if not surface.curved:
        zero = jnp.zeros(3, dtype)
        return per_point(surface.frame(dtype)), per_point((zero, zero, zero))
    arm = matvec(R, model.offset.astype(dtype))
    centre, centre_vel = state.pos + arm, state.vel + cross(w, arm)
    if surface.parts > 1:
        frames = lambda c: surface.part_frames(c, side)  # noqa: E731
    else:
        frames = lambda c: per_point(surface.frame_at(c, side))  # noqa: E731
    return jax.jvp(frames, (centre,), (centre_vel,))


def point_gaps(surface, points, side=None):
    """Gaps (m) (P,) of world contact `points` (P, 3): above the surface, or on a surface of
    several parts, point i's above part i."""
    if surface.parts > 1:
        return jnp.diagonal(surface.part_gaps(points, side))
    return surface.gap(points, side)


def point_coefficients(scene, model):
    """Friction, rolling and spin resistance (each (P,)) at each contact point: the
    surface's, or on a surface of several parts, that of the part each point touches."""
    surface = scene.floor
    if surface.parts > 1:
        return surface.part_coefficients()
    P = model.num_points
    coefficients = (surface.friction, surface.rolling_resistance, surface.spin_resistance)
    return tuple(jnp.broadcast_to(c, (P,)) for c in coefficients)


def geometry(state: State, scene, model, seed, side=None) -> Geometry:
    """Contact kinematics at `state` (unit quaternion); `side`: the part of a curved surface
    whose geometry is used (a mode's `side`; None: the part the ball is over), so that a
    segment keeps to one part's geometry up to the junction where it ends.

    A contact point p(d) may depend on the surface's normal in the body frame, d = R^T n (a
    support point); then its offset r = R p(d) moves at r' = w x r + R p'(d)[d'], with
    d' = d x omega_body + R^T n' (n' = 0 on a plane), which is zero beyond w x r for a
    corner.
    """
    R = quat_to_matrix(state.quat)
    w = matvec(R, state.omega)
    (n, t1, t2), (n_dot, t1_dot, t2_dot) = surface_frame(state, scene, model, R, w, side)
    # the normal in the body frame: one per part on a surface of several, else the one
    several = scene.floor.parts > 1
    normal, normal_rate = (n, n_dot) if several else (n[0], n_dot[0])
    down, down_rate = vecmat(normal, R), vecmat(normal_rate, R)
    down_dot = cross(down, state.omega) + down_rate
    if model.moving_points:
        p, p_dot = jax.jvp(lambda d: model.points(d, seed), (down,), (down_dot,))
    else:
        p = model.points(down, seed)
        p_dot = jnp.zeros_like(p)
    r = matvec(R, p)
    r_dot = cross(w, r) + matvec(R, p_dot)
    gap = point_gaps(scene.floor, state.pos + r, side)
    vel = state.vel + cross(w, r)
    gap_rate = dot(vel, n)
    slip = vel - gap_rate[:, None] * n
    region = jnp.ones((), state.pos.dtype)
    if scene.floor.curved:
        region = scene.floor.region(state.pos + matvec(R, model.offset.astype(state.pos.dtype)))
    return Geometry(
        n, t1, t2, n_dot, t1_dot, t2_dot, R, w, r, r_dot, gap, gap_rate, slip, region, several
    )


def unit_or(x, fallback):
    """x / |x|, or `fallback` where |x| is (numerically) zero; gradient safe."""
    n = _safe_norm(x, keepdims=True)
    tiny = n <= 1e3 * jnp.finfo(x.dtype).tiny
    return jnp.where(tiny, fallback, x / jnp.where(tiny, 1.0, n))


class Rows(eqx.Module):
    """A mode's constraint rows at a state (6 slots, module docstring).

    Each row (and each force column) is a force direction `d` at offset `r` from the mass
    centre plus a couple `k`: it acts on u = (v, w) as (d, r x d + k).

    - `J`, `C`: (6, 6) rows and force columns (world frame);
    - `bias`: (6,) velocity-product terms: J u' + bias is the rows' acceleration;
    - `vel`: (6,) the rows' velocities J u; `pos`: (6,) position residuals of the holonomic
      rows (gaps, tilts), 0 for the others;
    - `mask`: (6,) used rows; `holonomic`: (6,) used rows that constrain positions;
    - `rho`: the face's friction radius (m); `twist`: the face's slip twist (v.t1, v.t2, rho w.n);
    - `support_map`: (3, 3) the normal forces of a support's three vertices per multiplier of
      slots 0-2 (f = support_map lam[:3]); zero for every other mode.
    """

    J: jax.Array
    C: jax.Array
    bias: jax.Array
    vel: jax.Array
    pos: jax.Array
    mask: jax.Array
    holonomic: jax.Array
    rho: jax.Array
    twist: jax.Array
    support_map: jax.Array


def support_loads(geom, mode, rc):
    """A support's (`Mode.support`) vertices (3,) (point indices; 0 off a support), their
    offsets q (3, 3) from the face's centre `rc` (world), and the map G^-1 (3, 3) from the
    multipliers of the face's rows 0-2 (normal at the centre, tilts about t1 and t2) to the
    vertices' normal forces: sum f = lam_0 and sum f_i (q_i x n) = lam_1 t1 + lam_2 t2, so
    f = G^-1 lam. With three vertices that are not on one line G is invertible; off a
    support the map is zero."""
    n, t1, t2 = geom.frame_of(0)  # a face meets a plane: one frame
    used = on_support(mode)
    vertices = jnp.where(used, mode.support, 0)
    q = geom.r[vertices] - rc
    arms = cross(q, n)  # (3, 3): per vertex
    G = jnp.stack([jnp.ones(3, q.dtype), arms @ t1, arms @ t2])
    G_inv = jnp.where(used, inverse3(jnp.where(used, G, jnp.eye(3, dtype=q.dtype))), 0.0)
    return vertices, q, G_inv


def support_friction(geom, mode, rc, mu, hat_b):
    """A support's (`Mode.support`) vertices' friction, per multiplier of the face's rows 0-2
    (`support_loads`): each vertex's friction -mu_i f_i s_i opposes its own unit slip s_i;
    a vertex starting to slide from rest (`support_vertex_starts`), the direction `hat_b`;
    a pivot's (`on_pivot`) is its own rows'. Returns (G^-1 (3, 3), the friction force
    (3, 3) and its couple about the face's centre (3, 3) per unit of each multiplier,
    world)."""
    vertices, q, G_inv = support_loads(geom, mode, rc)
    own = support_vertex_b(mode)
    slides = ~(own & on_pivot(mode))
    starts = own & support_vertex_starts(mode)
    directions = jnp.where(starts[:, None], hat_b, unit_or(geom.slip[vertices], jnp.zeros_like(q)))
    friction = -jnp.where(slides, mu[vertices], 0.0)[:, None] * directions  # (3, 3)
    force = G_inv.T @ friction  # row k: sum_i G_inv[i, k] F_i
    couple = G_inv.T @ cross(q, friction)
    return G_inv, force, couple


def face_twist(state, geom, model, face):
    """The slip twist (v_c . t1, v_c . t2, rho w . n) of face `face`'s centre, and rho."""
    _, centres, rhos = model.face_frame()
    if not model.num_faces:
        return jnp.zeros(3, state.pos.dtype), jnp.ones((), state.pos.dtype)
    rc = matvec(geom.R, centres[face])
    vc = state.vel + cross(geom.w, rc)
    rho = rhos[face]
    n, t1, t2 = geom.frame_of(0)  # a face meets a plane: one frame
    return jnp.stack([dot(vc, t1), dot(vc, t2), rho * dot(geom.w, n)]), rho


def _with_face_rows(state, geom, mode, hats, mu, scene, model, point_rows, supports=True):
    """The rows of a face mode (normal at the face's centre, tilts about t1 and t2,
    tangential at the centre, spin; a face turning about a vertex, `on_pivot`: tangential
    at the vertex, no spin row), or `point_rows` for the other kinds; `hats`: the sliding
    directions at point b (a support's vertex starting from rest) and of the face's twist;
    `mu` (P,).
    `supports`: whether a support's vertices' friction enters the force columns (static;
    the projections use only the rows)."""
    p_d, p_r, p_rdot, p_dC, p_mask, p_pos = point_rows
    hat_b, hat_f = hats
    dtype = state.pos.dtype
    (n, t1, t2), R, w = geom.frame_of(0), geom.R, geom.w  # a face meets a plane: one frame
    is_face, stick = mode.kind == FACE, mode.stick[0]
    zero, zero3 = jnp.zeros((), dtype), jnp.zeros(3, dtype)
    normals, centres, _ = model.face_frame()
    twist, rho = face_twist(state, geom, model, mode.face)
    nu_w = matvec(R, normals[mode.face])
    rc = matvec(R, centres[mode.face])
    f_d = jnp.stack([n, zero3, zero3, t1, t2, zero3])
    f_k = jnp.stack([zero3, t1, t2, zero3, zero3, n])
    centre_gap = scene.floor.gap(state.pos + rc)
    # d/dt (nu_w . t2) = w . t1 and d/dt (-nu_w . t1) = w . t2 near nu_w = -n
    f_pos = jnp.stack([centre_gap, dot(nu_w, t2), -dot(nu_w, t1), zero, zero, zero])
    # sliding: the limit surface about the centre, or each support vertex's own friction
    if supports and has_supports(model):
        support = on_support(mode)
        support_map, v_force, v_couple = only_where_needed(
            support,
            lambda: support_friction(geom, mode, rc, mu, hat_b),
            lambda: (jnp.zeros((3, 3), dtype),) * 3,
        )
    else:
        support, support_map, v_force, v_couple = False, jnp.zeros((3, 3), dtype), 0.0, 0.0
    slide_force = n - mu[0] * (hat_f[0] * t1 + hat_f[1] * t2)
    slide_couple = -mu[0] * rho * hat_f[2] * n
    f_dC = jnp.concatenate([jnp.where(stick, n, slide_force)[None], f_d[1:]])
    f_kC = jnp.concatenate([jnp.where(stick, zero3, slide_couple)[None], f_k[1:]])
    f_dC = f_dC.at[:3].set(jnp.where(support, f_d[:3] + v_force, f_dC[:3]))
    f_kC = f_kC.at[:3].set(jnp.where(support, f_k[:3] + v_couple, f_kC[:3]))
    # a face turning about a vertex: the tangential rows (slots 3, 4) at that vertex
    pivot = on_pivot(mode)
    r_pivot = jnp.where(pivot, geom.r[mode.b], rc)
    f_r = jnp.stack([rc, rc, rc, r_pivot, r_pivot, rc])
    f_rdot = cross(w, f_r)  # the face's centre and its corners are body points
    f_mask = jnp.stack([is_face] * 3 + [is_face & (stick | pivot)] * 2 + [is_face & stick])
    mask = jnp.where(is_face, f_mask, p_mask)
    holonomic = mask & jnp.where(
        is_face,
        jnp.array([True, True, True, False, False, False]),
        jnp.array([True, True, False, False, False, False]),
    )
    return (
        jnp.where(is_face, f_d, p_d),
        jnp.where(is_face, f_r, p_r),
        jnp.where(is_face, f_rdot, p_rdot),
        jnp.where(is_face, f_k, 0.0),
        jnp.where(is_face, f_dC, p_dC),
        jnp.where(is_face, f_kC, 0.0),
        mask,
        jnp.where(is_face, f_pos, p_pos),
        holonomic,
        twist,
        rho,
        support_map,
    )


def resisting_couple(w, n, mu_r, mu_s, radius, blend):
    """The couple (N m per N of normal force, world) that resists the rolling and spinning
    of a ball of angular velocity `w` (world) at a contact of normal `n`:
    -r (mu_r e_roll + mu_s e_spin n), with e_roll the direction of the angular velocity's
    part along the surface and e_spin the sign of its part about the normal n. Each
    direction is taken of the speed it makes at the ball's surface (r w_t, r w . n) over
    max(that speed, `blend`): below the blend speed (m/s) the couple falls linearly to zero,
    so a ball comes to rest smoothly rather than chattering."""
    w_n = dot(w, n)
    roll = radius * (w - w_n * n)
    spin = radius * w_n
    e_roll = roll / jnp.maximum(_safe_norm(roll), blend)
    e_spin = spin / jnp.maximum(jnp.abs(spin), blend)
    return -radius * (mu_r * e_roll + mu_s * e_spin * n)


def mode_rows(
    state, geom: Geometry, mode: Mode, hats, mu, scene, model, blend=None, supports=True
) -> Rows:
    """The rows of `mode` at `state`; `hats` = (slip direction at a, at b, face twist
    direction) that sliding friction (coefficient `mu`, one per contact point (P,) or one
    for all) opposes (unit, or zero). `blend` (m/s): the speed below which a ball's rolling
    and spin resistance fade (`resisting_couple`); None leaves them, and a support's
    vertices' friction, out of the force columns (for the projections, which use only the
    rows); `supports` False (static) leaves out the latter alone."""
    dtype = state.pos.dtype
    w = geom.w
    mu = jnp.broadcast_to(mu, (model.num_points,))
    kind, stick_a, stick_b = mode.kind, mode.stick[0], mode.stick[1]
    hat_a, hat_b, hat_f = hats
    is_pair = kind == PAIR
    point_like = (kind == POINT) | is_pair

    # points and pairs: normal at a, normal at b, two tangential rows at a, two at b, each
    # in its point's frame; a pair's tangential rows run across and along its line
    ra, rb = geom.r[mode.a], geom.r[mode.b]
    (n_a, t1_a, t2_a), (n_b, t1_b, t2_b) = geom.frame_of(mode.a), geom.frame_of(mode.b)
    normals = jnp.stack([n_a, n_b])
    across = (rb - ra) - dot(rb - ra, normals)[:, None] * normals
    along_a, along_b = unit_or(across, jnp.stack([t1_a, t1_b]))
    e1_a, e2_a = jnp.where(is_pair, cross(n_a, along_a), t1_a), jnp.where(is_pair, along_a, t2_a)
    e1_b, e2_b = jnp.where(is_pair, cross(n_b, along_b), t1_b), jnp.where(is_pair, along_b, t2_b)
    p_d = jnp.stack([n_a, n_b, e1_a, e2_a, e1_b, e2_b])
    p_r = jnp.stack([ra, rb, ra, ra, rb, rb])
    slot_points = jnp.stack([mode.a, mode.b, mode.a, mode.a, mode.b, mode.b])
    p_rdot = geom.r_dot[slot_points]
    zero = jnp.zeros((), dtype)
    p_pos = jnp.stack([geom.gap[mode.a], geom.gap[mode.b], zero, zero, zero, zero])
    p_dC = jnp.concatenate(
        [
            jnp.where(stick_a, n_a, n_a - mu[mode.a] * hat_a)[None],
            jnp.where(stick_b, n_b, n_b - mu[mode.b] * hat_b)[None],
            p_d[2:],
        ]
    )
    p_mask = jnp.stack(
        [
            point_like,
            is_pair,
            point_like & stick_a,
            point_like & stick_a,
            is_pair & stick_b,
            is_pair & stick_b & ~stick_a,
        ]
    )

    if not model.num_faces:  # a shape with no face (a ball): point rows only
        k = kC = jnp.zeros((6, 3), dtype)
        if blend is not None:  # its rolling and spin resistance ride on the normal forces
            _, mu_r, mu_s = point_coefficients(scene, model)
            couple = lambda i, n: resisting_couple(w, n, mu_r[i], mu_s[i], model.radius, blend)  # noqa: E731
            kC = kC.at[0].set(couple(mode.a, n_a)).at[1].set(couple(mode.b, n_b))
        d, r, r_dot, dC, mask, pos = p_d, p_r, p_rdot, p_dC, p_mask, p_pos
        holonomic = mask & jnp.array([True, True, False, False, False, False])
        twist, rho = jnp.zeros(3, dtype), jnp.ones((), dtype)
        support_map = jnp.zeros((3, 3), dtype)
    else:
        d, r, r_dot, k, dC, kC, mask, pos, holonomic, twist, rho, support_map = _with_face_rows(
            state,
            geom,
            mode,
            (hat_b, hat_f),
            mu,
            scene,
            model,
            (p_d, p_r, p_rdot, p_dC, p_mask, p_pos),
            supports=supports and blend is not None,
        )
    J = jnp.concatenate([d, cross(r, d) + k], axis=1)
    C = jnp.concatenate([dC, cross(r, dC) + kC], axis=1)
    point_vel = state.vel + cross(w, r)
    bias = dot(d, cross(w, r_dot))
    if scene.floor.curved:  # a ball's point rows: their directions turn with the frame
        # (a pair's tangential rows turn otherwise than t1, t2, but they are used only
        # while their point sticks, with zero velocity, when the term vanishes)
        g, a, b = geom, mode.a, mode.b
        d_dot = jnp.stack(
            [g.n_dot[a], g.n_dot[b], g.t1_dot[a], g.t2_dot[a], g.t1_dot[b], g.t2_dot[b]]
        )
        bias = bias + dot(d_dot, point_vel)
    return Rows(
        J=J,
        C=C,
        bias=bias,
        vel=dot(d, point_vel) + matvec(k, w),
        pos=pos,
        mask=mask,
        holonomic=holonomic,
        rho=rho,
        twist=twist,
        support_map=support_map,
    )


def inverse_mass_columns(body, R, C):
    """M^-1 C_k for each column row C_k = (force, moment), world frame: (6, 6)."""
    inv_iw = matmul(matmul(R, body.inertia_matrix_inverse), R.T)
    return jnp.concatenate([C[:, :3] / body.mass, matvec(inv_iw, C[:, 3:])], axis=1)


def solve_rows(rows: Rows, minv_C, rhs):
    """lambda with (J M^-1 C) lambda = rhs on the used rows (0 on the others). `solve_mode`
    calls it only off flight (a flight's rows are none: `no_rows`)."""
    A = matmul(rows.J, minv_C.T)
    both = rows.mask[:, None] & rows.mask[None, :]
    A = jnp.where(both, A, jnp.eye(NUM_ROWS, dtype=rhs.dtype))
    lam = small_solve(A, jnp.where(rows.mask, rhs, 0.0))
    return jnp.where(rows.mask, lam, 0.0)


def only_where_needed(needed, compute, otherwise):
    """`compute()` if `needed` holds anywhere, else `otherwise()` (the same structure): for
    work whose result is used only where `needed` is true. The test is taken across a
    vmapped batch (`equinox.internal.unvmap_any`), so the skip holds under `jax.vmap` too:
    where any member needs the work it runs for all, and the others' results are discarded
    by the caller as before."""
    return jax.lax.cond(eqxi.unvmap_any(needed), compute, otherwise)


def tree_where(test, a, b):
    """`a` where `test` holds, else `b`, leaf by leaf (`a`, `b`: the same structure)."""
    return jax.tree.map(lambda x, y: jnp.where(test, x, y), a, b)


def tree_index(tree, i):
    """Entry `i` of every leaf's leading axis."""
    return jax.tree.map(lambda x: x[i], tree)


def tree_zeros(tree):
    """Zeros of the shape and dtype of every leaf of `tree` (arrays or `jax.eval_shape`'s
    shapes): the result of work skipped by `only_where_needed`."""
    return jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), tree)


def blend_direction(slip, start, blend):
    """The direction sliding friction opposes, unit(s + blend s0) (the last axis), for a slip
    s (m/s) whose unit direction at the segment's start was s0 = `start`. Where the slip is
    large against `blend` (m/s) this is the slip's direction; where sliding starts from rest
    it is s0, and in between it turns smoothly."""
    return unit_or(slip + blend * start, start)


def sliding_hats(geom: Geometry, twist, mode: Mode, blend):
    """The directions sliding friction opposes (`blend_direction`) for each slip (points a,
    b; the face's twist), from the mode's unit directions of those slips at the segment's
    start."""
    seeds = jnp.stack([mode.slide_dir[0], mode.slide_dir[1], mode.twist_dir])
    slips = jnp.stack([geom.slip[mode.a], geom.slip[mode.b], twist])
    hat_a, hat_b, hat_f = blend_direction(slips, seeds, blend)
    return hat_a, hat_b, hat_f


class Solution(eqx.Module):
    """A mode's solution at a state: accelerations (world a, alpha; body omega_dot), the
    multipliers `lam` (6,) (N, N m: one per row slot), the rows and the geometry."""

    acc: jax.Array
    alpha: jax.Array
    omega_dot: jax.Array
    lam: jax.Array
    rows: Rows
    geom: Geometry
    hats: tuple

    def point_accelerations(self) -> jax.Array:
        """World accelerations (P, 3) of the contact points (their gaps' and slips' rates)."""
        g = self.geom
        return self.acc + cross(self.alpha, g.r) + cross(g.w, g.r_dot)

    def twist_rate(self, model, face) -> jax.Array:
        """Rate of the face's slip twist."""
        g = self.geom
        _, centres, rhos = model.face_frame()
        if not model.num_faces:
            return jnp.zeros(3, self.acc.dtype)
        rc = matvec(g.R, centres[face])
        ac = self.acc + cross(self.alpha, rc) + cross(g.w, cross(g.w, rc))
        n, t1, t2 = g.frame_of(0)  # a face meets a plane: one frame
        return jnp.stack([dot(ac, t1), dot(ac, t2), rhos[face] * dot(self.alpha, n)])


def solve_mode(
    t, state: State, mode: Mode, scene, model, tol, hats=None, geom=None, supports=True
) -> Solution:
    """Accelerations and contact forces of `mode` at `state` (unit quaternion).

    `tol`: the resolved `Tolerances`; its `stabilisation` beta (1/s) makes constraint
    residuals of the holonomic rows decay like (1 + beta t) exp(-beta t) and slips of sticking
    rows like exp(-beta t) instead of drifting (Baumgarte); on the constraint manifold it has
    no effect. `hats`: the sliding directions (default: `sliding_hats`); `geom`: the state's
    `geometry` if already computed; `supports` (static): False for a mode known not to be a
    support (its friction is then not traced).
    """
    beta = tol.stabilisation
    body = scene.body
    dtype = state.pos.dtype
    if geom is None:
        geom = geometry(state, scene, model, mode.seed, mode.side)
    if hats is None:
        twist, _ = face_twist(state, geom, model, mode.face)
        hats = sliding_hats(geom, twist, mode, tol.slip_blend)
    mu, _, _ = point_coefficients(scene, model)
    acc0, omega_dot0 = accelerations(t, state, scene)
    u0_dot = jnp.concatenate([acc0, matvec(geom.R, omega_dot0)])

    def constrained():  # the rows, their multipliers and the accelerations they add
        rows = mode_rows(state, geom, mode, hats, mu, scene, model, tol.slip_blend, supports)
        b = jnp.asarray(beta, dtype)
        stab = jnp.where(rows.holonomic, 2 * b * rows.vel + b**2 * rows.pos, b * rows.vel)
        minv_C = inverse_mass_columns(body, geom.R, rows.C)
        lam = solve_rows(rows, minv_C, -(matvec(rows.J, u0_dot) + rows.bias + stab))
        return rows, lam, vecmat(lam, minv_C)

    def free():  # in flight: no row (every step's event function and step limit ask)
        return no_rows(dtype), jnp.zeros(NUM_ROWS, dtype), jnp.zeros(6, dtype)

    rows, lam, added = only_where_needed(mode.kind != FLIGHT, constrained, free)
    u_dot = u0_dot + added
    acc, alpha = u_dot[:3], u_dot[3:]
    return Solution(acc, alpha, vecmat(alpha, geom.R), lam, rows, geom, hats)


def no_rows(dtype) -> Rows:
    """The `Rows` of flight: none used (a unit friction radius, so that nothing divides by
    zero)."""
    zeros = jnp.zeros((NUM_ROWS, 6), dtype)
    unused = jnp.zeros(NUM_ROWS, bool)
    zero = jnp.zeros(NUM_ROWS, dtype)
    return Rows(
        J=zeros,
        C=zeros,
        bias=zero,
        vel=zero,
        pos=zero,
        mask=unused,
        holonomic=unused,
        rho=jnp.ones((), dtype),
        twist=jnp.zeros(3, dtype),
        support_map=jnp.zeros((3, 3), dtype),
    )


class SlidingSolver(eqx.Module):
    """A mode's solution as a function of the directions its sliding friction opposes, for
    the searches of a direction in which a contact at rest starts to slide
    (`_select.py`), which try many directions at one state.

    Only the force columns of slots 0-2 depend on the directions (a sliding point's
    normal column n - mu s_hat, a sliding face's force and couple: slots 0 and 1; a
    support's vertex starting from rest: 0-2), and affinely, so the matrix of the rows is
    A(s) = A0 + sum_k u_k(s) e_k^T (k = 0, 1, 2) with A0 the matrix at zero directions.
    With A0^-1 applied once to the right-hand side and to the columns' rates, each
    direction costs a 3 x 3 solve (Sherman-Morrison-Woodbury) instead of a 6 x 6 one: the
    same solution, up to roundoff, as `solve_mode` with those `hats`.
    """

    rows: Rows  # at zero directions
    d_columns: jax.Array  # (3, 3, 6, 6): dC / d(hat j, component c)
    minv_columns: jax.Array  # (6, 6): M^-1 C at zero directions
    d_minv_columns: jax.Array  # (3, 3, 6, 6)
    lam0: jax.Array  # (6,): A0^-1 rhs
    d_lam: jax.Array  # (3, 3, 6, 3): A0^-1 (the rate of columns 0-2 of A)
    u0_dot: jax.Array  # (6,): (a, alpha) from the forces alone
    geom: Geometry

    def __call__(self, hats) -> Solution:
        H = jnp.stack(hats)  # (3, 3): the directions at a, at b, of the face's twist
        Y = jnp.einsum("jc,jcik->ik", H, self.d_lam)  # A0^-1 [u0(s), u1(s), u2(s)]
        # (A0 + U V^T)^-1 rhs = x0 - Y (1 + V^T Y)^-1 V^T x0, with V = [e0, e1, e2]
        S = jnp.eye(3, dtype=Y.dtype) + Y[:3]
        lam = jnp.where(self.rows.mask, self.lam0 - Y @ (inverse3(S) @ self.lam0[:3]), 0.0)
        minv_C = self.minv_columns + jnp.einsum("jc,jcrk->rk", H, self.d_minv_columns)
        u_dot = self.u0_dot + lam @ minv_C
        rows = eqx.tree_at(
            lambda r: r.C,
            self.rows,
            self.rows.C + jnp.einsum("jc,jcrk->rk", H, self.d_columns),
        )
        acc, alpha = u_dot[:3], u_dot[3:]
        return Solution(acc, alpha, self.geom.R.T @ alpha, lam, rows, self.geom, hats)


def column_rates(geom: Geometry, mode: Mode, mu, model, support_map) -> jax.Array:
    """dC / d(hat j, component c) (3, 3, 6, 6) of `mode_rows`' force columns, j over the
    sliding directions (at a, at b, the face's twist): the columns are affine in them, and
    only slot 0 (a sliding point a, or a sliding face) and slot 1 (a sliding point b) move,
    with the friction force -mu s_hat at the point (a face: -mu (s_1 t1 + s_2 t2) at its
    centre, and the couple -mu rho s_3 n; a support's vertices' friction follows their own
    slips, not these directions, but for a vertex b starting from rest, whose friction
    -mu f_b s_b moves slots 0-2 by its load's share of each, (G^-1)_bk: the rows'
    `support_map`). Written out beside `mode_rows`' columns (the derivative of `mode_rows`
    traced a second copy of it into every contact program);
    `test_sliding_solver_equals_the_direct_solve` holds the two equal."""
    dtype = geom.R.dtype
    mu = jnp.broadcast_to(mu, (model.num_points,))
    eye = jnp.eye(3, dtype=dtype)
    is_face = mode.kind == FACE

    def column(r, force, couple=0.0):  # (3, 6): per component c, the column (f, r x f + k)
        return jnp.concatenate([force, cross(r, force) + couple], axis=-1)

    slide_a = jnp.where(~is_face & ~mode.stick[0], -mu[mode.a], 0.0)
    slide_b = jnp.where(~is_face & ~mode.stick[1], -mu[mode.b], 0.0)
    d = jnp.zeros((3, 3, NUM_ROWS, 6), dtype)
    d = d.at[0, :, 0].set(column(geom.r[mode.a], slide_a * eye))
    d = d.at[1, :, 1].set(column(geom.r[mode.b], slide_b * eye))
    if model.num_faces:
        n, t1, t2 = geom.frame_of(0)  # a face meets a plane: one frame
        _, centres, rhos = model.face_frame()
        slide_f = jnp.where(is_face & ~mode.stick[0] & ~on_support(mode), -mu[0], 0.0)
        zero3 = jnp.zeros(3, dtype)
        force = slide_f * jnp.stack([t1, t2, zero3])
        couple = slide_f * jnp.stack([zero3, zero3, rhos[mode.face] * n])
        rc = geom.R @ centres[mode.face]
        d = d.at[2, :, 0].set(column(rc, force, couple))
        if has_supports(model):  # a support's vertex b starting from rest: along hat b
            own = support_vertex_b(mode).astype(dtype)
            share = jnp.where(support_vertex_starts(mode), own @ support_map, 0.0)
            friction = column(geom.r[mode.b], -mu[mode.b] * eye)  # (3, 6): per component
            d = d.at[1, :, :3].add(share[None, :, None] * friction[:, None, :])
    return d


def sliding_solver(t, state: State, mode: Mode, scene, model, tol, geom) -> SlidingSolver:
    """The `SlidingSolver` of `mode` at `state` (unit quaternion), `geom` its geometry."""
    one = jax.tree.map(lambda x: x[None], mode)
    return tree_index(sliding_solvers(t, state, one, scene, model, tol, geom), 0)


def held_and_sliding(t, state: State, mode: Mode, scene, model, tol, geom):
    """(the solution of `mode` made to stick at both of its points, or its face (a
    support whose vertex b starts from rest: at that vertex, a pivot), with no sliding
    direction; the `SlidingSolver` of `mode`) at `state` (unit quaternion), `geom` its
    geometry: both built side by side (`sliding_solvers`), so that the compiled program
    holds the rows and their solve once for the two."""
    stick = jnp.stack([~support_vertex_starts(mode), jnp.array(True)])
    held = eqx.tree_at(lambda m: (m.stick, m.from_rest), mode, (stick, jnp.zeros(2, bool)))
    both = jax.tree.map(lambda x, y: jnp.stack([x, y]), held, mode)
    solvers = sliding_solvers(t, state, both, scene, model, tol, geom)
    zero = jnp.zeros(3, state.pos.dtype)
    return tree_index(solvers, 0)((zero, zero, zero)), tree_index(solvers, 1)


def sliding_solvers(t, state: State, modes: Mode, scene, model, tol, geom) -> SlidingSolver:
    """The `SlidingSolver`s of `modes` (each field with a leading axis, as the result's) at
    `state` (unit quaternion), `geom` its geometry."""
    body = scene.body
    dtype = state.pos.dtype
    mu, _, _ = point_coefficients(scene, model)
    blend = tol.slip_blend
    acc0, omega_dot0 = accelerations(t, state, scene)
    u0_dot = jnp.concatenate([acc0, geom.R @ omega_dot0])
    beta = jnp.asarray(tol.stabilisation, dtype)

    def build(mode):
        zero = jnp.zeros((3, 3), dtype)
        rows = mode_rows(state, geom, mode, (zero[0], zero[1], zero[2]), mu, scene, model, blend)
        d_columns = column_rates(geom, mode, mu, model, rows.support_map)
        minv = lambda C: inverse_mass_columns(body, geom.R, C)  # noqa: E731 (linear in C)
        minv_C = minv(rows.C)
        d_minv = jax.vmap(jax.vmap(minv))(d_columns)
        both = rows.mask[:, None] & rows.mask[None, :]
        A0 = jnp.where(both, rows.J @ minv_C.T, jnp.eye(NUM_ROWS, dtype=dtype))
        # the rates of A's columns 0-2 (the only ones the directions move)
        d_A = jnp.einsum("ix,jckx->jcik", rows.J, d_minv[:, :, :3])  # (3, 3, 6, 3)
        d_A = jnp.where(both[None, None, :, :3], d_A, 0.0)
        stab = jnp.where(rows.holonomic, 2 * beta * rows.vel + beta**2 * rows.pos, beta * rows.vel)
        rhs = jnp.where(rows.mask, -(rows.J @ u0_dot + rows.bias + stab), 0.0)
        right = jnp.concatenate([rhs[:, None], jnp.moveaxis(d_A, 2, 0).reshape(NUM_ROWS, 27)], 1)
        X = small_solve(A0, right)  # (6, 28)
        d_lam = jnp.moveaxis(X[:, 1:].reshape(NUM_ROWS, 3, 3, 3), 0, 2)
        return SlidingSolver(rows, d_columns, minv_C, d_minv, X[:, 0], d_lam, u0_dot, geom)

    return jax.vmap(build)(modes)


def no_derivative(tree):
    """`tree` with no derivative flowing through its float arrays (stopped at the inputs,
    so that no tangent of a computation on them is traced at all)."""
    return jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_inexact_array(x) else x, tree)


def unit_state(y: State) -> State:
    return State(y.pos, quat_normalize(y.quat), y.vel, y.omega)


def flat(y: State) -> jax.Array:
    """A state as one vector (..., 13): pos, quat, vel, omega. A segment's solve runs on it,
    so that diffrax's work per step (each stage's sums, the error norm, the saves, the
    interpolation) is one array's, not four."""
    return jnp.concatenate([y.pos, y.quat, y.vel, y.omega], axis=-1)


def unflat(x: jax.Array) -> State:
    """The `State` of a vector (..., 13) made by `flat`."""
    return State(x[..., 0:3], x[..., 3:7], x[..., 7:10], x[..., 10:13])


def _held_in_flight(flight):
    """For `jax.tree.map` over (held, live) inputs: the held (no derivative) one in flight."""
    return lambda held, live: jnp.where(flight, held, live) if eqx.is_inexact_array(live) else live


def mode_rates(t, x: jax.Array, mode: Mode, scene, model, tol, wanted, of_solution, empty):
    """(d(state)/dt, extra) in `mode` at a flat state `x` (13,) (`flat`): the right-hand
    side of a contact segment, flat, and `of_solution(sol)` of the mode's solution at x
    where `wanted` holds, from the same solve (a segment's values at a step's end,
    `_step_end.py`; no derivative is taken of them), else `empty` (of the same structure).
    In flight the rates are the free body's, and the mode is solved (the contact geometry
    computed) only where `wanted`."""
    flight = mode.kind == FLIGHT

    def solved():  # each branch takes the vector apart itself: XLA fuses it there
        # in flight the solve serves `of_solution` alone: its inputs are held constant
        # there, through a select, so that the rates' derivatives are the free body's and
        # no derivative of the contact geometry reaches x or the scene (a select passes no
        # NaN of the branch it does not take; a product by zero would)
        free_rates = accelerations(t, unit_state(unflat(x)), scene)
        inputs = (x, scene)
        x_used, scene_used = jax.tree.map(
            _held_in_flight(flight),
            no_derivative(inputs),
            inputs,
        )
        sol = solve_mode(t, unit_state(unflat(x_used)), mode, scene_used, model, tol)
        extra = only_where_needed(wanted, lambda: of_solution(sol), lambda: empty)
        acc, omega_dot = tree_where(flight, free_rates, (sol.acc, sol.omega_dot))
        return acc, omega_dot, extra

    def in_flight():
        acc, omega_dot = accelerations(t, unit_state(unflat(x)), scene)
        return acc, omega_dot, empty

    acc, omega_dot, extra = only_where_needed(~flight | wanted, solved, in_flight)
    y = unflat(x)
    rates = flat(State(pos=y.vel, quat=quat_rate(y.quat, y.omega), vel=acc, omega=omega_dot))
    return rates, extra
