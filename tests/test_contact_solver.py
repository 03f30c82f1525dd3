"""The mode selection: its sliding solver (`SlidingSolver`: a mode's solution for any sliding
directions by a 3 x 3 Woodbury update) against the direct 6 x 6 solve, and its choice (the
candidates of the resting points, tested a chunk at a time) against testing every mode."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent
from turning_states import (
    NARROW_BOX,
    first_face_down,
    flat_turning_states,
    narrow_box_on_end,
    narrow_box_scene,
)

import jaxrb
from benchmarks.contact_throws import floor_friction, shape_of, throws
from benchmarks.face_vertex_lcp import vertex_kinematics, vertex_problem
from jaxrb.contact._events import (
    CONE_A,
    CONE_B,
    COP,
    NORMAL_B,
    NUM_FORCE_CONDITIONS,
    SLIP_A,
    condition_tolerances,
    slide_end,
)
from jaxrb.contact._features import contact_model
from jaxrb.contact._modes import (
    FACE,
    PAIR,
    POINT,
    CandidateTable,
    face_twist,
    flight_mode,
    geometry,
    held_and_sliding,
    on_support,
    sliding_solver,
    solve_mode,
)
from jaxrb.contact._resting import resting_points, touching_points
from jaxrb.contact._select import exclusions, relative_accelerations

TOL = jaxrb.contact.ContactOptions().resolved(jnp.float64)


def _scene(shape, mu=0.4):
    body = jaxrb.RigidBody(0.004, shape=shape)
    forces = (jaxrb.Gravity(), jaxrb.QuadraticDrag(0.01))
    return jaxrb.Scene(body, forces=forces, floor=jaxrb.Floor(0.5, mu))


SHAPES = (
    jaxrb.Box((0.008, 0.006, 0.004)),
    jaxrb.Cylinder(0.012, 0.001),
    jaxrb.dice.d12(0.01).shape,
)


def _moving_state(k1, k2):
    """A state 1 cm up (float64), its attitude and velocity random from the keys, turning at
    (3, -2, 5) rad/s: every contact point's gap, gap rate and slip far from zero."""
    quat = jaxrb.quat_normalize(jax.random.normal(k1, (4,)))
    state = jaxrb.make_state(
        pos=(0.0, 0.0, 0.01), quat=quat, vel=jax.random.normal(k2, (3,)), omega=(3.0, -2.0, 5.0)
    )
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), state)


@persistent(static_argnames="which")
def _compare(which, key_data):
    """Every candidate mode of `SHAPES[which]` at one moving state, and every support with
    its first vertex starting to slide from rest, with random unit sliding directions drawn
    from the key (its raw data): (the solver's, the direct solve's) multipliers and
    accelerations, and the multipliers without friction."""
    shape = SHAPES[which]
    key = jax.random.wrap_key_data(key_data)
    scene = _scene(shape)
    model = contact_model(shape)
    table = CandidateTable(model)
    k1, k2, k3 = jax.random.split(key, 3)
    state = _moving_state(k1, k2)
    hats = jax.random.normal(k3, (2 * len(table), 3, 3))
    hats = hats / jnp.linalg.norm(hats, axis=-1, keepdims=True)
    old = flight_mode(jnp.float64)

    def one(i, h, vertex_starts):
        mode = table.mode(i, old)
        # (a support whose first vertex starts from rest: its direction moves slots 0-2)
        starts = vertex_starts & on_support(mode) & ~mode.stick[1]
        mode = eqx.tree_at(
            lambda m: (m.b, m.from_rest),
            mode,
            (jnp.where(starts, mode.support[0], mode.b), jnp.stack([False, starts])),
        )
        geom = geometry(state, scene, model, mode.seed, mode.side)
        h = (h[0], h[1], h[2])
        fast = sliding_solver(0.0, state, mode, scene, model, TOL, geom)(h)
        direct = solve_mode(0.0, state, mode, scene, model, TOL, hats=h, geom=geom)
        zero = jnp.zeros(3, jnp.float64)
        plain = solve_mode(0.0, state, mode, scene, model, TOL, hats=(zero,) * 3, geom=geom)
        # the mode made to stick (a support's vertex starting from rest: as a pivot), built
        # beside the sliding solver, against its direct solve
        held, beside = held_and_sliding(0.0, state, mode, scene, model, TOL, geom)
        stuck = eqx.tree_at(
            lambda m: (m.stick, m.from_rest),
            mode,
            (jnp.stack([~starts, True]), jnp.zeros(2, bool)),
        )
        held_direct = solve_mode(0.0, state, stuck, scene, model, TOL, hats=(zero,) * 3, geom=geom)
        pairs = [
            [(s.lam, s.acc, s.alpha, s.rows.C) for s in (fast, direct)],
            [(s.lam, s.acc, s.alpha, s.rows.J) for s in (held, held_direct)],
            [(s.lam, s.acc, s.alpha) for s in (beside(h), fast)],
        ]
        return pairs, plain.lam

    every = jnp.arange(len(table))
    starts = jnp.arange(2 * len(table)) >= len(table)
    return jax.vmap(one)(jnp.concatenate([every, every]), hats, starts)


def test_sliding_solver_equals_the_direct_solve():
    """For every candidate mode of a box, a coin and a d12 (stick and slide, points, pairs,
    faces, supports, pivots), and every support with a vertex starting from rest, the
    Woodbury update gives the direct solve's contact forces and accelerations to roundoff
    (1e-9 of their scale); so does the mode made to stick that the mode choice builds
    beside the sliding solver (`held_and_sliding`), whose sliding solver is the one built
    alone."""
    key = jax.random.key(3)
    for which in range(len(SHAPES)):
        key, sub = jax.random.split(key)
        pairs, plain = _compare(which, jax.random.key_data(sub))
        direct = pairs[0][1]
        for one, other in pairs:
            for a, b in zip(one, other, strict=True):
                a, b = np.asarray(a), np.asarray(b)
                scale = np.max(np.abs(b)) + 1e-300
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * scale)
        # the directions matter: some candidates' forces differ from those without friction
        change = np.max(np.abs(np.asarray(direct[0]) - np.asarray(plain)))
        assert change > 1e-2 * np.max(np.abs(np.asarray(plain)))


# --------------------------------- the conditions, relative to the stabilisation's targets


@persistent(static_argnames="which")
def _held_point_accelerations(which, key_data):
    """Every point mode (stick and slide) of `SHAPES[which]` at one random state off the
    constraint manifold (gaps, gap rates and slips far from zero): each mode's point a's
    normal and tangential acceleration relative to the stabilisation's targets, whether it
    sticks, the scale of its accelerations and the size of the targets (m/s^2)."""
    shape = SHAPES[which]
    scene = _scene(shape)
    model = contact_model(shape)
    table = CandidateTable(model)
    state = _moving_state(*jax.random.split(jax.random.wrap_key_data(key_data)))
    points = np.flatnonzero(table.kind == POINT)
    old = flight_mode(jnp.float64)

    def one(i):
        mode = table.mode(i, old)
        geom = geometry(state, scene, model, mode.seed, mode.side)
        sol = solve_mode(0.0, state, mode, scene, model, TOL, geom=geom)
        acc = sol.point_accelerations()
        rel = relative_accelerations(acc, geom, TOL.stabilisation)[mode.a]
        n = geom.n[mode.a]
        normal = rel @ n
        drift = jnp.linalg.norm(rel - acc[mode.a])  # the targets' size
        scale = 9.81 + jnp.linalg.norm(acc[mode.a]) + drift
        return normal, jnp.linalg.norm(rel - normal * n), mode.stick[0], scale, drift

    return jax.vmap(one)(jnp.asarray(points))


def test_a_held_points_accelerations_relative_to_the_stabilisation_are_zero():
    """A mode's forces are solved for the stabilisation's targets (the normal acceleration
    -2 beta g' - beta^2 g, a sticking point's slip acceleration -beta s), and the conditions
    of the modes that may follow are tested on the accelerations relative to these
    (`relative_accelerations`): so at a boundary of a mode (a normal force at zero, friction
    at its cone) its successor's condition holds with equality. Here, for every point mode
    of a box and of a coin (its moving rim point) at a state far from the floor's
    constraints, the held point's relative normal acceleration is zero, and a sticking
    point's relative slip acceleration too, to roundoff (1e-12 of their scale)."""
    key = jax.random.key(11)
    for which in (0, 1):
        key, sub = jax.random.split(key)
        normal, tangential, stick, scale, drift = map(
            np.asarray, _held_point_accelerations(which, jax.random.key_data(sub))
        )
        assert stick.any() and (~stick).any()
        np.testing.assert_array_less(np.abs(normal), 1e-12 * scale)
        np.testing.assert_array_less(tangential[stick], 1e-12 * scale[stick])
        assert np.all(drift > 1.0)  # far from the constraints: the targets are not zero


@persistent
def _held_pairs_and_faces(key_data):
    """Every sticking pair and sticking face of `SHAPES[0]` (a box) at one random state off
    the constraint manifold: a pair's ends' relative normal accelerations (2,) and end a's
    relative slip acceleration, a face's relative twist rate (3,: the rate of (v . t1,
    v . t2, rho w . n) at its centre plus beta times that twist), each with its scale."""
    shape = SHAPES[0]
    scene = _scene(shape)
    model = contact_model(shape)
    table = CandidateTable(model)
    state = _moving_state(*jax.random.split(jax.random.wrap_key_data(key_data)))
    beta = TOL.stabilisation
    old = flight_mode(jnp.float64)
    pairs = np.flatnonzero((table.kind == PAIR) & table.stick[:, 0] & table.stick[:, 1])
    faces = np.flatnonzero((table.kind == FACE) & table.stick[:, 0])

    def pair(i):
        mode = table.mode(i, old)
        geom = geometry(state, scene, model, mode.seed, mode.side)
        sol = solve_mode(0.0, state, mode, scene, model, TOL, geom=geom)
        acc = sol.point_accelerations()
        rel = relative_accelerations(acc, geom, beta)
        ends = jnp.stack([mode.a, mode.b])
        normal = jnp.sum(rel[ends] * geom.n[ends], axis=-1)
        slip_a = rel[mode.a] - normal[0] * geom.n[mode.a]
        scale = 9.81 + jnp.max(jnp.linalg.norm(acc[ends], axis=-1))
        return normal, jnp.linalg.norm(slip_a), scale

    def face(i):
        mode = table.mode(i, old)
        geom = geometry(state, scene, model, mode.seed, mode.side)
        sol = solve_mode(0.0, state, mode, scene, model, TOL, geom=geom)
        twist, _ = face_twist(state, geom, model, mode.face)
        rate = sol.twist_rate(model, mode.face)
        return rate + beta * twist, 9.81 + jnp.linalg.norm(rate)

    return jax.vmap(pair)(jnp.asarray(pairs)), jax.vmap(face)(jnp.asarray(faces))


