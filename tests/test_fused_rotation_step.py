"""A batch's free-rotation step as one kernel (`jaxrb._fused_rotation_step`): the same steps
as diffrax's solver, the same results to roundoff, derivatives equal to finite differences.
The kernel is Triton's (a GPU); here it runs in Pallas's interpreter, the same kernel
function on the CPU."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb import _batched, _persistent
from jaxrb._batched import batch_rms_norm
from jaxrb._coordinates import ROTATION
from jaxrb._exact_flow import torque_free_flow
from jaxrb._fused_rotation_step import (
    BLOCK,
    _rates,
    _xla_step,
    fused_rotation_solver,
    fused_step,
    member_rows,
    scalar_vector,
)

I123 = jnp.array([1.0, 2.0, 3.0])
FULL = jnp.array([[2.0, -0.3, 0.1], [-0.3, 2.5, 0.2], [0.1, 0.2, 3.2]])


def _members(n, seed=0):
    kq, kw = jax.random.split(jax.random.key(seed))
    quat = jax.random.normal(kq, (4, n))
    return quat / jnp.linalg.norm(quat, axis=0), 2.0 * jax.random.normal(kw, (3, n))


def _solve(scene, solver, y0):
    term = dfx.ODETerm(lambda t, y, args: ROTATION.member_last_rates(scene, y))
    return dfx.diffeqsolve(
        term,
        solver,
        0.0,
        4.0,
        None,
        y0,
        saveat=dfx.SaveAt(t0=True, ts=jnp.array([1.5]), t1=True),
        stepsize_controller=dfx.PIDController(rtol=1e-9, atol=1e-9, norm=batch_rms_norm),
        max_steps=4096,
    )


@pytest.mark.parametrize(
    "inertia, base",
    [(I123, dfx.Dopri8()), (FULL, dfx.Tsit5())],
    ids=["principal-Dopri8", "full-Tsit5"],
)
def test_the_fused_step_takes_diffrax_steps(inertia, base):
    """One block of members, principal moments with Dopri8 and a full tensor with Tsit5
    (first-same-as-last: the kernel evaluates the first stage itself): the same accepted and
    rejected steps as diffrax's own solver, the states at t1 and at a save between steps
    (the dense output) equal to roundoff."""
    body = jaxrb.RigidBody(1.0, inertia).with_inertia_inverse()
    scene = jaxrb.Scene(body)
    y0 = _members(BLOCK)
    ref = jax.jit(lambda y: _solve(scene, base, y))(y0)
    out = jax.jit(lambda y: _solve(scene, fused_rotation_solver(base, body, interpret=True), y))(y0)
    for key in ("num_accepted_steps", "num_rejected_steps"):
        assert int(out.stats[key]) == int(ref.stats[key])
    for got, want in zip(out.ys, ref.ys, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11)


def test_the_fused_step_is_the_written_out_step():
    """The kernel and the same step in jax.numpy (whose derivative the kernel's step takes):
    y1 and the error estimate agree to roundoff, for a full inertia tensor."""
    body = jaxrb.RigidBody(1.0, FULL).with_inertia_inverse()
    quat, omega = _members(BLOCK, seed=1)
    scalars = scalar_vector(0.05, body, jnp.float64)
    tableau = dfx.Dopri8().tableau
    got = fused_step(tableau, False, True, scalars, quat, omega)
    want = _xla_step(tableau, False, scalars, quat, omega)
    for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-15)


def test_the_fused_step_derivatives_equal_finite_differences():
    """Reverse mode through the kernel's step (its `custom_jvp`) against central differences
    in float64, with respect to omega, the step dt and the inertia entries, and forward mode
    along the same directions."""
    body = jaxrb.RigidBody(1.0, I123).with_inertia_inverse()
    quat, omega = _members(BLOCK, seed=2)
    tableau = dfx.Dopri8().tableau
    weights = jax.random.normal(jax.random.key(3), (7, BLOCK))

    def f(scalars, omega):
        (q1, w1), (qe, we) = fused_step(tableau, True, True, scalars, quat, omega)
        return jnp.sum(weights * jnp.concatenate([q1, w1])) + jnp.sum(qe) + jnp.sum(we)

    scalars = scalar_vector(0.1, body, jnp.float64)
    g_scalars, g_omega = jax.grad(f, argnums=(0, 1))(scalars, omega)
    directions = (
        (jnp.zeros(8).at[0].set(1.0), jnp.zeros_like(omega)),  # dt
        (jnp.zeros(8).at[2].set(1.0).at[5].set(-0.25), jnp.zeros_like(omega)),  # J_2, 1/J_2
        (jnp.zeros(8), jax.random.normal(jax.random.key(4), omega.shape)),  # omega
    )
    h = 1e-6
    for d_scalars, d_omega in directions:
        plus = f(scalars + h * d_scalars, omega + h * d_omega)
        minus = f(scalars - h * d_scalars, omega - h * d_omega)
        fd = float((plus - minus) / (2 * h))
        reverse = float(jnp.vdot(g_scalars, d_scalars) + jnp.vdot(g_omega, d_omega))
        _, forward = jax.jvp(f, (scalars, omega), (d_scalars, d_omega))
        assert abs(reverse - fd) <= 1e-6 * max(1.0, abs(fd))
        assert abs(float(forward) - reverse) <= 1e-12 * max(1.0, abs(reverse))


def test_simulate_on_a_gpu_uses_the_fused_step_for_a_batch(monkeypatch):
    """`simulate` of a batch sharing one free body, as on a GPU (the kernel interpreted):
    the fused solver is chosen, the batch (not a whole number of blocks) is padded with its
    last member and cut back, and steps and states equal the CPU's plain Dopri8 solve."""
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, I123))
    n = BLOCK + 5
    quat, omega = _members(n, seed=5)
    states = jaxrb.make_state(quat=quat.T, omega=omega.T)
    ts = jnp.array([0.0, 3.0])

    def run():
        return jaxrb.simulate(scene, states, ts, solver=dfx.Dopri8(), rtol=1e-9, atol=1e-9)

    ref = run()
    chosen = []

    def interpreted(solver, body):
        chosen.append(fused_rotation_solver(solver, body, interpret=True))
        return chosen[-1]

    monkeypatch.setitem(_persistent._KEEP, "on", False)
    monkeypatch.setattr(_batched, "on_gpu", lambda: True)
    monkeypatch.setattr(_batched, "fused_rotation_solver", interpreted)
    out = jaxrb.simulate(scene, states, ts, solver=dfx.Dopri8(), rtol=1e-9, atol=1e-9)
    assert [type(s).__name__ for s in chosen] == ["FusedRotationDopri8"]
    assert out.states.omega.shape == (n, 2, 3)
    assert np.array_equal(out.num_steps, ref.num_steps)
    np.testing.assert_allclose(out.states.omega, ref.states.omega, rtol=0, atol=1e-11)
    np.testing.assert_allclose(out.states.quat, ref.states.quat, rtol=0, atol=1e-11)


