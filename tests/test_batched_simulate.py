"""`simulate` with a batched initial state: the whole batch as one diffrax solve, against
exact solutions, `jax.vmap(simulate)` and finite differences (float64)."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb
from jaxrb import analytic
from jaxrb._batched import CPU_PART, batch_rms_norm, default_part_size
from jaxrb._coordinates import ROTATION, coordinates_for
from jaxrb._simulate import batch_controller
from jaxrb._solve import default_solver

I123 = jnp.array([1.0, 2.0, 3.0])
TS = jnp.array([0.0, 1.5, 4.0])
N = 6
TOL = dict(rtol=1e-11, atol=1e-11)
G = jnp.array([0.0, 0.0, -9.81])
GRAVITY = jaxrb.Scene(jaxrb.RigidBody(2.0, I123), forces=(jaxrb.Gravity(),))


def random_states(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return jaxrb.make_state(
        pos=rng.normal(size=(n, 3)),
        quat=q / np.linalg.norm(q, axis=-1, keepdims=True),
        vel=rng.normal(size=(n, 3)),
        omega=rng.normal(size=(n, 3)),
    )


@pytest.fixture(scope="module")
def states():
    return random_states(N)


@pytest.fixture(scope="module")
def gravity_run(states):
    return jaxrb.simulate(GRAVITY, states, TS, **TOL)


def test_shapes_and_per_member_fields(gravity_run):
    traj = gravity_run
    assert traj.ts.shape == (3,)
    assert traj.states.pos.shape == (N, 3, 3) and traj.states.vel.shape == (N, 3, 3)
    assert traj.states.quat.shape == (N, 3, 4) and traj.states.omega.shape == (N, 3, 3)
    assert traj.result._value.shape == (N,)
    assert bool(jnp.all(traj.result == jaxrb.RESULTS.successful))
    assert traj.num_steps.shape == (N,) and len(set(np.asarray(traj.num_steps).tolist())) == 1
    assert int(traj.num_steps[0]) > 10
    assert traj.quat_norm_drift.shape == (N,) and float(jnp.max(traj.quat_norm_drift)) < 1e-9


def test_rotation_exact_and_mass_centre_on_the_parabola(states, gravity_run):
    """Gravity only: omega against the elliptic solution, attitude against the exact
    torque-free flow, the mass centre on its parabola (integrated: rotation only)."""
    traj = gravity_run
    w_exact = jax.vmap(lambda w: analytic.asymmetric_top(TS, I123, w))(states.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9
    exact = jaxrb.torque_free_flow(I123, states, TS)
    assert float(jnp.max(jaxrb.quat_geodesic_angle(traj.states.quat, exact.quat))) < 1e-9
    t = TS[None, :, None]
    pos = states.pos[:, None] + states.vel[:, None] * t + 0.5 * G * t**2
    np.testing.assert_allclose(traj.states.pos, pos, rtol=0, atol=1e-13)
    np.testing.assert_allclose(traj.states.vel, states.vel[:, None] + G * t, rtol=0, atol=1e-13)


def test_batch_equals_vmap_to_the_tolerance(states, gravity_run):
    per_member = jax.vmap(lambda s: jaxrb.simulate(GRAVITY, s, TS, **TOL))(states)
    assert per_member.states.quat.shape == gravity_run.states.quat.shape
    for name in ("pos", "quat", "vel", "omega"):
        np.testing.assert_allclose(
            getattr(gravity_run.states, name), getattr(per_member.states, name), atol=2e-9
        )
    # the batch takes the steps of its hardest member
    assert int(gravity_run.num_steps[0]) >= int(jnp.max(per_member.num_steps))


def test_a_batch_larger_than_a_cpu_part_runs_in_parts():
    """On a CPU, `simulate` runs CPU_PART members per solve: with one member more, the last
    one is a part of its own (padded), and every member matches the exact solution."""
    assert jax.default_backend() == "cpu" and default_part_size(CPU_PART + 1) == CPU_PART
    big = random_states(CPU_PART + 1, seed=3)
    ts = jnp.array([0.0, 0.5])
    traj = jaxrb.simulate(GRAVITY, big, ts, **TOL)
    assert traj.states.omega.shape == (CPU_PART + 1, 2, 3)
    w_exact = jax.vmap(lambda w: analytic.asymmetric_top(ts, I123, w))(big.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9
    steps = np.asarray(traj.num_steps)
    assert len(set(steps[:CPU_PART])) == 1


def test_full_state_with_linear_drag_matches_closed_form(states):
    """Linear drag (a force but no moment): all 13 numbers are integrated; the mass centre
    against v(t) = v_inf + (v0 - v_inf) exp(-k t), k = c / m, v_inf = g / k."""
    m, c = 2.0, 0.3
    scene = jaxrb.Scene(jaxrb.RigidBody(m, I123), forces=(jaxrb.Gravity(), jaxrb.LinearDrag(c)))
    traj = jaxrb.simulate(scene, states, TS, **TOL)
    k = c / m
    v_inf = G / k
    t = TS[None, :, None]
    decay = jnp.exp(-k * t)
    vel = v_inf + (states.vel[:, None] - v_inf) * decay
    pos = states.pos[:, None] + v_inf * t + (states.vel[:, None] - v_inf) * (1 - decay) / k
    np.testing.assert_allclose(traj.states.vel, vel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj.states.pos, pos, rtol=0, atol=1e-9)
    w_exact = jax.vmap(lambda w: analytic.asymmetric_top(TS, I123, w))(states.omega)
    assert float(jnp.max(jnp.abs(traj.states.omega - w_exact))) < 1e-9


# --- bad members ----------------------------------------------------------------------------


def _with_bad_members(states):
    omega = states.omega.at[2, 1].set(jnp.nan)
    quat = states.quat.at[4].set(0.0)
    return jaxrb.State(states.pos, quat, states.vel, omega)


def test_bad_members_flagged_and_the_others_unaffected(states, gravity_run):
    traj = jaxrb.simulate(GRAVITY, _with_bad_members(states), TS, throw=False, **TOL)
    R = jaxrb.RESULTS
    codes = [R.successful] * N
    codes[2], codes[4] = R.nonfinite_state, R.zero_quaternion
    assert [int(r) for r in traj.result._value] == [c._value for c in codes]
    good = np.array([0, 1, 3, 5])
    # a flagged member takes no part in the step control: the others take the same steps
    # as without it and agree with the clean run
    np.testing.assert_array_equal(traj.num_steps[good], gravity_run.num_steps[good])
    for name in ("pos", "quat", "vel", "omega"):
        np.testing.assert_allclose(
            getattr(traj.states, name)[good], getattr(gravity_run.states, name)[good], atol=1e-13
        )
        assert bool(jnp.all(jnp.isnan(getattr(traj.states, name)[np.array([2, 4])])))


@pytest.mark.parametrize(
    "inertia", [I123, jnp.array([[2.0, 0.3, -0.2], [0.3, 3.0, 0.1], [-0.2, 0.1, 4.0]])]
)
def test_member_last_rates_equal_the_mapped_one_body_rates(states, inertia):
    """The free rotation's row-wise batch right-hand side (member axis last) is the one-body
    `rates` mapped over the members, for principal moments and a full tensor."""
    scene = jaxrb.Scene(jaxrb.RigidBody(2.0, inertia), forces=(jaxrb.Gravity(),))
    coords = coordinates_for(scene)
    assert coords is ROTATION
    y = (states.quat, states.omega)
    mapped = jax.vmap(lambda y1: coords.rates(scene, 0.0, y1, None))(y)
    rows = coords.member_last_rates(scene, (states.quat.T, states.omega.T))
    for got, want in zip(rows, mapped, strict=True):
        np.testing.assert_allclose(got.T, want, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("inertia", [[jnp.nan, 2.0, 3.0], jnp.diag(jnp.array([1.0, jnp.nan, 3.0]))])
def test_bad_shared_scene_flags_every_member_and_takes_no_time(states, inertia):
    """A traced bad inertia (principal moments or the full tensor) shared by the batch:
    every member is flagged, with NaN states, and the solve does not grind on (a few steps,
    not max_steps)."""
    run = jax.jit(
        lambda J: jaxrb.simulate(
            jaxrb.Scene(jaxrb.RigidBody(2.0, J)), states, TS, throw=False, max_steps=1000
        )
    )
    traj = run(jnp.asarray(inertia))
    assert all(int(r) == jaxrb.RESULTS.invalid_inertia._value for r in traj.result._value)
    assert int(traj.num_steps[0]) <= 10
    assert bool(jnp.all(jnp.isnan(traj.states.omega)))


def test_bad_member_raises_naming_the_member(states):
    bad = _with_bad_members(states)
    with pytest.raises(ValueError, match=r"state0\.omega .*batch member 2"):
        jaxrb.simulate(GRAVITY, bad, TS, **TOL)
    with pytest.raises(ValueError, match="zero norm in batch member 4"):
        jaxrb.simulate(GRAVITY, jaxrb.State(states.pos, bad.quat, states.vel, states.omega), TS)


def test_mismatched_batch_shapes_raise():
    with pytest.raises(ValueError, match="state0 must be one body's state"):
        mixed = jaxrb.State(jnp.zeros((3, 3)), jnp.ones((2, 4)), jnp.zeros(3), jnp.zeros(3))
        jaxrb.simulate(GRAVITY, mixed, TS)


# --- gradients ------------------------------------------------------------------------------

I_GRAD = jnp.array([1.0, 2.0, 2.5])  # strictly inside the triangle inequality
OMEGA_GRAD = jnp.array([[1.0, 0.2, 1.5], [0.5, -0.3, 1.2], [-0.8, 0.4, 1.0], [0.3, 1.1, -0.6]])
W_Q = jax.random.normal(jax.random.key(1), (4, 4))
W_W = jax.random.normal(jax.random.key(2), (4, 3))
TS_GRAD = jnp.array([0.0, 2.0])


def _observable(inertia, omega0, adjoint=None):
    """A weighted sum of every member's final attitude and angular velocity."""
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, inertia))
    traj = jaxrb.simulate(
        scene, jaxrb.make_state(omega=omega0), TS_GRAD, rtol=1e-12, atol=1e-12, adjoint=adjoint
    )
    return jnp.sum(W_Q * traj.states.quat[:, -1]) + jnp.sum(W_W * traj.states.omega[:, -1])