def test_a_held_pairs_and_faces_accelerations_relative_to_the_stabilisation_are_zero():
    """As for points (above): a box's sticking pairs hold both ends' relative normal
    accelerations and end a's relative slip acceleration at zero, and its sticking faces
    their relative twist rate (the conditions of a face that starts to slide from rest
    read it), to roundoff (1e-12 of their scale), at a state far from the constraints."""
    (normal, slip_a, pair_scale), (twist, face_scale) = map(
        lambda t: tuple(map(np.asarray, t)),
        _held_pairs_and_faces(jax.random.key_data(jax.random.key(12))),
    )
    assert len(pair_scale) == 12 and len(face_scale) == 6
    assert np.all(np.abs(normal) < 1e-12 * pair_scale[:, None]), normal
    np.testing.assert_array_less(slip_a, 1e-12 * pair_scale)
    assert np.all(np.abs(twist) < 1e-12 * face_scale[:, None]), twist


@persistent
def _coin_throws(states, restitution, friction):
    """Coins of the throws benchmark (`contact_throws`), their first second, float64,
    tolerance 1e-8."""
    ts = jnp.linspace(0.0, 1.0, 101)

    def run(state0, e, mu):
        body = jaxrb.RigidBody(0.0075, shape=jaxrb.Cylinder(0.012, 0.001))
        scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))
        return jaxrb.simulate(scene, state0, ts, max_impacts=200, throw=False, rtol=1e-8, atol=1e-8)

    return jax.vmap(run)(states, restitution, friction)


def test_a_fast_rolling_coins_slip_starts_with_a_consistent_mode():
    """Throw 258 of `contact_throws.throws(300, 0)`: a coin rolling fast on its rim whose
    friction reaches its cone at 0.7186 and 0.8958 s. Against `force_tol` alone, the slide
    from rest that follows missed its condition by 8.2e-7 and 9.0e-6 m/s^2, against forces
    of 3203 and 2162 per unit mass (2.6e-10 and 4.2e-9 of them: the located event time's
    error), and was taken as the least inconsistent candidate. With the tolerance grown by
    1e-8 of the candidate's forces (`FORCE_TOL_PER_FORCE`), both events have a consistent
    mode. (The same throw three times: the batch of `_coin_throws`' compiled program.)"""
    states, restitution, friction = throws(300, 0)
    pick = lambda x: x[np.array([258, 258, 258])]  # noqa: E731
    batch = _coin_throws(jax.tree.map(pick, states), pick(restitution), pick(friction))
    log = batch.contact
    assert int(batch.result._value[0]) == jaxrb.RESULTS.successful._value
    n = int(log.events[0])
    times = np.asarray(log.event_time[0, 1 : n + 1])
    causes = np.asarray(log.event_cause[0, 1 : n + 1])
    for t in (0.71855867, 0.89576299):
        k = np.argmin(np.abs(times - t))
        assert abs(times[k] - t) < 1e-6, (t, times)
        assert causes[k] == jaxrb.contact.CAUSES.index("slip starts")
    assert int(log.inconsistent[0]) == 0
    assert not np.any(np.asarray(log.event_inconsistent[0, : n + 1]))


def test_coins_lift_off_and_start_to_slip_with_a_consistent_mode():
    """Throws 56, 76 and 81 of `contact_throws.throws(100, 0)`: a coin rolling on its rim
    whose friction reaches its cone (56, twice in its first second) and coins whose rim
    point's normal force reaches zero (76 and 81). Tested on the plain accelerations, the
    mode that follows (sliding from rest, flight) missed its condition by 1e-7 to 1.3e-6
    m/s^2 at these four events, just over `force_tol` (the residual slip and gap rate times
    the stabilisation rate): none was consistent, and the least inconsistent was taken.
    Tested relative to the stabilisation's targets, each event has a consistent mode."""
    states, restitution, friction = throws(100, 0)
    members = np.array([56, 76, 81])
    pick = lambda x: x[members]  # noqa: E731
    batch = _coin_throws(jax.tree.map(pick, states), pick(restitution), pick(friction))
    log = batch.contact
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    causes = [np.asarray(log.event_cause[m, : int(log.events[m])]).tolist() for m in range(3)]
    slip_starts = jaxrb.contact.CAUSES.index("slip starts")
    lift_off = jaxrb.contact.CAUSES.index("lift-off")
    assert causes[0].count(slip_starts) >= 2
    assert lift_off in causes[1] and lift_off in causes[2]
    np.testing.assert_array_equal(np.asarray(log.inconsistent), 0)
    assert not np.any(np.asarray(log.event_inconsistent))


# a coin of `contact_throws` (throw 6 of `throws(60, 0)`) 0.56 s into its throw, rolling on its
# rim at a tilt of about 45 degrees (position m, quaternion, velocity m/s, omega rad/s, body)
ROLLING_COIN = (
    (-0.05722568371659757, -0.1111920876480065, 0.00980944884113742),
    (0.31033287644954044, 0.07295330693247865, 0.9041526642036455, 0.28439282799610094),
    (0.05343685271297912, -0.03058540023765986, -0.0166515346065274),
    (14.892898431640937, -12.531791163854276, 6.356080671478968),
)


def test_a_rolling_coins_brief_slides_from_rest_take_hundreds_of_steps_not_thousands():
    """The rolling coin above, on floors of friction 0.438 (its throw's) and 0.45, for 1 s.
    With 0.45 it rolls throughout. With 0.438 the friction its rolling needs leaves the cone
    every 0.12 s for about 4.6 ms: a slide from rest whose slip stays within a few blend
    speeds, where friction's direction follows the slip at about mu g / blend. With the
    blend speed at a tenth of `slip_stop` those eight slides took 1830 steps each (15307 in
    the second against 683 rolling); with it at `slip_stop`, about 680 (6093)."""
    pos, quat, vel, omega = (jnp.asarray(x) for x in ROLLING_COIN)
    coin = jaxrb.make_state(pos=pos, quat=quat, vel=vel, omega=omega)
    states = jax.tree.map(lambda x: jnp.stack([x] * 3), coin)
    friction = jnp.array([0.4379113542237306, 0.45, 0.45])
    batch = _coin_throws(states, jnp.full(3, 0.39657751143910197), friction)
    log = batch.contact
    assert np.all(np.asarray(batch.result._value) == jaxrb.RESULTS.successful._value)
    np.testing.assert_array_equal(np.asarray(log.inconsistent), 0)
    causes = [
        [jaxrb.contact.CAUSES[int(c)] for c in log.event_cause[m, 1 : int(log.events[m]) + 1]]
        for m in range(2)
    ]
    assert causes[1] == []  # rolls throughout
    assert causes[0] == ["slip starts", "slip stops"] * 8, causes[0]
    steps = np.asarray(batch.num_steps)
    assert steps[1] < 1000, steps
    assert steps[0] - steps[1] < 8 * 1000, steps  # under 1000 steps per slide


# ------------------------------------------------------------ the end of a slide from rest

BLEND = TOL.slip_blend  # m/s
# coin 84 of `contact_throws --n 300`, run with the mode choice of before its conditions were
# taken relative to the stabilisation's targets and without this condition: a rim point's
# slide from rest, 0.7047 s into the throw, whose slip stayed at 5e-7 m/s for 1e5 steps (its
# slip along the start direction and across it, in blend speeds: 1e-6 m/s then)
CREEP = (-0.4886 * BLEND, 0.2084 * BLEND)


def _slips_from_rest(cases):
    """Slips (m/s, world) of a slide that started from rest along x, from rows of (along x,
    along y, whether from rest)."""
    cases = np.asarray(cases, dtype=np.float64)
    return jnp.asarray(np.column_stack([cases[:, :2], np.zeros(len(cases))])), cases[:, 2] > 0


@jax.jit
def _slide_ends(slips, from_rest):
    direction = jnp.array([1.0, 0.0, 0.0])
    return jax.vmap(lambda s, r: slide_end(s, direction, r, TOL))(slips, from_rest)


