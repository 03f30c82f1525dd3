"""Runge-Kutta steps with their stages written out (`jaxrb._unrolled_stages`): the same steps,
saves, jumps and gradients as diffrax's own solvers (float64), and the batch solve's use of
them off a CPU."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import persistent

import jaxrb
from jaxrb import _persistent, _unrolled_stages
from jaxrb._unrolled_stages import UnrolledDopri8, UnrolledTsit5, batch_solver

unrolled = jaxrb.unrolled_solver

TS = jnp.linspace(0.0, 3.0, 7)
Y0 = (jnp.array([1.0, 0.5]), jnp.array([1.0, 0.1, 1.5]))
I123 = jnp.array([1.0, 2.0, 3.0])


def rates(t, y, a):
    """A small non-autonomous system with two leaves, scaled by the parameter `a`."""
    p, w = y
    dp = jnp.stack([w[1] * p[0] - p[1], p[0] * jnp.sin(t)])
    dw = -jnp.cross(w, I123 * w) / I123
    return a * dp, a * dw


def solve(solver, a, jump_ts=None):
    return dfx.diffeqsolve(
        dfx.ODETerm(rates),
        solver,
        0.0,
        3.0,
        None,
        Y0,
        args=a,
        stepsize_controller=dfx.PIDController(rtol=1e-8, atol=1e-8, jump_ts=jump_ts),
        saveat=dfx.SaveAt(ts=TS),
    )


def final_sum(solver, a):
    return sum(jnp.sum(y[-1]) for y in solve(solver, a).ys)


# compiled once per solver, kept between runs of the suite (the solver is a static argument)
solve_kept = persistent(solve)
final_sum_kept = persistent(final_sum)
gradient_kept = persistent(lambda solver, a: jax.grad(lambda b: final_sum(solver, b))(a))
saves_kept = persistent(lambda a: solve(UnrolledTsit5(), a).ys)
batched_saves_kept = persistent(jax.vmap(lambda a: solve(UnrolledTsit5(), a).ys))


@pytest.mark.parametrize("solver", [dfx.Tsit5(), dfx.Dopri5(), dfx.Dopri8()], ids=repr)
def test_same_steps_and_saves_as_diffrax(solver):
    """Interior saves come from the solver's own interpolation of the written-out stages; a
    jump (Tsit5: the first stage evaluated again after it) changes nothing either."""
    twin = unrolled(solver)
    assert type(twin) is not type(solver) and isinstance(twin, type(solver))
    for jump_ts in (None, jnp.array([1.3])):
        ref = solve_kept(solver, 1.0, jump_ts)
        out = solve_kept(twin, 1.0, jump_ts)
        assert int(out.stats["num_steps"]) == int(ref.stats["num_steps"])
        assert int(out.stats["num_rejected_steps"]) == int(ref.stats["num_rejected_steps"])
        for y, r in zip(out.ys, ref.ys, strict=True):
            # the sums run in another order: roundoff, amplified by Dopri8's large coefficients
            np.testing.assert_allclose(y, r, rtol=0, atol=1e-11)


@pytest.mark.parametrize("twin", [UnrolledTsit5(), UnrolledDopri8()], ids=repr)
def test_reverse_gradient_against_finite_differences(twin):
    grad = float(gradient_kept(twin, 1.0))
    h = 1e-5
    fd = (float(final_sum_kept(twin, 1.0 + h)) - float(final_sum_kept(twin, 1.0 - h))) / (2 * h)
    base = float(gradient_kept(dfx.Dopri8(), 1.0))
    assert abs(grad - fd) < 1e-6 * abs(fd)
    assert abs(grad - base) < 1e-6 * abs(base)


def test_under_vmap_equals_each_member_alone():
    """The FSAL first stage is taken under `jax.vmap` too (its condition is batch-wide)."""
    a = jnp.array([0.5, 1.0, 1.7])
    batched = batched_saves_kept(a)
    for i in range(3):
        for y, r in zip(batched, saves_kept(a[i]), strict=True):
            np.testing.assert_allclose(y[i], r, rtol=0, atol=1e-12)


def test_other_solvers_are_left_as_they_are():
    for solver in (dfx.Heun(), dfx.Kvaerno5(), dfx.Euler()):
        assert unrolled(solver) is solver
    assert type(batch_solver(dfx.Dopri8())) is dfx.Dopri8  # this suite runs on a CPU


def test_batch_solve_off_a_cpu_uses_the_written_out_stages(monkeypatch):
    """`simulate` of a batch as one solve, as it runs on a GPU: the same steps as on a CPU,
    the trajectories equal to roundoff. The run off a CPU is traced afresh: it saves once
    more (at t = 1), so it is not the program this process compiled for the first run, and
    programs kept on disk are off for it (their key does not see the patched backend)."""
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, I123))
    omega = jnp.array([[1.0, 0.0, 1.5], [0.7, 0.0, 1.2], [1.3, 0.1, 1.9]])
    states = jaxrb.make_state(omega=omega)

    def run(ts):
        return jaxrb.simulate(scene, states, ts, solver=dfx.Dopri8(), rtol=1e-10, atol=1e-10)

    ref = run(jnp.array([0.0, 2.0, 5.0]))
    seen = []

    def recorded(solver):
        seen.append(unrolled(solver))
        return seen[-1]

    monkeypatch.setitem(_persistent._KEEP, "on", False)
    monkeypatch.setattr(_unrolled_stages, "on_cpu", lambda: False)
    monkeypatch.setattr(_unrolled_stages, "unrolled_solver", recorded)
    out = run(jnp.array([0.0, 1.0, 2.0, 5.0]))
    assert [type(s) for s in seen] == [UnrolledDopri8]
    assert np.array_equal(out.num_steps, ref.num_steps)
    same_times = jax.tree.map(lambda x: x[:, jnp.array([0, 2, 3])], out.states)
    np.testing.assert_allclose(same_times.omega, ref.states.omega, rtol=0, atol=1e-11)
    np.testing.assert_allclose(same_times.quat, ref.states.quat, rtol=0, atol=1e-11)


def test_one_body_simulate_with_the_twin_equals_diffrax_loop():
    """`jaxrb.unrolled_solver` as `simulate`'s solver for one free body: the same steps and,
    to roundoff, the same trajectory as with diffrax's own Dopri8."""
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, I123))
    state = jaxrb.make_state(omega=jnp.array([1.0, 0.05, 1.5]))
    ts = jnp.linspace(0.0, 5.0, 6)
    kw = dict(rtol=1e-10, atol=1e-10)
    ref = jaxrb.simulate(scene, state, ts, solver=dfx.Dopri8(), **kw)
    out = jaxrb.simulate(scene, state, ts, solver=jaxrb.unrolled_solver(dfx.Dopri8()), **kw)
    assert int(out.num_steps) == int(ref.num_steps)
    np.testing.assert_allclose(out.states.omega, ref.states.omega, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.states.quat, ref.states.quat, rtol=0, atol=1e-12)