@pytest.fixture(scope="module")
def finite_differences():
    """Central differences (h = 1e-5) along each inertia axis and along one direction of
    all members' initial omega."""
    f = jax.jit(_observable)
    h = 1e-5
    I3 = jnp.eye(3)
    d_inertia = jnp.stack(
        [(f(I_GRAD + h * e, OMEGA_GRAD) - f(I_GRAD - h * e, OMEGA_GRAD)) / (2 * h) for e in I3]
    )
    direction = jax.random.normal(jax.random.key(3), OMEGA_GRAD.shape)
    d_omega = (f(I_GRAD, OMEGA_GRAD + h * direction) - f(I_GRAD, OMEGA_GRAD - h * direction)) / (
        2 * h
    )
    return d_inertia, direction, d_omega


@persistent
def _observable_gradient(inertia, omega0):
    return jax.grad(_observable, argnums=(0, 1))(inertia, omega0)


@persistent
def _observable_forward_derivatives(inertia, omega0, direction):
    """Forward mode (diffrax's `ForwardMode` adjoint): the Jacobian along the inertia axes
    and the derivative along `direction` of all members' initial omega."""
    fwd = dfx.ForwardMode()
    jac = jax.jacfwd(lambda i: _observable(i, omega0, fwd))(inertia)
    _, tangent = jax.jvp(lambda w: _observable(inertia, w, fwd), (omega0,), (direction,))
    return jac, tangent


