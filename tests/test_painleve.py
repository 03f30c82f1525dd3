"""The Painlevé paradox: a rod sliding on one end with large Coulomb friction.

A rod of half-length L (mass m, moment of inertia I = m L^2 / 3 about its centre) touches
the floor with its lower end A and leans at the angle theta to it, its centre G on the +x
side of A. While A slides with velocity u along x (s = sign u), the normal force N is fixed
by keeping A on the floor (Génot & Brogliato 1999, in their notation N = -m b / A):

    A(theta) = 1 + (m L^2 / I) cos(theta) (cos(theta) + s mu sin(theta)),
    b = L theta'^2 sin(theta) - g      (A's normal acceleration without contact force).

With A > 0 sliding is consistent (N >= 0 when b <= 0, lift-off when b > 0). With A < 0
(s = -1 and mu above 4/3, the least at tan(theta) = 2) there is no solution when b < 0 and
two (N = 0 and N = -m b / A) when b > 0. jaxrb stops the run in the first case
(`RESULTS.painleve_paradox`) and lets the end lift off in the second, counting it
(`ContactLog.ambiguous`). In the consistent region the simulated motion is checked against
the planar equations above, integrated by scipy.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent
from scipy.integrate import solve_ivp
from turning_states import NARROW_BOX, narrow_box_on_end, narrow_box_scene

import jaxrb
from benchmarks.face_vertex_lcp import vertex_problem
from jaxrb.contact import contact_model

L, W, M, G = 0.5, 0.01, 1.0, 9.81
I_ROD = M * L**2 / 3
T_END, SAVES = 0.05, 26
STEEP = float(np.arctan(2.0))  # where A is smallest for s = -1

# (mu, theta, u, theta'): three consistent slides, two with no solution, one with two
CASES = {
    "consistent, sliding towards G's side": (2.0, STEEP, 1.0, 0.0),
    "consistent, s = -1 at a low angle": (2.0, np.radians(30.0), -1.0, 0.0),
    "consistent, mu = 1.2 < 4/3": (1.2, STEEP, -1.0, 0.0),
    "no solution, mu = 1.4 > 4/3": (1.4, STEEP, -1.0, 0.0),
    "no solution, mu = 2": (2.0, STEEP, -1.0, 0.0),
    "two solutions, mu = 2, turning fast": (2.0, STEEP, -1.0, 6.0),
}


def coefficients(mu, theta, u, theta_dot):
    s = np.sign(u)
    A = 1 + (M * L**2 / I_ROD) * np.cos(theta) * (np.cos(theta) + s * mu * np.sin(theta))
    b = L * theta_dot**2 * np.sin(theta) - G
    return A, b


def rod_scene(mu):
    tips = [[L, 0, 0], [-L, 0, 0], [0, W, 0], [0, -W, 0], [0, 0, W], [0, 0, -W]]
    body = jaxrb.RigidBody(M, jnp.array([1e-4, I_ROD, I_ROD]), shape=jaxrb.ConvexPolyhedron(tips))
    return jaxrb.Scene(body, (jaxrb.Gravity(),), floor=jaxrb.Floor(0.0, mu))


def rod_state(theta, u, theta_dot):
    """End A at the origin, the rod in the x-z plane leaning towards +x at `theta`; A slides
    at `u` along x and the rod turns at `theta_dot` (theta growing)."""
    q = jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, 0.0]), -theta)
    pos = jnp.stack([L * jnp.cos(theta), 0.0, L * jnp.sin(theta)])
    omega_world = jnp.stack([0.0, -theta_dot, 0.0])
    vel = jnp.stack([u, 0.0, 0.0]) + jnp.cross(omega_world, pos)
    omega = jaxrb.quat_rotate(jaxrb.quat_conjugate(q), omega_world)
    return jaxrb.make_state(pos=pos, quat=q, vel=vel, omega=omega)


@persistent
def _rods(mu, theta, u, theta_dot):
    ts = jnp.linspace(0.0, T_END, SAVES)

    def one(mu, theta, u, theta_dot):
        state0 = rod_state(theta, u, theta_dot)
        return jaxrb.simulate(
            rod_scene(mu), state0, ts, throw=False, rtol=1e-11, atol=1e-11, max_impacts=8
        )

    return jax.vmap(one)(mu, theta, u, theta_dot)


@pytest.fixture(scope="module")
def rods():
    params = np.array(list(CASES.values()))
    return params, _rods(*(jnp.asarray(p) for p in params.T))


def test_painleve_flagged_per_member_where_the_closed_form_says(rods):
    params, traj = rods
    codes = np.asarray(traj.result._value)
    lowest = np.asarray(
        jax.vmap(jax.vmap(rod_scene(1.0).body.shape.floor_distance))(
            traj.states.pos, traj.states.quat
        )
    )
    for k, (name, case) in enumerate(CASES.items()):
        A, b = coefficients(*case)
        assert np.isclose(params[k], case).all()
        if A > 0:
            assert codes[k] == jaxrb.RESULTS.successful._value, name
            assert int(traj.contact.ambiguous[k]) == 0, name
            assert int(traj.contact.kind[k, 1]) == jaxrb.contact.KIND_NAMES.index("point"), name
        elif b < 0:  # no solution: flagged (throw=True would raise), the run stops there
            assert codes[k] == jaxrb.RESULTS.painleve_paradox._value, name
            np.testing.assert_array_equal(
                traj.states.pos[k], np.repeat(traj.states.pos[k, :1], SAVES, 0)
            )
        else:  # two solutions: counted, and the end lifts off
            assert codes[k] == jaxrb.RESULTS.successful._value, name
            assert int(traj.contact.ambiguous[k]) == 1, name
            assert int(traj.contact.kind[k, 1]) == jaxrb.contact.KIND_NAMES.index("flight"), name
            # after lift-off the rod flies freely: G on a parabola, theta growing uniformly
            _, theta, _, theta_dot = case
            t = np.linspace(0.0, T_END, SAVES)
            z_G = L * np.sin(theta) + L * theta_dot * np.cos(theta) * t - 0.5 * G * t**2
            z_A = z_G - L * np.sin(theta + theta_dot * t)
            assert z_A[1] > 0.0 and b > 0.0  # rising from the start, at A's acceleration b
            # rtol = atol = 1e-11 in the solver: A's height to 1e-11 m
            np.testing.assert_allclose(lowest[k], z_A, rtol=0, atol=1e-11, err_msg=name)


def planar_rod(mu, theta, u, theta_dot, ts, slip_stop=1e-5):
    """The sliding rod's planar equations (module docstring), to the first event: the slip of
    A stopping (jaxrb ends a slide when its slip has fallen to half of `slip_stop`, then
    sticks) or the normal force reaching zero. Returns (x_G, z_G, theta) at the `ts` before
    it, and the event time."""
    s = np.sign(u)

    def normal_force(th, w):
        A = 1 + (M * L**2 / I_ROD) * np.cos(th) * (np.cos(th) + s * mu * np.sin(th))
        return M * (G - L * w**2 * np.sin(th)) / A

    def rhs(t, y):
        x, th, vx, w = y
        N = normal_force(th, w)
        return [vx, w, -mu * s * N / M, -L * N * (np.cos(th) + s * mu * np.sin(th)) / I_ROD]

    def slip(t, y):
        return s * (y[2] + L * np.sin(y[1]) * y[3]) - 0.5 * slip_stop

    def lift(t, y):
        return normal_force(y[1], y[3])

    slip.terminal = lift.terminal = True
    y0 = [L * np.cos(theta), theta, u - L * np.sin(theta) * theta_dot, theta_dot]
    sol = solve_ivp(
        rhs,
        (0.0, ts[-1]),
        y0,
        method="DOP853",
        rtol=1e-13,
        atol=1e-14,
        dense_output=True,
        events=(slip, lift),
    )
    t_event = min([e[0] for e in sol.t_events if len(e)], default=np.inf)
    before = ts < t_event - 1e-6
    x, th = sol.sol(ts[before])[:2]
    return np.stack([x, L * np.sin(th), th], -1), before, t_event


def test_consistent_sliding_follows_the_planar_equations(rods):
    params, traj = rods
    ts = np.linspace(0.0, T_END, SAVES)
    checked = 0
    for k, case in enumerate(params):
        if coefficients(*case)[0] <= 0:
            continue
        reference, before, t_event = planar_rod(*case, ts)
        Rm = np.asarray(jaxrb.quat_to_matrix(traj.states.quat[k]))
        theta = np.arctan2(Rm[:, 2, 0], Rm[:, 0, 0])
        pos = np.asarray(traj.states.pos[k])
        simulated = np.stack([pos[:, 0], pos[:, 2], theta], -1)[before]
        np.testing.assert_allclose(simulated, reference, rtol=0, atol=1e-8)
        assert np.all(np.abs(pos[before, 1]) < 1e-12)  # the motion stays in its plane
        assert np.all(np.asarray(traj.contact.sliding[k])[before])
        if np.isfinite(t_event):  # the first event: the slip stops, or the end lifts off
            first = float(traj.contact.event_time[k, 1])
            np.testing.assert_allclose(first, t_event, atol=1e-8)
        checked += before.sum()
    assert checked >= 12


# ------------------------------------------------ a narrow box tipping while it turns
@persistent
def _narrow_boxes(state0, friction):
    ts = jnp.linspace(0.0, 0.02, 3)

    def one(mu):
        return jaxrb.simulate(narrow_box_scene(mu), state0, ts, throw=False, max_impacts=60)

    return jax.vmap(one)(friction)


def test_a_narrow_box_tipping_while_it_turns_stops_where_its_edge_problem_turns_singular():
    """The narrow box (24 x 8 x 8 mm) on its end, turning about a corner at 1 rad/s, tips onto
    an edge through that corner, both ends sliding. With friction 1.5 (a rod of its
    proportions, sliding across the edge, meets the paradox above 1.44) the edge's normal
    problem turns singular within 15 microseconds: the forces grow without bound and pass
    through a pole, where the event function falls as if a force had reached zero. Nothing
    fits after it, whatever the event excludes: the run stops with `painleve_paradox`, the
    event log marking that event, and only it, as without a consistent mode (before, it
    chattered between the edge and one corner to `max_events`). Checked at the
    state where it stopped, on the two ends' normal problem built here with each end's
    friction along its own slip: the end that was to lift pushes itself into the floor
    (the problem is not a P-matrix), and the 2 x 2 problem is singular to 1e-2 of its
    diagonal. With friction 1.2 the box comes down onto its end and rests there."""
    traj = _narrow_boxes(narrow_box_on_end(1.0)[0], jnp.array([1.5, 1.2]))
    codes = np.asarray(traj.result._value)
    assert codes.tolist() == [
        jaxrb.RESULTS.painleve_paradox._value,
        jaxrb.RESULTS.successful._value,
    ]
    last_event = int(traj.contact.events[0])
    stop = float(traj.contact.event_time[0, last_event])
    assert 0.0 < stop < 2e-5
    # the stop is the one event without a consistent mode, and the event log marks it
    assert int(traj.contact.inconsistent[0]) == 1
    assert np.flatnonzero(np.asarray(traj.contact.event_inconsistent[0])).tolist() == [last_event]
    marked = np.asarray(traj.contact.event_inconsistent[1])
    assert int(np.sum(marked)) == int(traj.contact.inconsistent[1])
    last = jax.tree.map(lambda x: np.asarray(x[0, -1]), traj.states)
    scene = narrow_box_scene(1.5)
    corners = np.asarray(contact_model(NARROW_BOX).corners)
    heights = last.pos[2] + corners @ np.asarray(jaxrb.quat_to_matrix(jnp.asarray(last.quat)))[2]
    edge = np.flatnonzero(heights < 1e-12)
    assert len(edge) == 2
    A, _, _ = vertex_problem(scene, last, corners[edge])
    assert min(A[0, 0], A[1, 1]) < 0, A  # N/(m/s^2): one end alone is pushed into the floor
    assert abs(np.linalg.det(A)) < 1e-2 * abs(A[0, 0] * A[1, 1]), A
    # friction 1.2: on its end at rest, its energy never rising between saves
    assert jaxrb.contact.KIND_NAMES[int(traj.contact.kind[1, -1])] == "face"
    assert float(np.linalg.norm(traj.states.vel[1, -1])) < 1e-9
    energy = jaxrb.energy(narrow_box_scene(1.2), jax.tree.map(lambda x: x[1], traj.states))
    assert np.all(np.diff(np.asarray(energy)) <= 1e-15)