def test_a_slide_from_rest_ends_when_its_slip_turns_back_or_friction_pushes_it_on():
    """A slide from rest in direction s0 has friction opposing s_f = unit(s + blend s0). It
    ends (its condition falls to zero) when the slip turns back past -blend/2 along s0, or
    when friction pushes the slip on, s . s_f < -0.3 blend (as it held coin 84's slip near
    zero for 1e5 steps, `CREEP`, where the turn-back condition still held). It goes on while
    the slip grows along s0 or turns across it (friction's direction turning with it). Any
    other slide ends at half the stop speed."""
    goes_on = [
        (0.0, 0.0, 1),  # the start
        (0.1 * BLEND, 0.0, 1),
        (BLEND, 0.0, 1),
        (1e3 * BLEND, 0.0, 1),
        (-0.2 * BLEND, 0.0, 1),  # turning back, not yet past -blend/2: s . s_f = -0.2 blend
        (0.0, BLEND, 1),  # across s0: friction turns 45 degrees and opposes it in part
        (0.0, 3.0 * BLEND, 1),  # a large slip turned by 90 degrees
        (0.6 * TOL.slip_stop, 0.0, 0),  # not from rest: above half the stop speed
    ]
    ends = [
        (-0.6 * BLEND, 0.0, 1),  # turned back
        (-0.4 * BLEND, 0.1 * BLEND, 1),  # pushed on: s . s_f = -0.378 blend
        (*CREEP, 1),  # s . s_f = -0.374 blend
        (0.4 * TOL.slip_stop, 0.0, 0),  # not from rest: below half the stop speed
    ]
    values_on = np.asarray(_slide_ends(*_slips_from_rest(goes_on)))
    values_end = np.asarray(_slide_ends(*_slips_from_rest(ends)))
    assert np.all(values_on > 0), values_on
    assert np.all(values_end < 0), values_end
    # it starts above its tolerance (a quarter of the blend speed), so it is not shifted at
    # the start (`start_offsets`) and fires as soon as it falls through zero
    start = values_on[0]
    model = contact_model(SHAPES[1])
    tolerance = condition_tolerances(model, TOL, jnp.float64)[model.num_points + SLIP_A]
    assert start > tolerance, (start, tolerance)
    np.testing.assert_allclose(start, 0.3 * BLEND, rtol=1e-12)
    # where friction pushes the slip on, the slip had not turned back past -blend/2 along s0
    assert CREEP[0] + 0.5 * BLEND > 0 and -0.4 * BLEND + 0.5 * BLEND > 0


# d12 614 of `throws(1000, 1)` (restitution 0.7213, friction 0.7873) at 1.893640411234179 s,
# where a series of ever shorter rocks from vertex 1 to vertex 9 and back ended with vertex 1's
# slip stopping and vertex 9 touching down with a slip just above slip_stop (position m,
# quaternion, velocity m/s, omega rad/s, body)
ROCKING_ONTO_AN_EDGE = (
    (-0.015944900637862573, -0.36949589408214334, 0.010770101239737038),
    (-0.43910702898125176, -0.894572257156564, 0.0831317870012503, -0.0038209704326869444),
    (0.05543244538045575, 0.05715147313299382, -0.03529774810450038),
    (-5.981891296687682, -2.2847800326048184, -3.695410548606192),
)


@persistent
def _d12_throw_from(state0, restitution, friction, ts):
    """The d12 of `contact_throws` from `state0` over the save times `ts` (s), at the
    benchmark's tolerances, with a budget of 5000 steps."""
    scene = _throw_scene("d12", restitution, friction)
    settings = dict(rtol=1e-8, atol=1e-8, max_steps=5000, max_impacts=200)
    return jaxrb.simulate(scene, state0, ts, throw=False, **settings)


def test_a_slide_whose_slip_starts_below_the_stop_speed_ends_at_once():
    """d12 614 of `throws(1000, 1)` came down onto its edge (1, 9) as vertex 1's slip
    stopped and vertex 9's was 1e-5 m/s, just above slip_stop: the edge with end 1 sliding
    from rest and end 9 sliding. The projection onto that mode (both ends' normal
    velocities and end 1's slip held at zero) left end 9's slip at 1e-7 m/s, below half
    the stop speed, where its slip condition starts; shifted by the band's tolerance, it
    could never fire, and friction along a slip of 1e-7 m/s, whose direction is
    roundoff's, held the solver to steps of 2e-8 s: the throw ran out of steps (100000) in
    0.4 ms. Now such a slide ends at once, and the edge sticks at both ends: the die rocks
    about it, its energy conserved."""
    _, restitution, friction = throws(1000, 1)
    state = jaxrb.State(*map(jnp.asarray, ROCKING_ONTO_AN_EDGE))
    state = jaxrb.State(state.pos, jaxrb.quat_normalize(state.quat), state.vel, state.omega)
    ts = jnp.linspace(0.0, 1e-3, 11)
    # (built here first: `shape_of` measures the die eagerly, which it cannot under `jit`)
    scene = _throw_scene("d12", restitution[614], friction[614])
    traj = _d12_throw_from(state, restitution[614], friction[614], ts)
    assert traj.result == jaxrb.RESULTS.successful
    assert int(traj.num_steps) < 100
    log = traj.contact
    assert jaxrb.contact.CAUSES[int(log.event_cause[1])] == "slip stops"
    assert float(log.event_time[1]) < 1e-8
    assert jaxrb.contact.KIND_NAMES[int(log.event_kind[1])] == "pair"
    assert not bool(log.event_sliding[1])
    energy = np.asarray(jax.vmap(lambda s: jaxrb.energy(scene, s))(traj.states))
    assert np.max(np.abs(np.diff(energy))) < 1e-9 * energy[0], energy


# ------------------------------------------------- the mode choice against testing every mode

CHOICE_SHAPES = (jaxrb.Box((0.008, 0.006, 0.004)), jaxrb.dice.d12(0.01).shape)