def test_reverse_mode_gradient_of_a_batch(finite_differences):
    d_inertia, direction, d_omega = finite_differences
    g_inertia, g_omega = _observable_gradient(I_GRAD, OMEGA_GRAD)
    np.testing.assert_allclose(g_inertia, d_inertia, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(jnp.sum(g_omega * direction), d_omega, rtol=1e-6, atol=1e-7)


def test_forward_mode_gradient_of_a_batch(finite_differences):
    d_inertia, direction, d_omega = finite_differences
    jac, tangent = _observable_forward_derivatives(I_GRAD, OMEGA_GRAD, direction)
    np.testing.assert_allclose(jac, d_inertia, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(tangent, d_omega, rtol=1e-6, atol=1e-7)


# --- jointed scenes -------------------------------------------------------------------------

P = analytic.SAMPLE_PENDULUM  # m = 7.5 kg, r = 0.25 m, k_O = 0.295 m


@pytest.mark.parametrize("joint_cls", [jaxrb.Hinge, jaxrb.Pivot])
def test_batched_pendulums_match_the_exact_swing(joint_cls):
    """The sample pendulum released from rest with its mass centre level with the axis, in
    three copies turned about the vertical and moved: each swings by the exact theta(t)."""
    J_c = P.mass * (P.k_O**2 - P.r**2)  # about the mass centre, so that J_O = m k_O^2
    body = jaxrb.RigidBody(P.mass, jnp.array([J_c, J_c, J_c]))
    point = jnp.array([-P.r, 0.0, 0.0])
    joint = joint_cls(point, axis=(0.0, 1.0, 0.0)) if joint_cls is jaxrb.Hinge else joint_cls(point)
    scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=joint)
    turn = jnp.array([0.0, 1.0, -2.5])  # about world z (rad)
    anchors = jnp.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.5], [-0.3, 0.2, 3.0]])
    radial = jnp.stack([jnp.cos(turn), jnp.sin(turn), jnp.zeros(3)], -1)
    states = jaxrb.make_state(
        pos=anchors + P.r * radial,
        quat=jaxrb.axis_angle_to_quat(jnp.array([0.0, 0.0, 1.0]), turn),
    )
    ts = jnp.linspace(0.0, 0.6, 4)
    traj = jaxrb.simulate(scene, states, ts, **TOL)
    assert bool(jnp.all(traj.result == jaxrb.RESULTS.successful))
    arm = traj.states.pos - anchors[:, None]
    theta = jnp.arctan2(-arm[..., 2], jnp.sum(arm[..., :2] * radial[:, None, :2], -1))
    exact = analytic.pendulum_theta(ts, P.r, P.k_O)
    np.testing.assert_allclose(theta, jnp.broadcast_to(exact, theta.shape), atol=1e-9)
    np.testing.assert_allclose(jnp.linalg.norm(arm, axis=-1), P.r, atol=1e-12)