MOMENTS = jnp.array([2.0, 2.5, 3.0])  # principal moments inside the triangle inequality


def _member_inertias(n, full, seed=6):
    """n inertias about MOMENTS or FULL, each its own (5 % or a symmetric perturbation of
    0.1), and their inverses: (N, 3) or (N, 3, 3)."""
    u = jax.random.uniform(jax.random.key(seed), (n, 3, 3), minval=-0.1, maxval=0.1)
    if full:
        inertia = FULL + 0.5 * (u + jnp.swapaxes(u, 1, 2))
        return inertia, jnp.linalg.inv(inertia)
    inertia = MOMENTS * (1.0 + 0.5 * u[:, 0])
    return inertia, 1.0 / inertia


@pytest.mark.parametrize("full", [False, True], ids=["principal", "full"])
def test_the_per_member_step_and_its_inertia_derivative(full):
    """Each member with its own J and J^-1 (`member_rows`): the kernel equals the same step
    in jax.numpy, equals the shared-inertia kernel where all members share one J, leaves a
    flagged member still, and its reverse-mode derivative along a change of some members'
    J entries equals central differences (float64); forward mode equals reverse mode."""
    quat, omega = _members(BLOCK, seed=7)
    inertia, inverse = _member_inertias(BLOCK, full)
    valid = jnp.ones(BLOCK, bool).at[5].set(False)
    rows = member_rows(inertia, inverse, valid)
    dt = scalar_vector(0.05, None, jnp.float64, per_member=True)
    tableau = dfx.Dopri8().tableau
    got = fused_step(tableau, not full, True, dt, quat, omega, rows)
    want = _xla_step(tableau, not full, dt, quat, omega, rows)
    for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-15)
    (q1, w1), (qe, we) = got
    assert np.array_equal(q1[:, 5], quat[:, 5]) and np.array_equal(w1[:, 5], omega[:, 5])
    assert not np.any(qe[:, 5]) and not np.any(we[:, 5])

    shared_inertia = FULL if full else MOMENTS
    body = jaxrb.RigidBody(1.0, shared_inertia).with_inertia_inverse()
    shared = fused_step(
        tableau, not full, True, scalar_vector(0.05, body, jnp.float64), quat, omega
    )
    one_j = member_rows(
        jnp.broadcast_to(body.inertia, (BLOCK,) + body.inertia.shape),
        jnp.broadcast_to(body.inertia_inverse, (BLOCK,) + body.inertia.shape),
        jnp.ones(BLOCK, bool),
    )
    each = fused_step(tableau, not full, True, dt, quat, omega, one_j)
    for g, w in zip(jax.tree.leaves(each), jax.tree.leaves(shared), strict=True):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-15)

    weights = jax.random.normal(jax.random.key(8), (7, BLOCK))

    def f(rows):
        (q1, w1), (qe, we) = fused_step(tableau, not full, True, dt, quat, omega, rows)
        return jnp.sum(weights * jnp.concatenate([q1, w1])) + jnp.sum(qe) + jnp.sum(we)

    direction = jnp.zeros_like(rows).at[1, :64].set(1.0)  # J's second entry, 64 members
    h = 1e-6
    fd = float((f(rows + h * direction) - f(rows - h * direction)) / (2 * h))
    reverse = float(jnp.vdot(jax.grad(f)(rows), direction))
    _, forward = jax.jvp(f, (rows,), (direction,))
    assert abs(reverse - fd) <= 1e-6 * max(1.0, abs(fd))
    assert abs(float(forward) - reverse) <= 1e-12 * max(1.0, abs(reverse))