def _resting_states(model, key, n):
    """`n` states of the shape of `model` resting on the floor (its lowest point at height 0,
    no normal speed there) on its first face, one of that face's edges or one of its
    corners in turn, with random slips and spins, every fourth without any slip (a slide
    would start from rest)."""
    corners = np.asarray(model.corners)
    face = list(model.face_points[0])
    base, world = first_face_down(model)
    a, b = next((a, b) for a, b in model.pairs if a in face and b in face)
    centre = world[face].mean(axis=0)
    # tilt axes (world, horizontal) that lift the face off all but the edge (a, b) or corner a
    edge = (world[b] - world[a]) / np.linalg.norm(world[b] - world[a])
    edge = edge if np.cross(edge, centre - 0.5 * (world[a] + world[b]))[2] > 0 else -edge
    corner = np.cross(centre - world[a], [0.0, 0.0, 1.0])
    corner = corner / np.linalg.norm(corner)
    axes = jnp.asarray(np.stack([edge, edge, corner]))  # (the face's unused)
    support = jnp.arange(n) % 3  # 0 face, 1 edge, 2 corner
    k = jax.random.split(key, 6)
    tilt = jnp.where(support == 0, 0.0, jax.random.uniform(k[0], (n,), minval=0.2, maxval=0.6))
    yaw = jax.random.uniform(k[1], (n,), maxval=2 * np.pi)
    still = (jnp.arange(n) // 3) % 4 == 0
    vxy = jnp.where(still[:, None], 0.0, 0.05 * jax.random.normal(k[2], (n, 2)))
    spin = jnp.where(still, 0.0, 3.0 * jax.random.normal(k[3], (n,)))
    roll = jnp.where(still | (support == 0), 0.0, 2.0 * jax.random.normal(k[4], (n,)))
    wild = jnp.where(((support == 2) & ~still)[:, None], jax.random.normal(k[5], (n, 3)), 0.0)
    up = jnp.array([0.0, 0.0, 1.0])

    def place(s, tilt, yaw, v, spin, roll, wild):
        turn = jaxrb.quat_multiply(
            jaxrb.axis_angle_to_quat(up, yaw), jaxrb.axis_angle_to_quat(axes[s], tilt)
        )
        q = jaxrb.quat_multiply(turn, base)
        R = jaxrb.quat_to_matrix(q)
        r = R @ jnp.asarray(corners[a])  # a point of the support (world, from the centre)
        Y = jaxrb.quat_to_matrix(jaxrb.axis_angle_to_quat(up, yaw))
        w = Y @ (roll * axes[s] + wild) + spin * up
        pos = jnp.array([0.0, 0.0, -r[2]])
        vel = jnp.array([v[0], v[1], -jnp.cross(w, r)[2]])
        return jaxrb.State(pos, q, vel, R.T @ w)

    return jax.vmap(place)(support, tilt, yaw, vxy, spin, roll, wild)


@persistent(static_argnames="which")
def _choices(which, states, friction):
    """The mode `select_mode` chooses (chunks in the table's order, stopping early) and the
    one chosen by testing every mode of the table, for resting states of
    `CHOICE_SHAPES[which]`."""
    from jaxrb.contact._select import _candidate, continued_slides, select_mode

    shape = CHOICE_SHAPES[which]
    model = contact_model(shape)
    table = CandidateTable(model)
    old = flight_mode(jnp.float64)
    trigger = jnp.array(-1)

    def one(state, mu):
        scene = _scene(shape, mu)
        geom = geometry(state, scene, model, old.seed, old.side)
        touching = touching_points(geom, model, old, TOL)
        resting, zero_slip = resting_points(touching, geom, model, TOL)
        args = (0.0, state, geom, old, trigger, scene, model, table, TOL, resting, zero_slip)
        chosen = select_mode(*args)
        # every mode of the table, the first consistent one with no rival taken
        every = jnp.arange(len(table))

        def candidate(i):
            mode = table.mode(i, old)
            continued = continued_slides(mode, old, trigger, zero_slip)
            args = (0.0, state, geom, mode, scene, model, TOL, resting, zero_slip, continued)
            return _candidate(*args, True)

        modes, margins, still, paradox = jax.vmap(candidate)(every)
        admissible = jnp.all(~jnp.asarray(table.active) | resting, axis=1) & still
        excluded = exclusions(table, every, model, old, trigger, zero_slip, resting)[0]
        admissible = admissible & ~excluded
        violation = jnp.max(jnp.maximum(-margins, 0.0), axis=1)
        ok = admissible & (violation <= TOL.force)
        plain = ok & ~paradox
        first = jnp.where(jnp.any(plain), jnp.argmax(plain), jnp.argmax(ok))
        i = jnp.where(jnp.any(ok), first, jnp.argmin(jnp.where(admissible, violation, jnp.inf)))
        reference = jax.tree.map(lambda x: x[i], modes)
        return chosen.mode, chosen.consistent, reference, jnp.any(ok), jnp.sum(resting)

    return jax.vmap(one)(states, friction)


def test_a_lift_off_readmits_the_modes_of_a_point_that_came_down_with_it():
    """An edge of a d12 sliding on both ends, whose end b's normal force reached zero as a
    third corner came down onto the floor (within the event's tolerance: a root that
    another condition's zero lies beside): the modes holding b are excluded, since they
    would re-enter the boundary just crossed; but those that also hold the new corner are
    another contact, whose forces the event did not test, and are readmitted where no
    candidate fits (two d12s of `test_d12_turning_flat_with_high_friction_comes_to_rest`
    had no consistent mode without it). The ended pair itself stays excluded."""
    model = contact_model(jaxrb.dice.d12().shape)
    table = CandidateTable(model)
    P = model.num_points
    every = jnp.arange(len(table))
    kind, active = np.asarray(table.kind), np.asarray(table.active)
    pair = int(np.flatnonzero(kind == PAIR)[0])
    old = table.mode(pair, flight_mode(jnp.float64))
    a, b = int(table.a[pair]), int(table.b[pair])
    # a corner of a face through the edge, other than its ends
    face = next(f for f in model.face_points if a in f and b in f)
    c = next(int(v) for v in face if v not in (a, b))
    resting = np.zeros(P, bool)
    resting[[a, b, c]] = True
    zero_slip = jnp.zeros(P, bool)  # both ends still slide
    trigger = jnp.array(P + 1)  # NORMAL_B
    excluded, readmitted = map(
        np.asarray,
        exclusions(table, every, model, old, trigger, zero_slip, jnp.asarray(resting)),
    )
    holds_b, holds_c = active[:, b], active[:, c]
    np.testing.assert_array_equal(excluded, holds_b)
    np.testing.assert_array_equal(readmitted, holds_b & holds_c)
    assert np.any(readmitted) and not readmitted[pair]
    # without the new corner at rest nothing is readmitted (both ends slide)
    resting[c] = False
    _, readmitted = exclusions(table, every, model, old, trigger, zero_slip, jnp.asarray(resting))
    assert not np.any(np.asarray(readmitted))


def test_mode_choice_equals_testing_every_mode():
    """The mode chosen at an event from the candidates of the resting points, tested a chunk
    at a time until one holds a consistent mode, is the one that testing every mode of the
    table would choose (the first consistent one in the table's order), with its sliding
    directions, for a box and a d12 resting on a face, an edge or a corner, sliding,
    spinning, rocking or still (48 states each, friction 0.1-1)."""
    key = jax.random.key(11)
    for which in range(len(CHOICE_SHAPES)):
        key, k1, k2 = jax.random.split(key, 3)
        friction = jax.random.uniform(k2, (48,), minval=0.1, maxval=1.0)
        states = _resting_states(contact_model(CHOICE_SHAPES[which]), k1, 48)
        chosen, consistent, reference, reference_ok, resting = _choices(which, states, friction)
        # every kind of support was tested (corners, edges, faces of 4 or 5 points)
        assert {1, 2}.issubset(set(np.asarray(resting).tolist()))
        assert int(np.max(resting)) >= 4
        np.testing.assert_array_equal(np.asarray(consistent), np.asarray(reference_ok))
        for a, b in zip(jax.tree.leaves(chosen), jax.tree.leaves(reference), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        # and most states have a consistent mode of contact
        assert np.mean(np.asarray(chosen.kind) != 0) > 0.5


# die 875 of `contact_throws --n 1000` at 0.3142465116 s (position m, quaternion, velocity m/s,
# omega rad/s, body) as the event there left it: on an edge (its points 1 and 5), both ends
# sliding, end 5's normal force had reached zero as end 1's slip fell below slip_stop
EDGE_LIFTS_AS_SLIP_STOPS = (
    (0.051258116927898556, -0.002796369974588031, 0.011083869046289146),
    (-0.16028607861395563, -0.2978783013712541, 0.8286957916841006, 0.4459149867629469),
    (0.057854863771767254, -0.06985575992854219, -0.018470127836288312),
    (-8.140612593761679, 0.04962672788033679, -0.03276168129891336),
)


def _choice_at_event(t, state, scene, old, trigger, slip_may_be_gone=True):
    """`select_mode` for `scene` (a throw of `contact_throws`) at time `t` (s) and `state`
    after the event `trigger` ended the mode `old`; `slip_may_be_gone` (P,) masks which
    points may count as without slip. Returns the choice, the chosen mode's margins
    (m/s^2), the points resting and without slip, and the geometry."""
    from jaxrb.contact._select import _candidate, continued_slides, select_mode

    model = contact_model(scene.body.shape)
    geom = geometry(state, scene, model, old.seed, old.side)
    resting, zero_slip = resting_points(touching_points(geom, model, old, TOL), geom, model, TOL)
    zero_slip = zero_slip & slip_may_be_gone
    table = CandidateTable(model)
    args = (t, state, geom, old, trigger, scene, model, table, TOL, resting, zero_slip)
    chosen = select_mode(*args)
    continued = continued_slides(chosen.mode, old, trigger, zero_slip)
    args = (t, state, geom, chosen.mode, scene, model, TOL, resting, zero_slip, continued)
    tested = _candidate(*args, True)
    return chosen, tested[1], resting, zero_slip, geom


def _throw_scene(kind, restitution, friction):
    """The scene of a throw of `kind` in `contact_throws` on a floor (restitution, friction)."""
    mass, make_shape, _, _ = shape_of(kind)
    body = jaxrb.RigidBody(mass, shape=make_shape())
    return jaxrb.Scene(body, (jaxrb.Gravity(),), floor=jaxrb.Floor(restitution, friction))


@persistent
def _edge_choice(state, restitution, friction, old, trigger, slip_may_be_gone):
    """`_choice_at_event` for the die of `contact_throws` 875 at 0.3142465116295643 s, less
    the geometry."""
    scene = _throw_scene("die", restitution, friction)
    t = 0.3142465116295643
    return _choice_at_event(t, state, scene, old, trigger, slip_may_be_gone)[:4]


def test_an_edge_whose_end_lifts_as_the_other_ends_slip_stops_has_a_consistent_mode():
    """Die 875 of `contact_throws --n 1000` slid on an edge; end 5's normal force reached
    zero as end 1's slip fell below slip_stop. The event's lift-off ruled out every mode
    with end 5, which left end 1 alone (sticking: end 5 would sink at 4.96 m/s^2; sliding
    from rest: at 7.95) or flight: no consistent mode. But with end 1's slip gone the
    pair's modes are other modes than the one whose normal force reached zero: with end 1
    sticking and end 5 sliding the pair holds (every margin > 1 m/s^2). Where end 1 is taken
    to slip still, the lift-off rules the pair out as before."""
    states, restitution, friction = throws(1000, 0)
    e, mu = restitution[875], friction[875]
    pos, quat, vel, omega = map(jnp.asarray, EDGE_LIFTS_AS_SLIP_STOPS)
    state = jaxrb.State(pos, quat, vel, omega)
    old = eqx.tree_at(
        lambda m: (m.kind, m.a, m.b),
        flight_mode(jnp.float64),
        (jnp.array(PAIR, jnp.int32), jnp.array(1, jnp.int32), jnp.array(5, jnp.int32)),
    )
    model = contact_model(shape_of("die")[1]())
    lift_off_b = jnp.array(model.num_points + 1)  # NORMAL_B: end b's normal force
    every = jnp.ones(model.num_points, bool)
    chosen, margins, resting, zero_slip = _edge_choice(state, e, mu, old, lift_off_b, every)
    points = np.arange(model.num_points)
    np.testing.assert_array_equal(np.asarray(resting), np.isin(points, [1, 5]))
    np.testing.assert_array_equal(np.asarray(zero_slip), points == 1)
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, 1, 5)
    assert np.asarray(mode.stick).tolist() == [True, False]
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] > 1.0), margins
    # end 1 counted as still slipping: the pair stays ruled out (end 1 slides on alone)
    chosen, _, _, zero_slip = _edge_choice(state, e, mu, old, lift_off_b, ~every)
    assert not np.any(np.asarray(zero_slip))
    assert (int(chosen.mode.kind), int(chosen.mode.a)) == (POINT, 1)


# d12 69 of `contact_throws --n 300 --shapes d12` at 0.7010875018938936 s (position m,
# quaternion, velocity m/s, omega rad/s, body) as the event there left it: on an edge (its
# points 5 and 9), end 5 sticking and end 9 sliding, end 5's friction had reached the cone
CONE_EDGE_OF_A_PIVOTING_EDGE = (
    (0.03877962500673957, -0.19623262964520216, 0.01084539003753185),
    (0.06592710098750075, 0.9651799407200761, -0.03396583268018705, -0.2508537852959681),
    (0.026516348419317794, -0.1358447352632256, -0.06375012406934585),
    (12.534053671033965, -4.679969709329864, -4.535978218510977),
)


@persistent(static_argnames="kind")
def _die_choice(t, state, restitution, friction, old, trigger, kind="d12"):
    """`_choice_at_event` for a die of `contact_throws` (`kind`, static) at time `t` (s):
    the choice, the chosen mode's margins (m/s^2), the points resting, their gap rates
    (m/s), and the friction (world, N) and normal force (N) at `old`'s ends a and b (a
    pair's; (2, 3) and (2,)) in `old` itself."""
    scene = _throw_scene(kind, restitution, friction)
    chosen, margins, resting, _, geom = _choice_at_event(t, state, scene, old, trigger)
    model = contact_model(scene.body.shape)
    held = solve_mode(t, state, old, scene, model, TOL, geom=geom)
    d, lam = held.rows.J[:, :3], held.lam
    friction = jnp.stack([lam[2] * d[2] + lam[3] * d[3], lam[4] * d[4] + lam[5] * d[5]])
    return chosen, margins, resting, geom.gap_rate, friction, lam[:2]


def _ended_pair(a, b, stick):
    """The pair mode of points `a` and `b` (`stick`: whether each end sticks) as the mode
    an event ended."""
    return eqx.tree_at(
        lambda m: (m.kind, m.a, m.b, m.stick),
        flight_mode(jnp.float64),
        (
            jnp.array(PAIR, jnp.int32),
            jnp.array(a, jnp.int32),
            jnp.array(b, jnp.int32),
            jnp.array(stick),
        ),
    )


