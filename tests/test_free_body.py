"""Torque-free and forced free bodies against exact oracles (float64)."""

import diffrax as dfx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb import analytic

I123 = jnp.array([1.0, 2.0, 3.0])
TIGHT = dict(solver=dfx.Dopri8(), rtol=1e-13, atol=1e-13)


def free_scene(inertia=I123, forces=()):
    return jaxrb.Scene(jaxrb.RigidBody(1.0, inertia), forces=forces)


def rest_state(omega, quat=(1.0, 0.0, 0.0, 0.0)):
    return jaxrb.make_state(omega=omega, quat=quat)


@pytest.fixture(scope="module")
def tumbling():
    """A torque-free asymmetric body over 60 time units at tight tolerance."""
    omega0 = jnp.array([0.8, 0.3, 1.4])
    ts = jnp.linspace(0.0, 60.0, 121)
    traj = jaxrb.simulate(free_scene(), rest_state(omega0), ts, **TIGHT)
    return omega0, ts, traj


def test_asymmetric_top_matches_elliptic_solution(tumbling):
    omega0, ts, traj = tumbling
    exact = analytic.asymmetric_top(ts, I123, omega0)
    exact = getattr(exact, "omega", exact)
    err = jnp.max(jnp.abs(traj.states.omega - exact)) / jnp.linalg.norm(omega0)
    assert err <= 1e-9, err


def test_energy_and_world_angular_momentum_conserved(tumbling):
    _, _, traj = tumbling
    scene = free_scene()
    E = jaxrb.energy(scene, traj.states)
    L = jaxrb.angular_momentum(scene, traj.states)
    assert jnp.max(jnp.abs(E / E[0] - 1)) <= 1e-10
    assert jnp.max(jnp.linalg.norm(L - L[0], axis=-1)) / jnp.linalg.norm(L[0]) <= 1e-10


def test_quaternion_norm_policy(tumbling):
    """Saved quaternions are unit; the drift before normalisation is reported and tiny."""
    omega0, ts, traj = tumbling
    norms = jnp.linalg.norm(traj.states.quat, axis=-1)
    assert jnp.max(jnp.abs(norms - 1)) <= 1e-14
    assert 0 <= traj.quat_norm_drift <= 1e-11
    # A loose tolerance lets it drift visibly, and the drift is reported, not hidden.
    loose = jaxrb.simulate(free_scene(), rest_state(omega0), ts, rtol=1e-4, atol=1e-4)
    assert loose.quat_norm_drift > 10 * traj.quat_norm_drift


def _fixed_step_error(solver, n_steps):
    omega0 = jnp.array([0.8, 0.3, 1.4])
    T = 4.0
    traj = jaxrb.simulate(
        free_scene(),
        rest_state(omega0),
        jnp.array([0.0, T]),
        solver=solver,
        stepsize_controller=dfx.ConstantStepSize(),
        dt0=T / n_steps,
        max_steps=400,
    )
    exact = analytic.asymmetric_top(jnp.array([T]), I123, omega0)
    exact = getattr(exact, "omega", exact)
    return float(jnp.max(jnp.abs(traj.states.omega[-1] - exact[-1])))


@pytest.mark.parametrize("solver, order", [(dfx.Heun(), 2), (dfx.Bosh3(), 3), (dfx.Tsit5(), 5)])
def test_convergence_order(solver, order):
    """Measured order (slope of log error vs log step) matches the solver's order."""
    steps = [40, 80, 160, 320]
    errs = [_fixed_step_error(solver, n) for n in steps]
    slope = -np.polyfit(np.log(steps), np.log(errs), 1)[0]
    assert abs(slope - order) < 0.25, (slope, errs)


@pytest.mark.parametrize("regime", ["axis3", "axis1", "near_separatrix"])
def test_dzhanibekov_flip_period(regime):
    """Time between sign changes of omega_2 equals 2 K(m) / |omega_p|."""
    omega0 = {
        "axis3": jnp.array([0.4, 0.2, 1.0]),
        "axis1": jnp.array([1.0, 0.2, 0.4]),
        "near_separatrix": jnp.array([1e-3, 1.0, 1e-3]),
    }[regime]
    half = float(analytic.flip_half_period(I123, omega0))
    ts = np.linspace(0.0, 3.2 * half, 20001)
    traj = jaxrb.simulate(free_scene(), rest_state(omega0), jnp.asarray(ts), **TIGHT)
    w2 = np.asarray(traj.states.omega[:, 1])
    idx = np.nonzero(np.sign(w2[1:]) != np.sign(w2[:-1]))[0]
    assert len(idx) >= 3
    # each crossing: the root of the cubic through the 4 samples around it (error ~ dt^4)
    crossings = []
    for i in idx[:3]:
        k = slice(i - 1, i + 3)
        coeffs = np.polyfit(ts[k] - ts[i], w2[k], 3)
        roots = np.roots(coeffs)
        roots = roots[np.abs(roots.imag) < 1e-12].real
        crossings.append(ts[i] + roots[np.argmin(np.abs(roots - (ts[i + 1] - ts[i]) / 2))])
    np.testing.assert_allclose(np.diff(crossings), half, rtol=1e-6)


