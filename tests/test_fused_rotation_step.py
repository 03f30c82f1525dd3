"""A batch's free-rotation step as one kernel (`jaxrb._fused_rotation_step`): the same steps
as diffrax's solver, the same results to roundoff, derivatives equal to finite differences.
The kernel is Triton's (a GPU); here it runs in Pallas's interpreter, the same kernel
function on the CPU."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
from jaxrb import _batched, _persistent
from jaxrb._batched import batch_rms_norm
from jaxrb._coordinates import ROTATION
from jaxrb._fused_rotation_step import (
    BLOCK,
    _xla_step,
    fused_rotation_solver,
    fused_step,
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