def _ended_pair_from_rest(a, b, b_sticks, s0):
    """`_ended_pair` with end a sliding from rest along `s0` (world, unit) and end b
    sticking (`b_sticks`) or sliding."""
    return eqx.tree_at(
        lambda m: (m.from_rest, m.slide_dir),
        _ended_pair(a, b, [False, b_sticks]),
        (jnp.array([True, False]), jnp.array([s0, [0.0, 0.0, 0.0]])),
    )


def _throw_event(kind, n, seed, member, state, old, condition, t):
    """`_die_choice` for the throw `member` of `kind` in `throws(n, seed)` (its floor's
    friction mapped as `contact_throws` maps it) at time `t` (s) and `state` (position,
    quaternion, velocity, omega: body), after the force condition `condition`
    (`_events.py`) of `old` ended a segment; and the throw's scene and state."""
    _, restitution, friction = throws(n, seed)
    e, mu = restitution[member], floor_friction(kind, friction[member])
    scene = _throw_scene(kind, e, mu)
    state = jaxrb.State(*map(jnp.asarray, state))
    trigger = jnp.array(len(contact_model(scene.body.shape).corners) + condition)
    return _die_choice(t, state, e, mu, old, trigger, kind), scene, state


def _d12_event(seed, member, state, old, condition, t):
    """`_throw_event` for the d12 `member` of `throws(1000 if seed else 300, seed)`."""
    return _throw_event("d12", 1000 if seed else 300, seed, member, state, old, condition, t)


def test_a_pivoting_edge_whose_sticking_end_reaches_the_cone_slides_on_from_rest():
    """d12 69 of `contact_throws` pivoted on an edge, end 5 sticking while end 9 slid, until
    end 5's friction reached the cone. The next mode is the edge with end 5 sliding from
    rest, in the direction opposite to the friction it carried, where its slip starts with
    no acceleration at all: the scan of directions finds that root, whose a_t . s is then
    roundoff (-2e-15 m/s^2 here) of either sign. Counted only where a_t . s >= 0, the root
    was refused and the candidate fell back on the direction of both ends sticking, from
    which the fixed point ran to a direction whose slip decelerates (-0.94 m/s^2): no mode
    was consistent."""
    old = _ended_pair(5, 9, [True, False])
    t = 0.7010875018938936
    choice, scene, _ = _d12_event(0, 69, CONE_EDGE_OF_A_PIVOTING_EDGE, old, CONE_A, t)
    chosen, margins, _, _, friction, normal = choice
    mu = scene.floor.friction
    # the event left end 5's friction on the cone's edge
    friction_a, normal_a = np.asarray(friction[0]), float(normal[0])
    assert normal_a > 0
    np.testing.assert_allclose(np.linalg.norm(friction_a), float(mu) * normal_a, rtol=1e-9)
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, 5, 9)
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert np.asarray(mode.from_rest).tolist() == [True, False]
    start = np.asarray(mode.slide_dir[0])
    np.testing.assert_allclose(start, -friction_a / np.linalg.norm(friction_a), atol=1e-9)
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] >= -1e-12), margins


# d12 733 of `throws(1000, 1)`, its mode choices traced (which moves its course at roundoff
# from the benchmark's), at 0.5091903879665312 s (position m, quaternion, velocity m/s, omega
# rad/s, body) as the event there left it: on an edge (its points 6 and 18), end 6 sliding
# and end 18 sticking, end 18's friction had reached the cone
CONE_EDGE_BESIDE_A_LIGHT_END = (
    (-0.01839731692901036, -0.11067778923329409, 0.01060698295354669),
    (-0.9451653891564543, 0.0027113130357976434, -0.31443239646893006, 0.08824570229283656),
    (-0.12926080815694257, -0.018965232292058824, -0.07717895950062478),
    (12.19952257242879, -11.701197260763234, -1.660685855522938),
)


def test_an_edge_end_reaching_its_cone_beside_a_light_end_slides_on_from_rest():
    """d12 733 of `throws(1000, 1)` pivoted on an edge, end 18 sticking while end 6 slid
    carrying a normal force of 0.07 m/s^2 per unit mass, until end 18's friction reached
    the cone. The next mode is the edge with end 18 sliding from rest opposite to that
    friction, with the same forces (the slip starts with no acceleration). Across the scan's
    bracket of that root the light end's force changes sign (its friction turns with end
    18's), and a bracket counted only where the forces were admissible at both of its ends
    (to pass over poles): no root was found, nothing fitted, and the least inconsistent mode
    (end 18 alone, end 6 sinking into the floor) began a chatter of 794 events without a
    consistent mode, every 4e-9 s, to `max_events`. Checked against the edge's contact
    problem solved in numpy (`_vertex_at_rest`)."""
    old = _ended_pair(6, 18, [False, True])
    t = 0.5091903879665312
    choice, scene, state = _d12_event(1, 733, CONE_EDGE_BESIDE_A_LIGHT_END, old, CONE_B, t)
    chosen, margins = choice[:2]
    mu = scene.floor.friction
    corners = np.asarray(contact_model(scene.body.shape).corners)
    # the edge sticking at 18 in numpy: its friction on the cone's edge
    f_stick, F_stick, _, _ = _vertex_at_rest(scene, state, corners, (6, 18), 18)
    np.testing.assert_allclose(np.linalg.norm(F_stick), float(mu) * f_stick[1], rtol=1e-9)
    assert 0 < f_stick[0] < 0.02 * f_stick[1]  # end 6 light
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, 6, 18)
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert np.asarray(mode.from_rest).tolist() == [False, True]
    start = np.asarray(mode.slide_dir[1])
    np.testing.assert_allclose(start, -F_stick / np.linalg.norm(F_stick), atol=1e-6)
    f, _, slip_acc, _ = _vertex_at_rest(scene, state, corners, (6, 18), 18, start)
    np.testing.assert_allclose(f, f_stick, rtol=1e-6)
    assert np.linalg.norm(slip_acc) < 1e-5  # m/s^2, against 9.81 m/s^2 of gravity
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] >= -1e-12), margins


# bar 34 of `contact_throws --n 400 --shapes bar --seed 2` at 0.6786100614604008 s, as the
# event there left it: on a long edge (its points 0 and 2) sliding at 0.16 m/s while turning
# at 13 rad/s about it, end 0 sticking and end 2 sliding at 2 cm/s, end 0's friction had
# reached the cone
CONE_EDGE_OF_A_TURNING_BAR = (
    (0.1486860525822549, 0.10926079120916281, 0.004019143856509701),
    (-0.675678435108257, 0.0005881891159674067, 0.0005391058478592715, 0.7371960497236171),
    (0.025341359731869406, -0.044079857259594755, -0.15340717226789152),
    (0.0038686523659470914, 12.79075090312675, 2.4243507308753314),
)


def test_an_edge_end_whose_slip_accelerates_in_a_narrow_fan_of_directions_starts_in_it():
    """Bar 34 of the seed-2 throws turned about a long edge, end 0 sticking and end 2
    sliding, until end 0's friction reached the cone. End 0 then slides from rest opposite
    to that friction, where its slip starts with no acceleration; but its slip accelerates
    only within a fan of directions narrower than the scan's step (2 pi / 64): at both ends
    of the scan's bracket of that root the slip decelerates, and a bracket counted only
    where it accelerated at an end. No root, and the candidate's fixed point ran to a
    direction whose slip decelerates at 2.9 m/s^2: 15 events without a consistent mode,
    end 0 chattering between sticking and sliding every 1.1e-6 s. A bracket now counts
    where its slip's acceleration along the direction may reach zero within it (its ends'
    less step^2 / 8 of the largest slip acceleration scanned). Checked against the edge's
    contact problem solved in numpy (`_vertex_at_rest`)."""
    old = _ended_pair(0, 2, [True, False])
    t = 0.6786100614604008
    choice, scene, state = _throw_event(
        "bar", 400, 2, 34, CONE_EDGE_OF_A_TURNING_BAR, old, CONE_A, t
    )
    chosen, margins = choice[:2]
    mu = scene.floor.friction
    corners = np.asarray(contact_model(scene.body.shape).corners)
    # the edge sticking at 0 in numpy: its friction on the cone's edge
    f_stick, F_stick, _, _ = _vertex_at_rest(scene, state, corners, (0, 2), 0)
    np.testing.assert_allclose(np.linalg.norm(F_stick), float(mu) * f_stick[0], rtol=1e-9)
    start = -F_stick / np.linalg.norm(F_stick)

    def slip_along(angle):  # end 0 sliding from rest along `start` turned by `angle` (rad)
        c, s = np.cos(angle), np.sin(angle)
        turned = np.array([c * start[0] - s * start[1], s * start[0] + c * start[1], 0.0])
        return _vertex_at_rest(scene, state, corners, (0, 2), 0, turned)[2] @ turned

    # the fan of directions in which the slip accelerates, about 0.084 rad wide (from the
    # start direction on), is narrower than the scan's step of 0.098 rad
    assert abs(slip_along(0.0)) < 1e-12  # m/s^2
    assert slip_along(-0.005) < 0 < slip_along(0.04) and slip_along(0.09) < 0
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, 0, 2)
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert np.asarray(mode.from_rest).tolist() == [True, False]
    np.testing.assert_allclose(np.asarray(mode.slide_dir[0]), start, atol=1e-5)
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] >= -1e-12), margins


# d12 586 of `throws(1000, 1)`, its mode choices traced, at 0.7764385324346504 s, as the event
# there left it: on an edge (its points 7 and 15) at rest to 1e-5 m/s, rocking about it, end 7
# sticking and end 15 sliding, end 7's friction had reached the cone
CONE_EDGE_OF_A_ROCKING_EDGE = (
    (-0.1045971977964378, 0.05717531837842946, 0.010408384975707539),
    (-0.5609324534869617, -0.015232815021526102, -0.7205237119683447, 0.4073921016207544),
    (0.01416405077036097, 0.004286634795714424, 0.00784931835133056),
    (-0.44025918735020864, 0.7105582877484816, -1.1506168730378148),
)