def test_symmetric_top_closed_forms():
    J1, J3 = 2.0, 3.0
    omega0 = jnp.array([0.3, -0.4, 2.0])
    ts = jnp.linspace(0.0, 20.0, 81)
    traj = jaxrb.simulate(free_scene(jnp.array([J1, J1, J3])), rest_state(omega0), ts, **TIGHT)
    lam = (J1 - J3) * omega0[2] / J1
    w1 = omega0[0] * jnp.cos(lam * ts) + omega0[1] * jnp.sin(lam * ts)
    w2 = omega0[1] * jnp.cos(lam * ts) - omega0[0] * jnp.sin(lam * ts)
    np.testing.assert_allclose(traj.states.omega[:, 0], w1, atol=1e-10)
    np.testing.assert_allclose(traj.states.omega[:, 1], w2, atol=1e-10)
    np.testing.assert_allclose(traj.states.omega[:, 2], omega0[2], atol=1e-10)
    top = analytic.symmetric_top(ts, J1, J3, omega0)
    np.testing.assert_allclose(traj.states.omega, top.omega, atol=1e-10)
    geodesic = jaxrb.quat_geodesic_angle(traj.states.quat, top.quat)
    assert jnp.max(geodesic) <= 1e-9


def test_spherical_top_keeps_omega_fixed():
    omega0 = jnp.array([0.3, -0.4, 2.0])
    ts = jnp.linspace(0.0, 10.0, 21)
    traj = jaxrb.simulate(free_scene(jnp.array([2.0, 2.0, 2.0])), rest_state(omega0), ts, **TIGHT)
    np.testing.assert_allclose(traj.states.omega, jnp.broadcast_to(omega0, (21, 3)), atol=1e-12)
    _, q_exact = analytic.spherical_top(ts, omega0)
    assert jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, q_exact)) <= 1e-10


def test_products_of_inertia_equal_principal_description():
    """A tensor with products of inertia and the same body in principal axes move identically."""
    principal = jnp.array([1.0, 2.0, 3.0])
    rot = jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, -0.5]), 0.9)  # body frame B -> P
    Rbp = jaxrb.quat_to_matrix(rot)
    J_full = Rbp @ jnp.diag(principal) @ Rbp.T  # tensor in frame B
    assert jnp.max(jnp.abs(J_full - jnp.diag(jnp.diag(J_full)))) > 0.1  # real products
    omega_b = jnp.array([0.7, -0.2, 1.1])
    ts = jnp.linspace(0.0, 10.0, 41)
    forces = (jaxrb.Gravity(), jaxrb.DampingMoment(linear=0.05))
    a = jaxrb.simulate(free_scene(J_full, forces), rest_state(omega_b), ts, **TIGHT)
    # same body described in principal axes P: attitude q_P = q_B (x) rot, omega_P = R^T omega_B
    q_p = jaxrb.quat_multiply(jnp.array([1.0, 0.0, 0.0, 0.0]), rot)
    b = jaxrb.simulate(free_scene(principal, forces), rest_state(Rbp.T @ omega_b, q_p), ts, **TIGHT)
    np.testing.assert_allclose(a.states.omega, b.states.omega @ Rbp.T, atol=1e-10)
    R_a = jaxrb.quat_to_matrix(a.states.quat)
    R_b = jaxrb.quat_to_matrix(b.states.quat)
    np.testing.assert_allclose(R_a @ Rbp, R_b, atol=1e-10)
    np.testing.assert_allclose(a.states.pos, b.states.pos, atol=1e-10)


