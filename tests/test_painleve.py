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

import jaxrb

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