def test_an_edge_end_reaching_its_cone_as_the_other_ends_slip_stops_sticks_at_both():
    """d12 586 of `throws(1000, 1)` rocked about an edge at rest, end 7 sticking and end 15
    sliding (8.5e-6 m/s), until end 7's friction reached its cone as end 15's slip fell
    below slip_stop. The event ruled out every mode with end 7 sticking, which left end 7
    starting from rest (end 15's friction would leave its cone) and both ends from rest
    (their slips would decelerate): no consistent mode, and the die went on chattering
    between the two. But with end 15's slip gone, end 7's friction with end 15 sticking is
    another friction, which the event has not tested (as a lift-off beside a stopped slip):
    the edge sticks at both ends, every margin above 1 m/s^2."""
    old = _ended_pair(7, 15, [True, False])
    t = 0.7764385324346504
    choice, scene, _ = _d12_event(1, 586, CONE_EDGE_OF_A_ROCKING_EDGE, old, CONE_A, t)
    # (end 7's friction is 2.9e-4 beyond its cone solved again at the event's state: end
    # 15's friction turns with its slip of 8.5e-6 m/s)
    _assert_sticks_at_both(choice, scene, (7, 15), 0, 1.0)


def _assert_sticks_at_both(choice, scene, edge, at_cone, least_margin):
    """A choice at an event where the friction of end `at_cone` (0: a, 1: b) of the pair
    `edge` reached its cone: both ends rest, that end's friction is on its cone (to 1e-3),
    and the pair is chosen, consistent, sticking at both ends, every margin above
    `least_margin` (m/s^2)."""
    chosen, margins, resting, _, friction, normal = choice
    mu = float(scene.floor.friction)
    assert np.flatnonzero(np.asarray(resting)).tolist() == list(edge)
    np.testing.assert_allclose(
        np.linalg.norm(np.asarray(friction[at_cone])), mu * float(normal[at_cone]), rtol=1e-3
    )
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, *edge)
    assert np.asarray(mode.stick).tolist() == [True, True]
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] > least_margin), margins


# d12 91 of `throws(1000, 3)` rolling over an edge (18, 19) at 23.5 rad/s as end 19's
# friction reached its cone (position, unit quaternion, velocity: world; omega: body)
CONE_EDGE_BESIDE_A_SLIDE_FROM_REST = (
    (-0.15021935145170304, -0.04616373936354901, 0.01029531609944909),
    (-0.5898110343836004, -0.6275705161129269, -0.32581474384341613, 0.39002941391560586),
    (-0.2403672662274005, 0.025426712115252353, -0.1344620414041397),
    (-0.0002905623872756824, 0.00016164047727564154, 23.47736389845499),
)


def test_an_edge_end_reaching_its_cone_beside_an_end_just_started_from_rest_sticks_at_both():
    """d12 91 of `throws(1000, 3)` rolled over an edge, end 18 sliding from rest (its slip
    3e-6 m/s, below slip_stop) and end 19 sticking, until end 19's friction reached its
    cone. The event ruled out every mode with end 19 sticking, and nothing else fitted (end
    19 from rest: end 18's friction beyond its cone; both from rest: their slips would
    decelerate); the least inconsistent mode was taken and 50 us later the edge chattered
    to `max_events` (800 events in 1.5 us). With end 18 at rest, end 19's friction with
    end 18 sticking is another friction, which the event has not tested (as where the other
    end's slip had stopped): the edge sticks at both ends, every margin above 0.28 m/s^2."""
    old = _ended_pair_from_rest(18, 19, True, [0.2874969912746546, 0.9577815408578415, 0.0])
    t = 0.4709871473748404
    choice, scene, _ = _throw_event(
        "d12", 1000, 3, 91, CONE_EDGE_BESIDE_A_SLIDE_FROM_REST, old, CONE_B, t
    )
    _assert_sticks_at_both(choice, scene, (18, 19), 1, 0.28)


# d12 232 of `throws(1000, 3)` on an edge (3, 17), end 3 sliding from rest, as end 17's
# load reached zero (position, unit quaternion, velocity: world; omega: body)
LIFT_OFF_BESIDE_A_SLIDE_FROM_REST = (
    (-0.16010287963693173, 0.019282564387342424, 0.010259758227114274),
    (-0.12861161267264495, -0.8385020459750385, 0.4620139774165629, -0.25868215362803476),
    (0.13198692015067787, -0.011021289296667713, -0.10212618701705087),
    (-3.656735516930288, -14.485910520501697, -13.230137497851505),
)


def test_a_slide_from_rest_that_goes_on_past_an_event_keeps_its_friction():
    """d12 232 of `throws(1000, 3)`: an edge (3, 17), end 3 sliding from rest (its slip
    grown to 0.02 m/s, friction opposing unit(s + blend s0)) and end 17 sliding, until end
    17's load reached zero. The candidates once took end 3's friction along its slip alone:
    the pair then still loaded end 17 (+3.9e-5 m/s^2) and, end 3 alone, end 17 sank
    (-4.3e-5 m/s^2), both off the boundary the event had found, and no mode fitted. End 3
    goes on sliding, with the same friction law: the pair's load at end 17 and end 3
    alone's gap acceleration at 17 meet at zero, and end 3 alone slides on, consistent."""
    s0 = [-0.8167914656698835, -0.576933013103639, 0.0]
    old = _ended_pair_from_rest(3, 17, False, s0)
    t = 0.7077863576370632
    choice, scene, _ = _throw_event(
        "d12", 1000, 3, 232, LIFT_OFF_BESIDE_A_SLIDE_FROM_REST, old, NORMAL_B, t
    )
    chosen, margins, resting, _, _, normal = choice
    assert np.flatnonzero(np.asarray(resting)).tolist() == [3, 17]
    assert abs(float(normal[1])) < 1e-9 * float(scene.body.mass)  # the boundary (N)
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a)) == (POINT, 3)
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert bool(mode.from_rest[0])
    np.testing.assert_array_equal(np.asarray(mode.slide_dir[0]), s0)
    assert abs(float(margins[17])) < 1e-9  # end 17's gap acceleration (m/s^2): at zero


# a d4 of `throws(300, 0)` (member 201's throw) rolling over an edge (1, 2) at 29.8 rad/s
# as end 2's friction reached its cone (position, unit quaternion, velocity: world; omega:
# body)
CONE_BESIDE_A_SLIDE_TURNING_BACK = (
    (-0.04713353696003685, -0.0039839011916432835, 0.004199763026903945),
    (-0.8764365255838343, -0.20092847993097135, 0.3600877667509769, 0.24864344514074477),
    (-0.12160591302217558, -0.028794972505833804, -0.14227062991794961),
    (21.039575736807276, -21.04018212309196, -0.0003766189021162202),
)


def test_a_slide_from_rest_about_to_turn_back_keeps_its_friction_at_another_event():
    """A d4 on an edge (1, 2), end 1 sliding from rest, its slip (1.03e-5 m/s, just above
    slip_stop) turned almost against its start direction (its condition 1.4e-6 m/s, within
    its tolerance of the turn back), end 2 sticking, until end 2's friction reached its
    cone. End 1 can neither stick (its slip is not at rest) nor slide with its friction
    along its slip alone (54 degrees from the blend's direction; then no mode fits):
    it goes on with its own friction law, and end 2 starts from rest beside it."""
    s0 = [0.552706778031427, -0.8333757960956862, 0.0]
    old = _ended_pair_from_rest(1, 2, True, s0)
    t = 0.20061716654675754
    choice, _, _ = _throw_event("d4", 300, 0, 201, CONE_BESIDE_A_SLIDE_TURNING_BACK, old, CONE_B, t)
    chosen, margins = choice[:2]
    assert bool(chosen.consistent), margins
    mode = chosen.mode
    assert (int(mode.kind), int(mode.a), int(mode.b)) == (PAIR, 1, 2)
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert np.asarray(mode.from_rest).tolist() == [True, True]
    np.testing.assert_array_equal(np.asarray(mode.slide_dir[0]), s0)


# a die of `throws(300, 0)` (member 165's throw) rolling over an edge (3, 7) at 23.7 rad/s
# as end 7's friction reached its cone (position, unit quaternion, velocity: world; omega:
# body)
CONE_BESIDE_A_SLIDE_FROM_REST = (
    (-0.014478228732194308, 0.020000568488706884, 0.009172546462247817),
    (0.5021908266961115, -0.5897479054710711, -0.48152893567135346, 0.4100386148717853),
    (0.21333508251874556, -0.04354448886864721, -0.15721291243624028),
    (23.73734594741318, -0.00022554955081910042, -3.640544302222898e-05),
)


def test_a_slide_from_rest_that_no_event_ended_is_not_stopped_first():
    """A die rolling over an edge (3, 7), end 3 sliding from rest (slip 3.7e-6 m/s, below
    slip_stop) and end 7 sticking, until end 7's friction reached its cone. The first
    consistent mode in the table's order stops end 3 and starts end 7 from rest; then end
    3's friction reaches its cone 0.07 us later, and the ends took turns, each starting from
    rest as the other stuck, up to `max_events` (817 events in 60 us). End 3's slide is not
    what the event ended: a mode that sticks there is tried only where nothing else fits.
    Nothing does (both ends from rest: their slips would decelerate; either end alone: the
    other corner sinks), and the edge sticks at both ends, every margin above 0.48 m/s^2."""
    s0 = [-0.3628851128666587, -0.9318338880185418, 0.0]
    old = _ended_pair_from_rest(3, 7, True, s0)
    t = 0.4658126677612029
    choice, scene, _ = _throw_event(
        "die", 300, 0, 165, CONE_BESIDE_A_SLIDE_FROM_REST, old, CONE_B, t
    )
    _assert_sticks_at_both(choice, scene, (3, 7), 1, 0.48)