def test_drag_matches_closed_form_fall():
    """Linear drag: v(t) = v_inf + (v0 - v_inf) exp(-c t / m), exact."""
    m, c = 2.0, 0.7
    g = jnp.array([0.0, 0.0, -9.81])
    scene = jaxrb.Scene(jaxrb.RigidBody(m, I123), forces=(jaxrb.Gravity(), jaxrb.LinearDrag(c)))
    v0 = jnp.array([3.0, 0.0, 5.0])
    ts = jnp.linspace(0.0, 3.0, 31)
    traj = jaxrb.simulate(scene, jaxrb.make_state(vel=v0), ts, **TIGHT)
    v_inf = m * g / c
    v = v_inf + (v0 - v_inf) * jnp.exp(-c * ts / m)[:, None]
    np.testing.assert_allclose(traj.states.vel, v, atol=1e-10)


def test_body_frame_torque_on_spherical_body_is_exact():
    """Spherical body (w x J w = 0) under a constant body-frame torque: w(t) = w0 + M t / I."""
    scene = free_scene(
        jnp.array([2.0, 2.0, 2.0]), (jaxrb.Wrench(torque=(0.0, 0.0, 0.5), frame="body"),)
    )
    ts = jnp.linspace(0.0, 2.0, 5)
    traj = jaxrb.simulate(scene, rest_state((0.3, 0.0, 1.0)), ts, **TIGHT)
    expected = jnp.stack([jnp.full_like(ts, 0.3), jnp.zeros_like(ts), 1.0 + 0.25 * ts], -1)
    np.testing.assert_allclose(traj.states.omega, expected, atol=1e-12)


def test_time_dependent_world_force():
    """F(t) = (sin t, 0, 0) N on a 2 kg body: v_x(t) = (1 - cos t) / 2."""
    scene = jaxrb.Scene(
        jaxrb.RigidBody(2.0, I123),
        forces=(jaxrb.Wrench(force=lambda t: jnp.stack([jnp.sin(t), 0.0 * t, 0.0 * t])),),
    )
    ts = jnp.linspace(0.0, 3.0, 7)
    traj = jaxrb.simulate(scene, rest_state((0.0, 0.0, 0.0)), ts, **TIGHT)
    np.testing.assert_allclose(traj.states.vel[:, 0], (1 - jnp.cos(ts)) / 2, atol=1e-12)


@pytest.mark.parametrize("frame", ["world", "body"])
def test_force_at_body_point_gives_its_moment(frame):
    """A force at body point p adds p x F (body frame) to the moment about the mass centre."""
    q = jaxrb.axis_angle_to_quat(jnp.array([0.3, -1.0, 0.5]), 0.7)
    state = rest_state((0.1, 0.2, -0.3), quat=q)
    p = jnp.array([0.2, -0.1, 0.4])
    f = jnp.array([1.0, -2.0, 0.5])
    force, moment = jaxrb.total_wrench(
        0.0, state, free_scene(I123, (jaxrb.Wrench(f, point=p, frame=frame),))
    )
    f_body = f if frame == "body" else jaxrb.quat_rotate(jaxrb.quat_conjugate(q), f)
    f_world = f if frame == "world" else jaxrb.quat_rotate(q, f)
    np.testing.assert_allclose(force, f_world, atol=1e-15)
    np.testing.assert_allclose(moment, jnp.cross(p, f_body), atol=1e-15)
    # and the rotational equation turns that moment into J^-1 (M - w x J w)
    rates = jaxrb.vector_field(
        0.0, state, free_scene(I123, (jaxrb.Wrench(f, point=p, frame=frame),))
    )
    w = state.omega
    np.testing.assert_allclose(
        rates.omega, (jnp.cross(p, f_body) - jnp.cross(w, I123 * w)) / I123, atol=1e-14
    )


def test_quadratic_drag_and_damping_moment_terms():
    """Each force adds only its own terms: F = -k |v| v, M = -(c_w + c_w2 |w|) w."""
    state = jaxrb.make_state(vel=(3.0, 0.0, 4.0), omega=(0.0, 0.6, 0.8))
    body = jaxrb.RigidBody(1.0, I123)
    f, m = jaxrb.QuadraticDrag(0.1).wrench(0.0, state, body)
    np.testing.assert_allclose(f, -0.1 * 5.0 * jnp.array([3.0, 0.0, 4.0]))
    np.testing.assert_allclose(m, 0.0)
    f, m = jaxrb.DampingMoment(0.2, 0.3).wrench(0.0, state, body)
    np.testing.assert_allclose(f, 0.0)
    np.testing.assert_allclose(m, -(0.2 + 0.3 * 1.0) * jnp.array([0.0, 0.6, 0.8]))
    drag = jaxrb.QuadraticDrag.from_air(rho=1.2, drag_coefficient=0.5, area=0.01)
    np.testing.assert_allclose(drag.coefficient, 0.5 * 1.2 * 0.5 * 0.01)
