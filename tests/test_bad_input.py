"""Bad input ends in a clear error or a per-member flag, never a silent NaN."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import pytest

import jaxrb

I123 = jnp.array([1.0, 2.0, 3.0])
TS = jnp.linspace(0.0, 1.0, 3)


def scene_with(mass=1.0, inertia=I123):
    return jaxrb.Scene(jaxrb.RigidBody(mass, inertia), forces=(jaxrb.Gravity(),))


@pytest.mark.parametrize("mass", [0.0, -1.0])
def test_nonpositive_mass_raises(mass):
    with pytest.raises(ValueError, match="mass must be > 0"):
        jaxrb.RigidBody(mass, I123)


def test_nonfinite_mass_raises():
    with pytest.raises(ValueError, match="mass must be finite"):
        jaxrb.RigidBody(jnp.nan, I123)


@pytest.mark.parametrize(
    "inertia, condition",
    [
        (jnp.array([[1.0, 0.2, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.5]]), "symmetric"),
        (jnp.array([1.0, -2.0, 3.0]), "positive definite"),
        (jnp.array([1.0, 1.0, 3.0]), "triangle"),
    ],
)
def test_invalid_inertia_names_the_condition(inertia, condition):
    with pytest.raises(ValueError, match=condition):
        jaxrb.RigidBody(1.0, inertia)


def test_wrong_inertia_shape_names_the_argument():
    with pytest.raises(ValueError, match="inertia"):
        jaxrb.RigidBody(1.0, jnp.ones((2, 2)))


@pytest.mark.parametrize("field", ["pos", "quat", "vel", "omega"])
def test_nonfinite_state_names_the_field(field):
    state = jaxrb.make_state()
    state = eqx.tree_at(
        lambda s: getattr(s, field), state, getattr(state, field).at[0].set(jnp.nan)
    )
    with pytest.raises(ValueError, match=f"state0.{field}"):
        jaxrb.simulate(scene_with(), state, TS)


def test_decreasing_times_raise():
    with pytest.raises(ValueError, match="non-decreasing"):
        jaxrb.simulate(scene_with(), jaxrb.make_state(), jnp.array([1.0, 0.0]))


def test_wrong_state_shape_names_the_field():
    state = jaxrb.State(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), jnp.zeros(3), jnp.zeros(3))
    with pytest.raises(ValueError, match="state0.quat"):
        jaxrb.simulate(scene_with(), state, TS)


def test_max_steps_raises_or_flags():
    state = jaxrb.make_state(omega=(1.0, 2.0, 3.0))
    with pytest.raises(Exception, match="max_steps"):
        jaxrb.simulate(scene_with(), state, TS, max_steps=2)
    traj = jaxrb.simulate(scene_with(), state, TS, max_steps=2, throw=False)
    assert traj.result == jaxrb.RESULTS.max_steps_reached


def test_traced_bad_mass_is_flagged_per_batch_member():
    masses = jnp.array([1.0, -1.0, 2.0, 0.0])

    def run(m):
        scene = jaxrb.Scene(jaxrb.RigidBody(m, I123), forces=(jaxrb.Gravity(),))
        return jaxrb.simulate(scene, jaxrb.make_state(omega=(0.1, 0.2, 0.3)), TS, throw=False)

    result = jax.vmap(run)(masses).result
    expected = [jaxrb.RESULTS.successful, jaxrb.RESULTS.invalid_mass] * 2
    for r, e in zip(result._value, expected, strict=True):
        assert r == e._value


def test_traced_bad_input_raises_when_asked():
    def run(m):
        scene = jaxrb.Scene(jaxrb.RigidBody(m, I123), forces=(jaxrb.Gravity(),))
        return jaxrb.simulate(scene, jaxrb.make_state(), TS, throw=True).states.pos

    with pytest.raises(Exception, match="mass must be finite and > 0"):
        jax.block_until_ready(jax.vmap(run)(jnp.array([1.0, -1.0])))


def test_traced_invalid_inertia_and_state_flagged():
    def run(J, w):
        scene = jaxrb.Scene(jaxrb.RigidBody(1.0, J))
        return jaxrb.simulate(scene, jaxrb.make_state(omega=w), TS, throw=False).result

    bad_J = jax.jit(run)(jnp.array([1.0, 1.0, 3.0]), jnp.ones(3))
    assert bad_J == jaxrb.RESULTS.invalid_inertia
    bad_w = jax.jit(run)(I123, jnp.array([1.0, jnp.inf, 0.0]))
    assert bad_w == jaxrb.RESULTS.nonfinite_state


def test_unknown_force_type_is_rejected():
    with pytest.raises(TypeError, match="forces\\[0\\]"):
        jaxrb.Scene(jaxrb.RigidBody(1.0, I123), forces=("gravity",))


def test_scene_forces_must_be_tuple():
    with pytest.raises(TypeError, match="tuple"):
        jaxrb.Scene(jaxrb.RigidBody(1.0, I123), forces=[jaxrb.Gravity()])


@pytest.mark.parametrize("e", [-0.1, 1.5])
def test_restitution_out_of_range(e):
    with pytest.raises(ValueError, match="restitution"):
        jaxrb.Floor(restitution=e)


def test_negative_friction():
    with pytest.raises(ValueError, match="friction"):
        jaxrb.Floor(restitution=0.5, friction=-0.1)


def test_solver_choice_passes_through():
    traj = jaxrb.simulate(
        scene_with(), jaxrb.make_state(omega=(1.0, 0.0, 0.0)), TS, solver=dfx.Dopri5()
    )
    assert traj.result == jaxrb.RESULTS.successful
