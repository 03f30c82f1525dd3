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


# --- every model parameter is validated where it is made, naming class and field ---------


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: jaxrb.Sphere(jnp.nan), "Sphere.radius"),
        (lambda: jaxrb.Sphere(-0.02), "Sphere.radius"),
        (lambda: jaxrb.Box([-0.1, -0.1, -0.1]), "Box.half_extents"),
        (lambda: jaxrb.Box([0.1, 0.0, 0.1]), "Box.half_extents"),
        (lambda: jaxrb.Cylinder(0.01, jnp.inf), "Cylinder.half_height"),
        (lambda: jaxrb.Cylinder(0.0, 0.001), "Cylinder.radius"),
        (lambda: jaxrb.Gravity([0.0, 0.0, jnp.nan]), "Gravity.g"),
        (lambda: jaxrb.LinearDrag(jnp.nan), "LinearDrag.coefficient"),
        (lambda: jaxrb.QuadraticDrag(-1.0), "QuadraticDrag.coefficient"),
        (lambda: jaxrb.DampingMoment(linear=jnp.inf), "DampingMoment.linear"),
        (lambda: jaxrb.DampingMoment(quadratic=-1e-3), "DampingMoment.quadratic"),
        (lambda: jaxrb.Wrench(force=[jnp.nan, 0.0, 0.0]), "Wrench.force"),
        (lambda: jaxrb.Wrench(torque=[0.0, 1.0, 0.0], point=[0.0, jnp.inf, 0.0]), "Wrench.point"),
        (lambda: jaxrb.Pivot([jnp.nan, 0.0, 0.5]), "Pivot.point"),
        (lambda: jaxrb.Hinge(axis=(0.0, 0.0, 0.0)), "Hinge.axis"),
        (lambda: jaxrb.Hinge(axis=(jnp.nan, 0.0, 1.0)), "Hinge.axis"),
        (lambda: jaxrb.Hinge(point=(jnp.inf, 0.0, 0.0)), "Hinge.point"),
        (lambda: jaxrb.Floor(0.5, height=jnp.nan), "Floor.height"),
        (lambda: jaxrb.Floor(jnp.nan), "Floor.restitution"),
    ],
)
def test_bad_parameter_names_class_and_field(make, name):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        make()


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(rtol=jnp.nan), "rtol"),
        (dict(rtol=-1e-8), "rtol"),
        (dict(atol=jnp.inf), "atol"),
        (dict(rtol=0.0, atol=0.0), "rtol \\+ atol"),
        (dict(dt0=0.0), "dt0"),
        (dict(dt0=jnp.nan), "dt0"),
        (dict(max_steps=0), "max_steps"),
        (dict(max_steps=2.5), "max_steps"),
    ],
)
def test_bad_solver_setting_names_it(kwargs, name):
    with pytest.raises(ValueError, match=name):
        jaxrb.simulate(scene_with(), jaxrb.make_state(), TS, **kwargs)


def test_nonfinite_save_times_raise():
    with pytest.raises(ValueError, match="ts contains non-finite"):
        jaxrb.simulate(scene_with(), jaxrb.make_state(), jnp.array([0.0, jnp.nan, 1.0]))


# --- traced bad input: one flag per batch member, the others computed ----------------------


def _free_run(radius, g_z, drag, rtol, ts):
    scene = jaxrb.Scene(
        jaxrb.RigidBody(1.0, I123, shape=jaxrb.Sphere(radius)),
        forces=(jaxrb.Gravity(jnp.stack([0.0, 0.0, g_z])), jaxrb.LinearDrag(drag)),
    )
    state = jaxrb.make_state(vel=(1.0, 0.0, 2.0), omega=(1.0, 2.0, 3.0))
    return jaxrb.simulate(scene, state, ts, rtol=rtol, atol=1e-9, throw=False)


_free_batch = jax.jit(jax.vmap(_free_run))


def test_each_bad_member_is_flagged_and_the_others_computed():
    R = jaxrb.RESULTS
    good = dict(radius=0.1, g_z=-9.81, drag=0.1, rtol=1e-9, ts=TS)
    members = [
        ({}, R.successful),
        (dict(ts=TS[::-1]), R.decreasing_times),
        (dict(ts=TS.at[1].set(jnp.nan)), R.nonfinite_times),
        (dict(g_z=jnp.nan), R.invalid_force),
        (dict(drag=-1.0), R.invalid_force),
        (dict(radius=-0.1), R.invalid_shape),
        (dict(rtol=jnp.nan), R.invalid_tolerances),
        ({}, R.successful),
    ]
    args = {k: jnp.stack([m[0].get(k, v) for m in members]) for k, v in good.items()}
    traj = _free_batch(**args)
    ref = _free_run(**{k: jnp.asarray(v) for k, v in good.items()})
    for i, (_, code) in enumerate(members):
        assert traj.result._value[i] == code._value, i
        if code == R.successful:
            assert jnp.allclose(traj.states.pos[i], ref.states.pos, rtol=1e-12, atol=1e-12)
        else:
            # a bad member takes no solver steps: it never runs into the step budget
            assert traj.num_steps[i] == 0
    assert traj.ts[1].tolist() == TS[::-1].tolist()  # the times the user gave are returned