# --- float32 --------------------------------------------------------------------------------


def test_float32_batch(states):
    f32 = jnp.float32
    scene = jaxrb.Scene(jaxrb.RigidBody(f32(1.0), I123.astype(f32)), forces=(jaxrb.Gravity(),))
    s32 = jax.tree.map(lambda x: x.astype(f32), states)
    traj = jaxrb.simulate(scene, s32, TS.astype(f32), rtol=1e-6, atol=1e-6)
    assert all(x.dtype == f32 for x in jax.tree.leaves(traj.states))
    assert bool(jnp.all(traj.result == jaxrb.RESULTS.successful))
    w_exact = jax.vmap(lambda w: analytic.asymmetric_top(TS, I123, w))(states.omega)
    err = jnp.abs(traj.states.omega.astype(jnp.float64) - w_exact)
    assert float(jnp.max(err)) < 1e-4


# --- settings -------------------------------------------------------------------------------


def test_default_solver_by_tolerance():
    assert isinstance(default_solver(1e-8), dfx.Tsit5)
    assert isinstance(default_solver(1e-9), dfx.Tsit5)
    assert isinstance(default_solver(1e-10), dfx.Dopri8)
    assert isinstance(default_solver(1e-8, batch=True), dfx.Dopri8)
    assert isinstance(default_solver(1e-6, batch=True), dfx.Dopri8)
    assert isinstance(default_solver(1e-5, batch=True), dfx.Tsit5)
    # a traced rtol (its value unknown): the choice for the default rtol, 1e-8
    chosen = []
    jax.jit(lambda r: chosen.append((default_solver(r), default_solver(r, batch=True))) or r)(1.0)
    assert isinstance(chosen[0][0], dfx.Tsit5) and isinstance(chosen[0][1], dfx.Dopri8)


def test_batch_norm_is_the_worst_members_rms():
    # the member axis last: member 0 is (3, 4, 0), member 1 is (0, 0, 6)
    tree = (jnp.array([[3.0, 0.0], [4.0, 0.0]]), jnp.array([[0.0, 6.0]]))
    # member 0: sqrt((9 + 16 + 0) / 3); member 1: sqrt(36 / 3)
    np.testing.assert_allclose(batch_rms_norm(tree), jnp.sqrt(12.0))
    default_norm = batch_controller(dfx.PIDController(rtol=1e-6, atol=1e-6))
    assert default_norm.norm is batch_rms_norm

    def own_norm(tree):
        return jnp.max(jnp.abs(tree[0]))

    own = batch_controller(dfx.PIDController(rtol=1e-6, atol=1e-6, norm=own_norm))
    assert own.norm is own_norm


# --- a floor ---------------------------------------------------------------------------------


def test_floor_scene_batch_runs_the_contact_engine_per_member():
    """Balls dropped from two heights bounce as the closed form says (restitution 0.7)."""
    radius, e = 0.1, 0.7
    body = jaxrb.RigidBody(1.0, shape=jaxrb.Sphere(radius))
    scene = jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, 0.0))
    h0 = jnp.array([1.0, 0.5])
    states = jaxrb.make_state(pos=jnp.stack([jnp.zeros(2), jnp.zeros(2), h0 + radius], -1))
    ts = jnp.linspace(0.0, 1.2, 5)
    traj = jaxrb.simulate(scene, states, ts, rtol=1e-10, atol=1e-10)
    assert traj.ts.shape == (5,) and traj.states.pos.shape == (2, 5, 3)
    assert traj.impacts.count.shape == (2,) and bool(jnp.all(traj.impacts.count >= 1))
    exact = jax.vmap(lambda h: analytic.ball_height(ts, h, e))(h0)
    np.testing.assert_allclose(traj.states.pos[..., 2] - radius, exact, rtol=0, atol=1e-8)
