"""Convex polyhedra and the regular dice: the hull, mass properties against published closed
forms and a Monte Carlo estimate, face numbers and outcomes, shape offsets, and polyhedral
dice thrown onto the floor with the contact engine, and the candidate modes the contact engine
tests for the points a body rests on."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent
from turning_states import flat_turning_states

import jaxrb
from jaxrb import dice
from jaxrb.contact._features import contact_model
from jaxrb.contact._modes import FLIGHT, CandidateTable

PHI = (1 + 5**0.5) / 2
# published moments of inertia about the centroid (isotropic), per unit mass and edge a = 1,
# and volumes per a^3
MOMENTS = {4: 1 / 20, 6: 1 / 6, 8: 1 / 10, 12: (95 + 39 * 5**0.5) / 300, 20: (3 + 5**0.5) / 20}
VOLUMES = {
    4: 1 / (6 * 2**0.5),
    6: 1.0,
    8: 2**0.5 / 3,
    12: (15 + 7 * 5**0.5) / 4,
    20: 5 * (3 + 5**0.5) / 12,
}
COUNTS = {4: (4, 6, 4), 6: (8, 12, 6), 8: (6, 12, 8), 12: (20, 30, 12), 20: (12, 30, 20)}


@pytest.mark.parametrize("sides", [4, 6, 8, 12, 20])
def test_regular_dice_mass_properties_against_closed_forms(sides):
    edge, mass = 0.013, 0.007
    die = dice.BUILDERS[sides](edge)
    shape = die.shape
    assert (len(shape.vertices), len(shape.edges), len(shape.faces)) == COUNTS[sides]
    lengths = [np.linalg.norm(shape.vertices[i] - shape.vertices[j]) for i, j in shape.edges]
    np.testing.assert_allclose(lengths, edge, rtol=1e-13)
    np.testing.assert_allclose(float(shape.volume), VOLUMES[sides] * edge**3, rtol=1e-13)
    inertia = np.asarray(jaxrb.RigidBody(mass, shape=shape).inertia_matrix)
    np.testing.assert_allclose(
        inertia, MOMENTS[sides] * mass * edge**2 * np.eye(3), rtol=1e-13, atol=1e-13 * edge**2
    )
    np.testing.assert_allclose(np.mean(np.asarray(shape.vertices), axis=0), 0.0, atol=1e-16)


def test_random_hull_against_monte_carlo():
    """Volume, centroid and inertia of a random hull against 4e6 uniform samples (the
    tolerance is 5 standard errors of each Monte Carlo estimate)."""
    rng = np.random.default_rng(7)
    points = rng.normal(size=(25, 3)) * np.array([1.0, 0.6, 0.3]) + np.array([0.5, -0.2, 0.1])
    shape = jaxrb.ConvexPolyhedron(points)
    vertices = np.asarray(shape.vertices)
    normals = np.asarray(shape.face_normals())
    offsets = np.array([n @ vertices[f[0]] for n, f in zip(normals, shape.faces, strict=True)])
    # Euler's formula, and every vertex a point given (moved by the centroid shift)
    assert len(vertices) - len(shape.edges) + len(shape.faces) == 2
    shift = points[np.argmin(points[:, 0])] - vertices[np.argmin(vertices[:, 0])]
    assert np.all(np.min(np.linalg.norm(points[:, None] - (vertices + shift), axis=-1), 0) < 1e-12)

    lo, hi = vertices.min(0), vertices.max(0)
    n = 4_000_000
    x = lo + (hi - lo) * rng.random((n, 3))
    inside = np.all(x @ normals.T <= offsets, axis=1)
    box = np.prod(hi - lo)
    frac = inside.mean()
    volume = box * frac
    assert abs(float(shape.volume) - volume) < 5 * box * np.sqrt(frac * (1 - frac) / n)
    xin = x[inside]
    centroid_se = xin.std(0) / np.sqrt(len(xin))
    assert np.all(np.abs(xin.mean(0)) < 5 * centroid_se)  # the shape is about its centroid
    mass = 2.0
    r2 = np.sum(xin**2, axis=1)
    samples = r2[:, None, None] * np.eye(3) - xin[:, :, None] * xin[:, None, :]
    mc = mass * samples.mean(0)
    se = mass * samples.std(0) / np.sqrt(len(xin))
    inertia = np.asarray(shape.inertia(mass))
    assert np.all(np.abs(inertia - mc) < 5 * se + 1e-12), (inertia - mc) / se


def test_hull_drops_inner_and_edge_points_and_refuses_flat_sets():
    cube = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    extra = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.2, 0.3, -0.1]])
    shape = jaxrb.ConvexPolyhedron(np.concatenate([extra, cube]))
    assert len(shape.vertices) == 8 and len(shape.faces) == 6
    assert all(len(f) == 4 for f in shape.faces)
    np.testing.assert_allclose(float(shape.volume), 8.0, rtol=1e-14)
    with pytest.raises(ValueError, match="one plane"):
        jaxrb.ConvexPolyhedron([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    with pytest.raises(ValueError, match="4 to 200 vertices"):
        jaxrb.ConvexPolyhedron([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="finite"):
        jaxrb.ConvexPolyhedron([[0, 0, np.nan], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match="offset must be finite"):
        jaxrb.ConvexPolyhedron(cube, offset=(0.0, np.inf, 0.0))
    with pytest.raises(ValueError, match="edge must be finite and > 0"):
        dice.d20(-0.01)


@pytest.mark.parametrize("sides", [4, 6, 8, 12, 20])
def test_face_numbers_and_outcomes(sides):
    die = dice.BUILDERS[sides]()
    assert sorted(die.numbers) == list(range(1, sides + 1))
    normals = np.asarray(die.shape.face_normals())
    if sides != 4:  # opposite faces sum to n + 1
        for i, n in enumerate(normals):
            j = int(np.argmin(normals @ n))
            assert die.numbers[i] + die.numbers[j] == sides + 1
    # turn each face to the outcome's direction: the die shows that face's number
    target = np.array([0.0, 0.0, -1.0 if sides == 4 else 1.0])
    quats = []
    for n in normals:
        axis = np.cross(n, target)
        angle = np.arctan2(np.linalg.norm(axis), n @ target)
        axis = axis if np.linalg.norm(axis) > 1e-12 else np.array([1.0, 0.0, 0.0])
        quats.append(jaxrb.axis_angle_to_quat(jnp.asarray(axis), angle))
    quats = jnp.stack(quats)
    np.testing.assert_array_equal(np.asarray(die.outcome(quats)), die.numbers)
    np.testing.assert_allclose(np.asarray(die.face_alignment(quats)), 1.0, atol=1e-14)


def test_offsets_move_support_points_and_contact_points():
    offset = jnp.array([0.001, -0.002, 0.003])
    q = jaxrb.axis_angle_to_quat(jnp.array([0.3, 1.0, -0.2]), 0.9)
    pos = jnp.array([0.1, 0.2, 0.05])
    pairs = [
        (jaxrb.Sphere(0.01), jaxrb.Sphere(0.01, offset)),
        (jaxrb.Box((0.01, 0.02, 0.005)), jaxrb.Box((0.01, 0.02, 0.005), offset)),
        (jaxrb.Cylinder(0.01, 0.002), jaxrb.Cylinder(0.01, 0.002, offset)),
        (dice.d8().shape, dice.d8(offset=offset).shape),
    ]
    down = jaxrb.quat_rotate(jaxrb.quat_conjugate(q), jnp.array([0.0, 0.0, -1.0]))
    for centred, moved in pairs:
        np.testing.assert_allclose(
            moved.support_point(down), centred.support_point(down) + offset, atol=1e-16
        )
        lift = float(jaxrb.quat_rotate(q, offset)[2])
        np.testing.assert_allclose(
            float(moved.floor_distance(pos, q)),
            float(centred.floor_distance(pos, q)) + lift,
            atol=1e-16,
        )
        a, b = contact_model(centred), contact_model(moved)
        seed = jnp.array([1.0, 0.0, 0.0])
        np.testing.assert_allclose(b.points(down, seed), a.points(down, seed) + offset, atol=1e-16)
        np.testing.assert_allclose(b.face_frame()[1], a.face_frame()[1] + offset, atol=1e-16)
        # the uniform solid's inertia about its centre does not depend on the offset
        np.testing.assert_allclose(moved.inertia(1.0), centred.inertia(1.0), atol=0)
    with pytest.raises(ValueError, match="Sphere.offset must be finite"):
        jaxrb.Sphere(0.01, (0.0, np.nan, 0.0))


def test_polyhedron_face_support_regions():
    """The centre-of-pressure margin of a polygonal face is >= 0 exactly inside the polygon:
    for the cube it equals the box's, and for a random hull with faces of several sizes the
    candidate table pads its groups."""
    box = contact_model(jaxrb.Box((0.008, 0.008, 0.008)))
    cube = contact_model(dice.d6().shape)
    rng = np.random.default_rng(3)
    for f, nu in enumerate(np.asarray(cube.normals)):
        g = int(np.argmax(np.asarray(box.normals) @ nu))
        for _ in range(5):
            couple = jnp.asarray(rng.normal(size=3) * 0.01)
            couple = couple - (couple @ nu) * nu  # in the face plane
            np.testing.assert_allclose(
                float(cube.cop_margin(f, 2.0, couple)),
                float(box.cop_margin(g, 2.0, couple)),
                rtol=1e-12,
                atol=1e-15,
            )
    model = contact_model(jaxrb.ConvexPolyhedron(rng.normal(size=(30, 3))))
    sizes = {len(f) for f in model.face_points}
    table = CandidateTable(model)
    assert table.groups.shape[0] == model.num_faces
    if len(sizes) > 1:  # faces of several sizes: smaller groups end in repeated FLIGHT
        assert np.all(table.kind[table.groups[:, -1]] == 0)


def test_candidate_lists_hold_every_mode_that_can_apply():
    """The modes `CandidateTable.candidates` has tested for a set of resting points (the
    chunks it names) include every mode that holds no other point, for every set of one or
    two points and every face's points, of a box, a coin, a ball, the regular dice and a
    random hull; the lists are whole chunks, FLIGHT after the tested ones. With no point
    resting nothing is tested (FLIGHT, the one mode that applies, is taken untested)."""
    rng = np.random.default_rng(5)
    shapes = [
        jaxrb.Box((0.008, 0.006, 0.004)),
        jaxrb.Cylinder(0.012, 0.001),
        jaxrb.Sphere(0.01),
        *(dice.BUILDERS[sides]().shape for sides in (4, 8, 12, 20)),
        jaxrb.ConvexPolyhedron(rng.normal(size=(30, 3))),
    ]
    for shape in shapes:
        model = contact_model(shape)
        table = CandidateTable(model)
        P = model.num_points
        sets = [np.isin(np.arange(P), (p, q)) for p in range(P) for q in range(p, P)]
        sets += [np.isin(np.arange(P), pts) for pts in model.face_points]
        sets.append(np.zeros(P, bool))
        indices, chunks = jax.vmap(table.candidates)(jnp.asarray(np.stack(sets)))
        assert indices.shape[1] % table.chunk == 0
        for resting, listed, n in zip(sets, np.asarray(indices), np.asarray(chunks), strict=True):
            tested, untested = listed[: n * table.chunk], listed[n * table.chunk :]
            applies = np.flatnonzero(np.all(~table.active | resting, axis=1))
            if not resting.any():
                assert n == 0 and list(applies) == [len(table) - 1]
                continue
            assert set(applies) <= set(tested), (type(shape).__name__, np.flatnonzero(resting))
            assert np.all(table.kind[untested] == FLIGHT)
        # fewer modes than a face's group when one or two points rest
        if model.num_faces and len(table.groups) > 1:
            assert int(np.max(table.near_chunks)) < int(np.min(table.group_chunks))


THROWS = 3
VERTEX_AT_REST = (1, 8, 12, 41)  # of the 48 turning states below: see its test


@persistent
def _throw_d12(states0, friction):
    """d12s (edge 9 mm, 5 g; restitution 0.5, friction `friction`) from `states0`, 1.5 s."""
    die = dice.d12()
    ts = jnp.linspace(0.0, 1.5, 151)

    def run(state0, mu):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(0.005, shape=die.shape),
            forces=(jaxrb.Gravity(),),
            floor=jaxrb.Floor(0.5, mu),
        )
        return jaxrb.simulate(scene, state0, ts, throw=False, max_impacts=160)

    return jax.vmap(run)(states0, friction)


def _assert_at_rest_on_a_face(die, batch, mass):
    """Every throw of `batch` successful, never below the floor (1e-9 m), its energy never
    rising beyond the tolerances, and at rest at the end on a face."""
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    log = batch.contact
    lift = mass * 9.81 * 1e-9  # m g contact_tol (docs/contact.md)
    assert np.all(np.asarray(log.max_energy_rise) <= lift)
    assert np.all(np.asarray(log.max_penetration) < 1e-9)
    dist = jax.vmap(jax.vmap(die.shape.floor_distance))(batch.states.pos, batch.states.quat)
    assert float(jnp.min(dist)) > -1e-9
    scene = jaxrb.Scene(jaxrb.RigidBody(mass, shape=die.shape), forces=(jaxrb.Gravity(),))
    energy = np.asarray(jax.vmap(jax.vmap(lambda s: jaxrb.energy(scene, s)))(batch.states))
    assert np.max(np.diff(energy, axis=1)) < 1e-9 * np.max(energy)
    assert np.all(np.asarray(log.kind[:, -1]) == jaxrb.contact.KIND_NAMES.index("face"))
    assert np.max(np.abs(np.asarray(batch.states.vel[:, -1]))) < 1e-8
    assert np.max(np.abs(np.asarray(batch.states.omega[:, -1]))) < 1e-6
    final = batch.states.quat[:, -1]
    np.testing.assert_allclose(np.asarray(die.face_alignment(final)), 1.0, atol=1e-12)
    inradius = min(
        float(n @ die.shape.vertices[f[0]])
        for n, f in zip(die.shape.face_normals(), die.shape.faces, strict=True)
    )
    np.testing.assert_allclose(np.asarray(batch.states.pos[:, -1, 2]), inradius, atol=1e-9)


def test_thrown_d12_settles_on_a_face(getkey):
    """A d12 (pentagonal faces, 20 corners) thrown at random: never below the floor (1e-9 m),
    energy never rises beyond the tolerances, at rest at the end on a face, by the dynamics
    alone (the benchmark `contact_throws --shapes d4,d8,d12,d20` throws hundreds)."""
    omegas = jax.random.normal(getkey(), (THROWS, 3)) * 15.0
    quats = jaxrb.quat_normalize(jax.random.normal(getkey(), (THROWS, 4)))
    vels = jax.random.normal(getkey(), (THROWS, 3)) * 0.5
    states0 = jax.vmap(
        lambda q, v, w: jaxrb.make_state(pos=(0.0, 0.0, 0.1), quat=q, vel=v, omega=w)
    )(quats, vels, omegas)
    batch = _throw_d12(states0, jnp.full(THROWS, 0.3))
    assert np.all(np.asarray(batch.impacts.count) > 3)
    _assert_at_rest_on_a_face(dice.d12(), batch, 0.005)


def test_d12_turning_flat_with_high_friction_comes_to_rest():
    """Four d12s lying flat on a face and turning (1-6 rad/s) with friction 0.92-0.94: the
    face slides on three of its vertices, tips onto an edge and hops, and comes down with a
    vertex of its support at rest, which then starts to slide from rest (docs/contact.md,
    section 2), or lands flat while it slides 50 times faster than it approaches, where the
    impact law's Gauss-Seidel sweeps need not converge and patterns of its slots pushing
    are tried (section 5). Before both no mode or impulse fitted there: 1, 1, 19 and 3
    events took the least inconsistent one (member 41 chattered 16 times in 2.2 us). Now
    every event is consistent, and each die comes to rest on a face."""
    die = dice.d12()
    states = flat_turning_states(contact_model(die.shape), jax.random.key(5), 48)
    friction = jax.random.uniform(jax.random.key(6), (48,), minval=0.75, maxval=0.95)
    which = np.array(VERTEX_AT_REST)
    batch = _throw_d12(jax.tree.map(lambda x: x[which], states), friction[which])
    log = batch.contact
    np.testing.assert_array_equal(np.asarray(log.inconsistent), 0)
    assert not np.any(np.asarray(log.event_inconsistent))
    _assert_at_rest_on_a_face(die, batch, 0.005)


def test_unknown_shape_in_a_floor_scene_is_an_error():
    class Blob(jaxrb.AbstractShape):
        offset: jnp.ndarray

        def __init__(self):
            self.offset = jnp.zeros(3)

        def requirements(self):
            return ()

        def inertia(self, mass):
            return mass * jnp.eye(3)

        def support_point(self, direction):
            return direction

    scene = jaxrb.Scene(
        jaxrb.RigidBody(1.0, shape=Blob()), forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(0.5)
    )
    with pytest.raises(TypeError, match="no contact model for shape Blob"):
        jaxrb.simulate(scene, jaxrb.make_state(pos=(0, 0, 1.0)), jnp.linspace(0.0, 0.1, 3))


def test_scene_files_take_dice_polyhedra_and_offsets():
    from jaxrb._scene_file import SceneFileError, loads_scene

    head = "[simulation]\nt_end = 1.0\n[floor]\nrestitution = 0.5\n[initial]\npos = [0, 0, 0.1]\n"
    spec = loads_scene(head + '[body]\nmass = 0.005\n[body.shape]\ntype = "die"\nsides = 20\n')
    assert isinstance(spec.scene.body.shape, jaxrb.ConvexPolyhedron)
    assert len(spec.scene.body.shape.faces) == 20
    text = (
        head
        + "[body]\nmass = 0.005\ninertia = [1e-7, 1e-7, 1e-7]\n[body.shape]\n"
        + 'type = "polyhedron"\noffset = [0.0, 0.0, 0.001]\n'
        + "vertices = [[0, 0, 0.01], [0.01, 0, -0.01], [-0.01, 0.01, -0.01],"
        + " [-0.01, -0.01, -0.01]]\n"
    )
    shape = loads_scene(text).scene.body.shape
    assert len(shape.faces) == 4
    np.testing.assert_allclose(np.asarray(shape.offset), [0.0, 0.0, 0.001])
    with pytest.raises(SceneFileError, match=r"\[body.shape\].sides: must be one of 4, 6, 8"):
        loads_scene(head + '[body]\nmass = 0.005\n[body.shape]\ntype = "die"\nsides = 7\n')
    flat = "vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]\n"
    with pytest.raises(SceneFileError, match=r"\[body.shape\].vertices: .*one plane"):
        loads_scene(head + '[body]\nmass = 1.0\n[body.shape]\ntype = "polyhedron"\n' + flat)