def test_traced_bad_joint_is_flagged():
    def run(axis, point):
        scene = jaxrb.Scene(
            jaxrb.RigidBody(1.0, I123), forces=(jaxrb.Gravity(),), joint=jaxrb.Hinge(point, axis)
        )
        return jaxrb.simulate(scene, jaxrb.make_state(), TS, throw=False).result

    axes = jnp.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    points = jnp.array([[0.0, 0.0, 0.3], [0.0, 0.0, 0.3], [jnp.nan, 0.0, 0.3]])
    result = jax.vmap(run)(axes, points)
    R = jaxrb.RESULTS
    assert [int(r) for r in result._value] == [
        R.successful._value,
        R.invalid_joint._value,
        R.invalid_joint._value,
    ]


def test_simulate_batch_flags_bad_bodies_and_computes_the_others():
    n = 4
    omega = jnp.tile(jnp.array([1.0, 2.0, 3.0]), (n, 1)).at[1, 0].set(jnp.nan)
    quat = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (n, 1)).at[2].set(0.0)
    states = jaxrb.State(jnp.zeros((n, 3)), quat, jnp.zeros((n, 3)), omega)
    traj = jaxrb.simulate_batch(scene_with(), states, TS, throw=False)
    R = jaxrb.RESULTS
    codes = [R.successful, R.nonfinite_state, R.zero_quaternion, R.successful]
    assert [int(r) for r in traj.result._value] == [c._value for c in codes]
    ref = jaxrb.simulate(
        scene_with(), jaxrb.make_state(omega=(1.0, 2.0, 3.0)), TS, rtol=1e-11, atol=1e-11
    )
    for i in (0, 3):
        assert jnp.allclose(traj.states.omega[i], ref.states.omega, rtol=1e-8, atol=1e-8)


# --- quaternions of any finite non-zero norm ----------------------------------------------


@pytest.mark.parametrize("scale", [1e-300, 1e-160, 1.0, 1e160, 1e300])
def test_quaternion_norm_does_not_matter(scale):
    q = jnp.array([0.3, -0.5, 0.2, 0.7])
    unit = q / jnp.linalg.norm(q)
    assert jnp.allclose(jaxrb.quat_normalize(q * scale), unit, rtol=1e-15, atol=1e-15)
    for seq in ("321", "313"):
        angles = jaxrb.quat_to_euler(q * scale, seq)
        assert jnp.allclose(angles, jaxrb.quat_to_euler(unit, seq), rtol=0, atol=1e-14)
        grad = jax.grad(lambda x, s=seq: jaxrb.quat_to_euler(x, s).sum())(q * scale)
        assert jnp.all(jnp.isfinite(grad))
    traj = jaxrb.simulate(scene_with(), jaxrb.make_state(quat=q * scale), TS)
    assert jnp.allclose(traj.states.quat[0], unit, rtol=1e-15, atol=1e-15)


def test_zero_quaternion_raises_when_concrete_and_is_nan_under_jit():
    with pytest.raises(ValueError, match="zero norm"):
        jaxrb.quat_to_euler(jnp.zeros(4), "321")
    with pytest.raises(ValueError, match="zero norm"):
        jaxrb.quat_normalize(jnp.zeros(4))
    angles = jax.jit(lambda q: jaxrb.quat_to_euler(q, "321"))(jnp.zeros(4))
    assert jnp.all(jnp.isnan(angles))


def test_subnormal_mass_and_quaternion_count_as_zero_everywhere():
    """XLA on a CPU flushes subnormal floats to 0 in some programs and not in others: a
    mass of 1e-320 kg or a quaternion of norm 1e-320 is refused alike by the constructor,
    the scene-file reader, the concrete checks and the traced flag."""
    from jaxrb._inputs import input_result
    from jaxrb._scene_file import SceneFileError, parse_scene

    with pytest.raises(ValueError, match=r"mass must be > 0, got 1e-320 \(subnormal"):
        jaxrb.RigidBody(1e-320, I123)
    doc = {
        "body": {"mass": 1e-320, "inertia": [1.0, 2.0, 3.0]},
        "simulation": {"t_end": 1.0},
    }
    with pytest.raises(SceneFileError, match=r"\[body\]\.mass: must be > 0"):
        parse_scene(doc, source="s.toml")
    flag = jax.jit(
        lambda m, q: input_result(
            jaxrb.Scene(jaxrb.RigidBody(m, I123)), jaxrb.make_state(quat=q), TS
        )
    )
    unit = jnp.array([1.0, 0.0, 0.0, 0.0])
    assert flag(1e-320, unit) == jaxrb.RESULTS.invalid_mass
    assert flag(1.0, 1e-320 * unit) == jaxrb.RESULTS.zero_quaternion
    assert flag(1e-300, 1e-300 * unit) == jaxrb.RESULTS.successful  # normal numbers: fine
    with pytest.raises(ValueError, match="zero norm"):
        jaxrb.simulate(scene_with(), jaxrb.make_state(quat=1e-320 * unit), TS)


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_inertia_checks_hold_at_any_scale(scale):
    jaxrb.RigidBody(1.0, jnp.array([1.0, 2.0, 2.5]) * scale)  # valid: accepted
    with pytest.raises(ValueError, match="triangle"):
        jaxrb.RigidBody(1.0, jnp.array([1.0, 1.0, 3.0]) * scale)
    assert jaxrb.inertia.is_valid_inertia(jnp.diag(jnp.array([1.0, 2.0, 2.5]) * scale))