# d12s of `contact_throws --n 300` (seed 0) at an event as a vertex's slip stopped: the
# member, the time (s), the state (position, unit quaternion, velocity in the world frame,
# angular velocity in the body frame), the vertex the die slid on, its face's vertices
FACES_COMING_DOWN_ABOUT_A_VERTEX = {
    "d12 248": (
        248,
        1.434229447508761,
        (
            (0.15283519720449026, -0.1458471105790759, 0.01002164753073356),
            (-0.6849346153877226, -0.5095364858162511, -0.4902780374745075, 0.17568320419392158),
            (-1.3272523434535835e-05, 1.2157560374390823e-05, 9.930397344672713e-06),
            (-0.0006485490399038333, -0.0010493743899353117, 0.000400825350031595),
        ),
        4,
        (4, 5, 14, 18, 19),
    ),
    "d12 251": (
        251,
        1.802328510965913,
        (
            (0.07050454362308915, -0.4919951352437769, 0.010021647904730839),
            (-0.40763117174614555, 0.7057986429366752, -0.042991576253351906, -0.577786143673301),
            (-1.2807172761601494e-05, -1.5992334964595912e-05, 1.1832155763218409e-05),
            (2.0609656633677562e-16, -5.2422250276817324e-17, -0.0015455038674873501),
        ),
        15,
        (6, 7, 15, 18, 19),
    ),
}


@pytest.mark.parametrize("throw", sorted(FACES_COMING_DOWN_ABOUT_A_VERTEX))
def test_a_face_whose_far_vertices_rise_slowly_comes_down_flat(throw):
    """A d12 slid on a vertex until its slip stopped, a face of that vertex nearly flat on
    the floor: three of the face's vertices rest, but the two furthest from the pivot rise
    faster than `slip_stop` (d12 248: both within `contact_tol`; d12 251: 1.1e-9 m up,
    just beyond it). A rigid face's gaps and normal velocities are affine functions of the
    point, so three vertices within the tolerances of rest leave the others within
    `face_reach` times them (2 + sqrt(5) on a regular pentagon). Counted as resting with
    the rest of their face, the face's sticking mode is consistent; without them no mode
    was (the pivot alone let the face's other vertices sink at 1.9 m/s^2)."""
    member, t, state, pivot, face_points = FACES_COMING_DOWN_ABOUT_A_VERTEX[throw]
    _, restitution, friction = throws(300, 0)
    state = jaxrb.State(*map(jnp.asarray, state))
    state = eqx.tree_at(lambda s: s.quat, state, state.quat / jnp.linalg.norm(state.quat))
    at_pivot = jnp.array(pivot, jnp.int32)
    old = eqx.tree_at(
        lambda m: (m.kind, m.a, m.b),
        flight_mode(jnp.float64),
        (jnp.array(POINT, jnp.int32), at_pivot, at_pivot),
    )
    model = contact_model(shape_of("d12")[1]())
    slip_a = jnp.array(model.num_points + SLIP_A)
    chosen, margins, resting, gap_rate, _, _ = _die_choice(
        t, state, restitution[member], friction[member], old, slip_a
    )
    face = [sorted(points) for points in model.face_points].index(list(face_points))
    on_face = np.isin(np.arange(model.num_points), face_points)
    np.testing.assert_array_equal(np.asarray(resting), on_face)
    rising = np.abs(np.asarray(gap_rate))[on_face] > TOL.slip_stop
    assert 1 <= rising.sum() <= len(face_points) - 3  # what the face's rule is for
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert (int(mode.kind), int(mode.face)) == (FACE, face)
    assert bool(mode.stick[0])
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] >= -1e-12), margins


def _vertex_at_rest(scene, state, corners, support, b, start=None):
    """A die on the floor (normal +z) held by its vertices `support` (indices into
    `corners`, body-frame offsets from the mass centre, m: a face's three, an edge's two),
    one of which, `b`, has no slip, solved here in world coordinates independently of the
    engine: the vertices' normal forces f (N) hold their normal accelerations at zero, each
    vertex but b has Coulomb friction -mu f_i along its own unit slip, and vertex b either
    starts to slide from rest along the unit vector `start` (friction -mu f_b start) or,
    with `start` None, sticks: its friction force F (N, world) holds its slip's acceleration
    at the stabilisation's target, a_t = -beta s_b (docs/contact.md, section 3). Returns (f,
    F, b's slip acceleration relative to that target, a_t + beta s_b (m/s^2, world), every
    corner's normal acceleration (m/s^2))."""
    body, mu = scene.body, float(scene.floor.friction)
    inertia, w, r, slip = vertex_kinematics(scene, state, corners)
    n = np.array([0.0, 0.0, 1.0])
    sticks = start is None
    held = len(support)
    directions = {i: slip[i] / np.linalg.norm(slip[i]) for i in support if i != b}
    directions[b] = np.zeros(3) if sticks else np.asarray(start)

    def accelerations(x):  # the points' accelerations (P, 3) for unknowns x: f, then F
        forces = [(i, x[k] * (n - mu * directions[i])) for k, i in enumerate(support)]
        if sticks:
            forces.append((b, np.array([x[held], x[held + 1], 0.0])))
        a = np.array([0.0, 0.0, -9.81]) + sum(f for _, f in forces) / float(body.mass)
        torque = sum(np.cross(r[i], f) for i, f in forces) - np.cross(w, inertia @ w)
        alpha = np.linalg.solve(inertia, torque)
        return a + np.cross(alpha, r) + np.cross(w, np.cross(w, r))

    def conditions(x):  # the normal accelerations of the support; a sticking b's slip's
        acc = accelerations(x)
        normal = acc[list(support), 2]
        return np.concatenate([normal, acc[b, :2] + 20.0 * slip[b, :2]]) if sticks else normal

    size = held + 2 if sticks else held
    base = conditions(np.zeros(size))  # the conditions are affine in the unknowns
    A = np.stack([conditions(e) - base for e in np.eye(size)], axis=1)
    x = np.linalg.solve(A, -base)
    f = x[:held]
    F = np.array([x[held], x[held + 1], 0.0]) if sticks else -mu * f[list(support).index(b)] * start
    acc = accelerations(x)
    relative = acc[b] + TOL.stabilisation * slip[b]
    return f, F, relative - (relative @ n) * n, acc[:, 2]


def _assert_starts_from_rest(chosen, margins, scene, state, vertex, mass):
    """The chosen mode is a support of the face whose vertex `vertex` starts to slide from
    rest, along a direction in which its slip accelerates (`_vertex_at_rest`), with the
    normal forces and margins the engine reports."""
    P = len(contact_model(scene.body.shape).corners)
    mode = chosen.mode
    assert bool(chosen.consistent)
    assert int(mode.kind) == FACE and int(mode.b) == vertex
    support = np.asarray(mode.support).tolist()
    assert vertex in support
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert bool(mode.from_rest[1])
    start = np.asarray(mode.slide_dir[1])
    corners = np.asarray(contact_model(scene.body.shape).corners)
    f, _, slip_acc, _ = _vertex_at_rest(scene, state, corners, support, vertex, start)
    along = slip_acc @ start
    across = np.cross(start, slip_acc)[2]
    assert along > 0 and abs(across) <= 1e-12 * along, (along, across)
    assert np.all(f >= 0)
    np.testing.assert_allclose(float(margins[P + COP]), f.min() / mass, rtol=1e-9)
    np.testing.assert_allclose(float(margins[P + NUM_FORCE_CONDITIONS + 1]), along, rtol=1e-9)
    used = np.abs(np.asarray(margins)) < 1e29
    assert np.all(np.asarray(margins)[used] >= -1e-12), margins


# a d12 of the turning states (`flat_turning_states`, key 5, member 41, friction
# 0.94415513...) as the slip of vertex 16 stopped, the face sliding on vertices 0, 1, 16:
# time (s), position, unit quaternion, velocity (world), angular velocity (body)
SUPPORT_VERTEX_STOPS = (
    0.004772832187875391,
    (-1.251322870498424e-05, -1.8077837352727175e-05, 0.010021647279704463),
    (0.566348034752144, 0.6578945972161324, -0.25918082288977906, 0.42337914867454696),
    (-8.688444868886096e-05, -0.00022612568805480983, 1.3974105195601398e-13),
    (-0.02745336353503959, -0.016967111770161632, -2.0415079885322694e-16),
)


def test_a_support_vertex_whose_slip_stops_starts_to_slide_from_rest():
    """A d12 sliding flat on three vertices of a face (friction 0.944) until vertex 16's
    slip stopped. No mode with that vertex sticking fits (on every support of it a vertex
    would pull, or its friction would leave the cone), and the supports with all three
    sliding need its slip. The next mode is a support with vertex 16 starting to slide
    from rest along the direction its slip then accelerates in, found by the scan of
    directions: checked against the vertices' contact problem solved here. Before this mode
    no candidate fitted, and the least inconsistent one chattered 16 times in 2.2 us."""
    t, *state = SUPPORT_VERTEX_STOPS
    state = jaxrb.State(*map(jnp.asarray, state))
    state = eqx.tree_at(lambda s: s.quat, state, state.quat / jnp.linalg.norm(state.quat))
    mu = 0.9441551327475222
    model = contact_model(shape_of("d12")[1]())
    old = eqx.tree_at(
        lambda m: (m.kind, m.support),
        flight_mode(jnp.float64),
        (jnp.array(FACE, jnp.int32), jnp.array([0, 1, 16], jnp.int32)),
    )
    slip_a = jnp.array(model.num_points + SLIP_A)
    chosen, margins, resting, _, _, _ = _die_choice(t, state, 0.5, mu, old, slip_a)
    assert np.flatnonzero(np.asarray(resting)).tolist() == [0, 1, 12, 16, 17]
    scene = _throw_scene("d12", 0.5, mu)
    plain = jax.tree.map(np.asarray, state)
    _assert_starts_from_rest(chosen, margins, scene, plain, 16, float(scene.body.mass))


