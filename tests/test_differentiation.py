"""Gradients through `simulate` vs finite differences; vmap == loop; no recompilation."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from programs import traces

import jaxrb
from jaxrb._simulate import _simulate_smooth

# Fixed steps make the discrete solution a smooth function of every parameter, so the
# derivative of the discrete map (AD) and central differences agree to O(h^2).
FIXED = dict(
    solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=0.01, max_steps=400
)
TS = jnp.array([0.0, 1.0, 2.0])
J_FULL = jnp.array([[1.2, -0.1, 0.05], [-0.1, 2.0, -0.2], [0.05, -0.2, 2.9]])


def make_scene(params):
    body = jaxrb.RigidBody(params["mass"], params["inertia"])
    forces = (
        jaxrb.Gravity(),
        jaxrb.LinearDrag(params["c1"]),
        jaxrb.QuadraticDrag(params["k2"]),
        jaxrb.DampingMoment(params["cw"], params["cw2"]),
    )
    return jaxrb.Scene(body, forces=forces)


PARAMS = dict(
    mass=jnp.array(1.3),
    inertia=J_FULL,
    c1=jnp.array(0.2),
    k2=jnp.array(0.05),
    cw=jnp.array(0.03),
    cw2=jnp.array(0.02),
    omega0=jnp.array([0.9, 0.4, -1.2]),
    vel0=jnp.array([2.0, 0.5, 4.0]),
)
WEIGHTS = jax.random.normal(jax.random.key(7), (13,))


def final_observable(params, adjoint=None):
    state0 = jaxrb.make_state(
        quat=jnp.array([0.9, 0.1, -0.3, 0.2]), vel=params["vel0"], omega=params["omega0"]
    )
    kwargs = dict(FIXED) if adjoint is None else dict(FIXED, adjoint=adjoint)
    traj = jaxrb.simulate(make_scene(params), state0, TS, **kwargs)
    final = jax.tree.map(lambda x: x[-1], traj.states)
    flat = jnp.concatenate([final.pos, final.quat[1:], final.vel, final.omega])
    return jnp.sum(WEIGHTS[:12] * flat)


def central_difference(f, params, name, index, h=1e-5):
    def shifted(delta):
        p = dict(params)
        x = p[name]
        if name == "inertia":  # keep the tensor symmetric: perturb J_ij and J_ji together
            i, j = index
            bump = jnp.zeros((3, 3)).at[i, j].set(delta).at[j, i].set(delta)
            p[name] = x + bump
        else:
            p[name] = x.at[index].add(delta) if x.ndim else x + delta
        return f(p)

    return (shifted(h) - shifted(-h)) / (2 * h)


@pytest.fixture(scope="module")
def reverse_grad():
    return jax.grad(final_observable)(PARAMS)


CASES = [
    ("mass", ()),
    ("c1", ()),
    ("k2", ()),
    ("cw", ()),
    ("cw2", ()),
    ("inertia", (0, 0)),
    ("inertia", (1, 1)),
    ("inertia", (0, 1)),
    ("inertia", (1, 2)),
    ("omega0", 0),
    ("omega0", 2),
    ("vel0", 1),
]


@pytest.mark.parametrize("name, index", CASES)
def test_reverse_mode_gradient_matches_finite_differences(reverse_grad, name, index):
    fd = central_difference(final_observable, PARAMS, name, index)
    g = reverse_grad[name]
    if name == "inertia":
        i, j = index
        ad = g[i, j] + (g[j, i] if i != j else 0.0)
    else:
        ad = g[index] if g.ndim else g
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


def test_forward_mode_equals_reverse_mode(reverse_grad):
    """jax.jvp with diffrax.ForwardMode gives the same directional derivative."""
    tangent = jax.tree.map(lambda x: jnp.full_like(x, 0.1), PARAMS)
    _, fwd = jax.jvp(lambda p: final_observable(p, dfx.ForwardMode()), (PARAMS,), (tangent,))
    rev = sum(
        jnp.sum(g * t)
        for g, t in zip(jax.tree.leaves(reverse_grad), jax.tree.leaves(tangent), strict=True)
    )
    np.testing.assert_allclose(fwd, rev, rtol=1e-10)


@pytest.fixture(scope="module")
def batch():
    key = jax.random.key(3)
    omega0 = jax.random.uniform(key, (1000, 3), minval=-2.0, maxval=2.0)
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([1.0, 2.0, 3.0])), forces=(jaxrb.Gravity(),))
    ts = jnp.linspace(0.0, 2.0, 5)

    def run(w):
        return jaxrb.simulate(scene, jaxrb.make_state(omega=w), ts, throw=False)

    return omega0, run, jax.jit(jax.vmap(run))(omega0)


def test_vmap_over_1000_initial_conditions_equals_loop(batch):
    omega0, run, batched = batch
    assert batched.states.omega.shape == (1000, 5, 3)
    assert bool(jnp.all(batched.result == jaxrb.RESULTS.successful))
    single = jax.jit(run)
    for i in range(0, 1000, 97):  # every 97th member, run on its own
        one = single(omega0[i])
        for a, b in zip(jax.tree.leaves(one.states), jax.tree.leaves(batched.states), strict=True):
            np.testing.assert_allclose(a, b[i], rtol=1e-13, atol=1e-13)


def test_vmap_over_scene_parameters():
    masses = jnp.array([0.5, 1.0, 2.0])
    inertias = jnp.array([[1.0, 2.0, 3.0], [1.5, 2.0, 2.5], [2.0, 2.0, 3.0]])
    ts = jnp.linspace(0.0, 1.0, 3)
    state0 = jaxrb.make_state(vel=(1.0, 0.0, 2.0), omega=(0.3, 1.0, 0.2))

    def run(m, J):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(m, J), forces=(jaxrb.Gravity(), jaxrb.QuadraticDrag(0.1))
        )
        return jaxrb.simulate(scene, state0, ts).states

    batched = jax.vmap(run)(masses, inertias)
    for i in range(3):
        one = run(masses[i], inertias[i])
        np.testing.assert_allclose(batched.vel[i], one.vel, rtol=1e-12)
        np.testing.assert_allclose(batched.omega[i], one.omega, rtol=1e-12)


def test_jit_equals_eager_and_no_recompilation_on_new_values():
    ts = jnp.linspace(0.0, 1.0, 3)
    scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.array([1.0, 2.0, 3.0])), forces=(jaxrb.Gravity(),))
    jitted = jax.jit(lambda s, w: jaxrb.simulate(s, jaxrb.make_state(omega=w), ts))
    jaxrb.simulate(scene, jaxrb.make_state(omega=(0.1, 0.2, 0.3)), ts)
    eager_traces = traces(_simulate_smooth)
    for k in range(3):
        scene_k = eqx.tree_at(lambda s: s.body.mass, scene, jnp.array(1.0 + k))
        omega = jnp.array([0.1 * k, 0.2, 0.3])
        eager = jaxrb.simulate(scene_k, jaxrb.make_state(omega=omega), ts)
        np.testing.assert_allclose(
            eager.states.omega, jitted(scene_k, omega).states.omega, rtol=1e-14
        )
    assert jitted._cache_size() == 1
    # the eager path compiled once before the loop; only the jitted path's trace was added
    assert traces(_simulate_smooth) <= eager_traces + 1