def test_the_per_member_fused_step_takes_diffrax_steps():
    """One inertia per member and a flagged member, in diffrax's loop: the same accepted and
    rejected steps as diffrax's Dopri8 on the same per-member rates, the states at t1 and at
    a save between steps equal to roundoff, the flagged member still."""
    inertia, inverse = _member_inertias(BLOCK, full=False, seed=11)
    rows = member_rows(inertia, inverse, jnp.ones(BLOCK, bool).at[9].set(False))

    def rates(t, y, args):
        r = _rates(None, True, (*y[0], *y[1]), rows)
        return jnp.stack(r[:4]), jnp.stack(r[4:])

    def solve(solver, y0):
        return dfx.diffeqsolve(
            dfx.ODETerm(rates), solver, 0.0, 4.0, None, y0,
            saveat=dfx.SaveAt(t0=True, ts=jnp.array([1.5]), t1=True),
            stepsize_controller=dfx.PIDController(rtol=1e-9, atol=1e-9, norm=batch_rms_norm),
            max_steps=4096,
        )  # fmt: skip

    principal_body = jaxrb.RigidBody(1.0, MOMENTS)  # only says J is principal
    fused = fused_rotation_solver(dfx.Dopri8(), principal_body, interpret=True, members=rows)
    y0 = _members(BLOCK, seed=12)
    ref = jax.jit(lambda y: solve(dfx.Dopri8(), y))(y0)
    out = jax.jit(lambda y: solve(fused, y))(y0)
    for key in ("num_accepted_steps", "num_rejected_steps"):
        assert int(out.stats[key]) == int(ref.stats[key])
    for got, want in zip(out.ys, ref.ys, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11)
    assert np.array_equal(out.ys[1][:, :, 9], jnp.broadcast_to(y0[1][:, 9], (3, 3)))