@pytest.mark.parametrize("spin", [1.0, 20.0])
def test_a_face_turning_about_a_vertex_pivots_until_the_vertex_cannot_hold_it(spin):
    """A d20 flat on a face, turning about one of its vertices at `spin` rad/s (friction
    0.5). Slowly (1 rad/s) the vertex sticks, a pivot whose friction stays inside its cone
    while the face's two other vertices of a support slide; fast (20 rad/s) the
    centripetal force the pivot would need leaves the cone on every support of it, and the
    vertex starts to slide from rest. Both checked against the vertices' contact problem
    solved here."""
    model = contact_model(shape_of("d20")[1]())
    face = sorted(model.face_points[0])
    base, world = first_face_down(model)
    vertex = face[0]
    up = np.array([0.0, 0.0, 1.0])
    w = spin * up
    state = jaxrb.State(
        jnp.array([0.0, 0.0, -np.min(world[:, 2])]),
        base,
        jnp.asarray(np.cross(w, -world[vertex])),
        jaxrb.quat_to_matrix(base).T @ jnp.asarray(w),
    )
    mu = 0.5
    chosen, margins, resting, _, _, _ = _die_choice(
        0.0, state, 0.5, mu, flight_mode(jnp.float64), jnp.array(-1), kind="d20"
    )
    assert np.flatnonzero(np.asarray(resting)).tolist() == face
    scene = _throw_scene("d20", 0.5, mu)
    mass = float(scene.body.mass)
    plain = jax.tree.map(np.asarray, state)
    corners = np.asarray(model.corners)
    # the vertex as a pivot on the face's only support (a triangle: its three vertices)
    f, F, _, _ = _vertex_at_rest(scene, plain, corners, face, vertex)
    cone = mu * f[face.index(vertex)] - np.linalg.norm(F)
    if spin < 10:
        mode = chosen.mode
        assert bool(chosen.consistent) and int(mode.kind) == FACE
        assert np.asarray(mode.support).tolist() == face and int(mode.b) == vertex
        assert np.asarray(mode.stick).tolist() == [False, True]
        assert np.all(f >= 0) and cone > 0
        P = model.num_points
        np.testing.assert_allclose(float(margins[P + COP]), f.min() / mass, rtol=1e-9)
        np.testing.assert_allclose(float(margins[P + CONE_B]), cone / mass, rtol=1e-9)
        used = np.abs(np.asarray(margins)) < 1e29
        assert np.all(np.asarray(margins)[used] >= -1e-12), margins
    else:
        assert cone < 0  # no pivot can hold it
        _assert_starts_from_rest(chosen, margins, scene, plain, vertex, mass)


@persistent
def _narrow_box_choice(state, friction):
    """The mode `NARROW_BOX` takes at the start, at `state`: the choice, its margins
    (m/s^2), the points resting."""
    scene = narrow_box_scene(friction)
    return _choice_at_event(0.0, state, scene, flight_mode(jnp.float64), jnp.array(-1))[:3]


def test_a_face_tipping_onto_an_edge_starts_its_corner_at_rest_in_an_admissible_direction():
    """The narrow box on its end, turning about a corner at 1 rad/s with friction 1.5: no mode
    of the face fits (sliding, the friction at its base tips it), and it tips onto an edge
    through that corner, the corner starting to slide from rest while the edge's other end
    slides on. Scanned round the circle, the corner's slip turns back through a pole as well
    as through roots: near the direction in which the edge's contact problem is singular
    the forces change sign through infinity, and the slip's acceleration along the
    direction is the largest there. A bracket counts only where the forces are admissible
    at both of its ends; checked against the edge's contact problem solved here: the normal
    forces push, the corner's slip accelerates along the direction found, the end face's
    other two corners rise."""
    state, corner = narrow_box_on_end(1.0)
    mu = 1.5
    chosen, margins, resting = _narrow_box_choice(state, mu)
    model = contact_model(NARROW_BOX)
    face = sorted(int(i) for i in model.face_points[0])
    assert np.flatnonzero(np.asarray(resting)).tolist() == face
    assert bool(chosen.consistent)
    mode = chosen.mode
    assert int(mode.kind) == PAIR and int(mode.a) == corner and int(mode.b) in face
    assert np.asarray(mode.stick).tolist() == [False, False]
    assert np.asarray(mode.from_rest).tolist() == [True, False]
    scene = narrow_box_scene(mu)
    plain = jax.tree.map(np.asarray, state)
    edge = [corner, int(mode.b)]
    start = np.asarray(mode.slide_dir[0])
    corners = np.asarray(model.corners)
    f, _, slip_acc, normal = _vertex_at_rest(scene, plain, corners, edge, corner, start)
    along = slip_acc @ start
    across = np.cross(start, slip_acc)[2]
    assert np.all(f > 0) and along > 0 and abs(across) <= 1e-12 * along, (f, along, across)
    others = [i for i in face if i not in edge]
    assert np.all(normal[others] > 1.0), normal[others]  # m/s^2: they rise
    mass = float(scene.body.mass)
    P = model.num_points
    np.testing.assert_allclose(np.asarray(margins[P : P + 2]), f / mass, rtol=1e-9)
    np.testing.assert_allclose(float(margins[P + NUM_FORCE_CONDITIONS]), along, rtol=1e-9)


def test_a_shape_without_pairs_has_no_pair_search_in_its_program(monkeypatch):
    """A candidate's sliding directions from rest are searched for a pair's ends only where
    the shape has pairs: a ball on one surface (no pair modes) traces no pair search, a box
    does (each candidate traced, not run)."""
    import jaxrb.contact._select as select

    searched = []
    real = select._pair_directions
    monkeypatch.setattr(
        select, "_pair_directions", lambda *args: searched.append(True) or real(*args)
    )
    for shape, pairs in ((jaxrb.Sphere(0.01), False), (CHOICE_SHAPES[0], True)):
        model = contact_model(shape)
        assert bool(model.pairs) == pairs
        old = flight_mode(jnp.float64)
        state = jaxrb.make_state(pos=[0.0, 0.0, 0.01])
        scene = _scene(shape)
        geom = geometry(state, scene, model, old.seed, old.side)
        resting = jnp.ones(model.num_points, bool)
        candidate = CandidateTable(model).mode(0, old)
        searched.clear()
        continued = (jnp.zeros(2, bool), jnp.zeros((2, 3)))  # no slide goes on
        args = (0.0, state, geom, candidate, scene, model, TOL, resting, resting, continued)
        eqx.filter_eval_shape(select._candidate, *args, True)
        assert searched == ([True] if pairs else [])


# ------------------------------------- a face that slides on three of its vertices (a support)


@persistent
def _support_forces(states, friction, support):
    """The normal forces (N) of the `support` vertices (n, 3) of a d12's first face in the
    sliding face mode on them, from the mode's multipliers."""
    shape = CHOICE_SHAPES[1]
    model = contact_model(shape)
    table = CandidateTable(model)

    def one(state, mu, support):
        plain = ~jnp.asarray(table.stick)[:, 1]  # all three vertices sliding, no pivot
        i = jnp.argmax(jnp.all(jnp.asarray(table.support) == support, axis=1) & plain)
        mode = table.mode(i, flight_mode(jnp.float64))
        sol = solve_mode(0.0, state, mode, _scene(shape, mu), model, TOL)
        return sol.rows.support_map @ sol.lam[:3]

    return jax.vmap(one)(states, friction, support)


def test_a_face_that_cannot_slide_flat_on_its_limit_surface_slides_on_three_vertices():
    """A d12 turning flat on a face with friction 0.75-0.95: above 0.62 the centre of
    pressure of a face sliding with its limit surface can fall outside the face (a
    pentagon's inradius is 0.62 of the body's), and then no mode of the face's limit
    surface, an edge or a corner may fit (17 of these 48 states before the face could
    slide on a support). Each state's mode is consistent; where the face slides on three of
    its vertices, each with its own friction, their normal forces are those of the
    vertices' own complementarity problem, solved independently (a = A f + b = 0 on those
    three, f >= 0; to 1e-9 of the weight), and the face's other two vertices stay on the
    floor (zero normal acceleration, no force)."""
    model = contact_model(CHOICE_SHAPES[1])
    states = flat_turning_states(model, jax.random.key(5), 48)
    friction = jax.random.uniform(jax.random.key(6), (48,), minval=0.75, maxval=0.95)
    chosen, consistent, _, _, resting = _choices(1, states, friction)
    assert np.all(np.asarray(resting) == 5)  # the whole pentagon touches
    assert np.all(np.asarray(consistent))
    on_support = np.asarray(chosen.support[:, 0]) >= 0
    assert np.all(np.asarray(chosen.kind)[on_support] == FACE)
    assert not np.any(np.asarray(chosen.stick)[on_support, 1])  # no vertex at rest here
    assert on_support.sum() >= 10, on_support.sum()
    forces = np.asarray(_support_forces(states, friction, chosen.support))
    face = list(model.face_points[0])
    corners = np.asarray(model.corners)
    weight = 0.004 * 9.81
    for m in np.flatnonzero(on_support):
        state = jax.tree.map(lambda x, m=m: np.asarray(x[m]), states)
        scene = _scene(CHOICE_SHAPES[1], float(friction[m]))
        support = list(np.asarray(chosen.support[m]))
        A, b, _ = vertex_problem(scene, state, corners[face])
        on = [face.index(p) for p in support]
        f = np.linalg.solve(A[np.ix_(on, on)], -b[on])
        assert np.all(f >= -1e-9 * weight)
        np.testing.assert_allclose(forces[m], f, rtol=0, atol=1e-9 * weight)
        full = np.zeros(len(face))
        full[on] = f
        np.testing.assert_allclose(A @ full + b, 0.0, atol=1e-9 * 9.81)