def test_simulate_batch_with_an_inertia_per_member_on_a_gpu_uses_the_fused_step(monkeypatch):
    """`simulate_batch` with one inertia per member (`batched_scene`), as on a GPU (the kernel
    interpreted): the fused solver is chosen with each member's J as rows, the batch is
    padded and cut back, a member with a bad inertia is flagged as on the CPU, and the
    others' steps and states equal the CPU's masked Dopri8 solve."""
    n = BLOCK + 5
    inertia, _ = _member_inertias(n, full=False, seed=9)
    scene = jaxrb.Scene(jaxrb.RigidBody(jnp.ones(n), inertia, principal=True))
    # member 3 not positive definite (past the constructor's check): flagged in the solve
    scene = eqx.tree_at(lambda s: s.body.inertia, scene, inertia.at[3, 0].set(-1.0))
    quat, omega = _members(n, seed=10)
    states = jaxrb.make_state(quat=quat.T, omega=omega.T)
    ts = jnp.array([0.0, 1.0, 3.0])

    def run():
        return jaxrb.simulate_batch(
            scene, states, ts, solver=dfx.Dopri8(), rtol=1e-9, atol=1e-9,
            batched_scene=True, throw=False,
        )  # fmt: skip

    ref = run()
    chosen = []

    def interpreted(solver, body, members=None):
        chosen.append(fused_rotation_solver(solver, body, interpret=True, members=members))
        return chosen[-1]

    monkeypatch.setitem(_persistent._KEEP, "on", False)
    monkeypatch.setattr(_batched, "on_gpu", lambda: True)
    monkeypatch.setattr(_batched, "fused_rotation_solver", interpreted)
    out = run()
    assert [type(s).__name__ for s in chosen] == ["FusedRotationDopri8"]
    assert chosen[0].members.shape == (7, 2 * BLOCK)
    assert out.states.omega.shape == (n, 3, 3)
    ok = np.asarray(ref.result._value == 0)
    assert not ok[3] and ok.sum() == n - 1
    assert np.array_equal(np.asarray(out.result._value), np.asarray(ref.result._value))
    assert np.all(np.isnan(out.states.omega[3])) and np.all(np.isnan(ref.states.omega[3]))
    # the CPU's masked rates divide by J where the kernel multiplies by J^-1 (the kernel's
    # own arithmetic is held to diffrax's steps above): both as close to the exact flow
    exact = jax.vmap(lambda J, q, w: torque_free_flow(J, jaxrb.make_state(quat=q, omega=w), ts))(
        inertia, quat.T, omega.T
    )
    error = lambda traj: np.max(np.abs(traj.states.omega - exact.omega)[ok])  # noqa: E731
    assert error(ref) < 1e-8
    assert error(out) <= 1.5 * error(ref)


def test_the_kernel_takes_whole_blocks_only():
    """A member count that is not a whole number of blocks is refused by name (the solve
    pads it; a partial block would write past the arrays' ends)."""
    body = jaxrb.RigidBody(1.0, I123).with_inertia_inverse()
    quat, omega = _members(BLOCK + 1)
    scalars = scalar_vector(0.1, body, jnp.float64)
    with pytest.raises(ValueError, match="whole blocks"):
        fused_step(dfx.Dopri8().tableau, True, True, scalars, quat, omega)


def test_only_explicit_diffrax_methods_have_a_fused_twin():
    body = jaxrb.RigidBody(1.0, I123).with_inertia_inverse()
    assert fused_rotation_solver(dfx.Heun(), body) is None
    assert fused_rotation_solver(jaxrb.unrolled_solver(dfx.Dopri8()), body) is None
    assert type(fused_rotation_solver(dfx.Dopri5(), body)).__name__ == "FusedRotationDopri5"


@pytest.mark.parametrize("inertia", [I123, FULL], ids=["principal", "full"])
def test_the_kernel_lowers_to_triton(inertia):
    """The kernel (not interpreted) lowers for an NVIDIA GPU from this machine: every
    operation in it has a Triton lowering, for both inertia forms and a first-same-as-last
    method. (Compiling the Triton module needs the GPU; B1 ran it on an H200.)"""
    body = jaxrb.RigidBody(1.0, inertia).with_inertia_inverse()
    quat, omega = _members(2 * BLOCK)
    scalars = scalar_vector(0.1, body, jnp.float64)
    for tableau in (dfx.Dopri8().tableau, dfx.Tsit5().tableau):

        def step(scalars, quat, omega, tableau=tableau):
            return fused_step(tableau, body.principal, False, scalars, quat, omega)

        lowered = jax.jit(step).trace(scalars, quat, omega).lower(lowering_platforms=("cuda",))
        text = lowered.as_text()
        assert text.count("xla.gpu.triton") == 1
        assert "fused_rotation_step" in text
    # each member's J, J^-1 and validity as rows beside the state's
    rows = member_rows(
        jnp.broadcast_to(body.inertia, (2 * BLOCK,) + body.inertia.shape),
        jnp.broadcast_to(body.inertia_inverse, (2 * BLOCK,) + body.inertia.shape),
        jnp.ones(2 * BLOCK, bool),
    )
    dt = scalar_vector(0.1, None, jnp.float64, per_member=True)

    def per_member(dt, quat, omega, rows):
        return fused_step(dfx.Dopri8().tableau, body.principal, False, dt, quat, omega, rows)

    lowered = jax.jit(per_member).trace(dt, quat, omega, rows).lower(lowering_platforms=("cuda",))
    assert lowered.as_text().count("xla.gpu.triton") == 1
