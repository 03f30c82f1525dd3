"""Scene files: the default scene parses; each kind of mistake gives one clear error."""

import numpy as np
import pytest

import jaxrb
from jaxrb._scene_examples import EXAMPLES, example_path
from jaxrb._scene_file import (
    SceneFileError,
    default_scene_path,
    load_scene,
    loads_scene,
    with_t_end,
)

B = "[body]\nmass = 1.0\ninertia = [1, 2, 3]\n"
S = "[simulation]\nt_end = 1.0\n"
HINGE = '[joint]\ntype = "hinge"\npoint = [-0.25, 0, 0]\naxis = [0, 2, 0]\n'
PIVOT = '[joint]\ntype = "pivot"\npoint = [0, 0, -0.1]\n'
MINIMAL = """
[body]
mass = 2.0
inertia = [1.0, 2.0, 3.0]
[simulation]
t_end = 1.0
"""


def test_default_scene_parses():
    spec = load_scene(default_scene_path())
    scene = spec.scene
    assert isinstance(scene.body.shape, jaxrb.Box)
    np.testing.assert_allclose(scene.body.shape.half_extents, 0.008)
    assert float(scene.body.mass) == 0.0045
    assert [type(f) for f in scene.forces] == [
        jaxrb.Gravity,
        jaxrb.QuadraticDrag,
        jaxrb.DampingMoment,
    ]
    np.testing.assert_allclose(scene.forces[1].coefficient, 0.5 * 1.225 * 1.05 * 2.56e-4)
    assert float(scene.floor.restitution) == 0.5 and float(scene.floor.friction) == 0.3
    assert spec.ts[0] == 0.0 and spec.ts[-1] == 0.6 and spec.ts.size == 241
    np.testing.assert_allclose(np.linalg.norm(spec.state0.quat), 1.0, rtol=1e-12)
    np.testing.assert_allclose(spec.state0.omega, [18.0, -11.0, 7.0])
    assert spec.options == {
        "rtol": 1e-6,
        "atol": 1e-6,
        "max_steps": 100000,
        "solver": "tsit5",
        "max_impacts": 64,
    }


def test_minimal_defaults():
    spec = loads_scene(MINIMAL)
    assert spec.scene.body.principal
    np.testing.assert_allclose(spec.scene.body.inertia, [1.0, 2.0, 3.0])
    assert spec.scene.forces == () and spec.scene.floor is None and spec.scene.joint is None
    np.testing.assert_allclose(spec.state0.quat, [1.0, 0.0, 0.0, 0.0])
    assert spec.ts.size == 201


def test_attitude_forms_agree():
    """axis + angle_deg, euler_deg + sequence and quat give the same attitude."""
    base = MINIMAL + "[initial]\n"
    q_axis = loads_scene(base + "axis = [0, 0, 2]\nangle_deg = 90\n").state0.quat
    q_euler = loads_scene(base + 'euler_deg = [90, 0, 0]\nsequence = "321"\n').state0.quat
    q_quat = loads_scene(
        base + f"quat = [{np.cos(np.pi / 4)}, 0, 0, {np.sin(np.pi / 4)}]\n"
    ).state0.quat
    np.testing.assert_allclose(q_axis, q_quat, atol=1e-15)
    np.testing.assert_allclose(q_euler, q_quat, atol=1e-15)
    # "313" (psi, theta, phi) = R3(psi) R1(theta) R3(phi)
    q = loads_scene(base + 'euler_deg = [30, 40, 50]\nsequence = "313"\n').state0.quat
    R = np.asarray(jaxrb.quat_to_matrix(q))

    def rot(axis, deg):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        if axis == 1:
            return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    np.testing.assert_allclose(R, rot(3, 30) @ rot(1, 40) @ rot(3, 50), atol=1e-14)


def test_full_inertia_tensor_and_joint():
    spec = loads_scene(
        """
[body]
mass = 7.5
inertia = [[0.1, -0.01, 0.0], [-0.01, 0.2, 0.0], [0.0, 0.0, 0.25]]
[joint]
type = "hinge"
point = [0.25, 0, 0]
axis = [0, 1, 0]
[simulation]
t_end = 0.5
num_saves = 11
"""
    )
    assert not spec.scene.body.principal
    assert isinstance(spec.scene.joint, jaxrb.Hinge)
    np.testing.assert_allclose(spec.scene.joint.axis, [0.0, 1.0, 0.0])


@pytest.mark.parametrize(
    "text, field, problem",
    [
        # missing field
        (
            "[body]\ninertia = [1, 2, 3]\n" + S,
            "[body].mass",
            "missing required field",
        ),
        (B + "", "[simulation]", "missing required table"),
        # wrong type
        (
            '[body]\nmass = "heavy"\ninertia = [1, 2, 3]\n[simulation]\nt_end = 1.0\n',
            "[body].mass",
            "must be a number, got a string",
        ),
        (
            B + "[initial]\nomega = [1, 2]\n" + S,
            "[initial].omega",
            "must be a list of 3 numbers",
        ),
        (
            B + "[simulation]\nt_end = 1.0\nnum_saves = 10.5\n",
            "[simulation].num_saves",
            "must be an integer",
        ),
        # unknown force
        (
            '[body]\nmass = 1.0\ninertia = [1, 2, 3]\n[[forces]]\ntype = "gravty"\n'
            "[simulation]\nt_end = 1.0\n",
            "[[forces]][0].type",
            "unknown force 'gravty' (did you mean 'gravity'?)",
        ),
        # negative mass
        (
            "[body]\nmass = -1.0\ninertia = [1, 2, 3]\n" + S,
            "[body].mass",
            "must be > 0, got -1.0",
        ),
        # other impossible values
        (
            B + "[floor]\nrestitution = 1.5\n" + S,
            "[floor].restitution",
            "must be in [0.0, 1.0], got 1.5",
        ),
        (
            "[body]\nmass = 1.0\ninertia = [1, 1, 3]\n" + S,
            "[body].inertia",
            "triangle",
        ),
        (
            B + "[simulation]\nt_end = -1.0\n",
            "[simulation].t_end",
            "must be greater than t_start",
        ),
        (
            B + "[simulation]\nt_start = -1e308\nt_end = 1e308\n",
            "[simulation].t_end",
            "t_end - t_start overflows",
        ),
        (
            B + S + "num_saves = 20000000\n",
            "[simulation].num_saves",
            "20000000 saves would make 2.4 GB of output arrays (120 bytes each); "
            "the limit is 1 GB, at most 8333333 saves",
        ),
        (
            B + S + "max_steps = 10000000000000\n",
            "[simulation].max_steps",
            "must be <= 1000000000000",
        ),
        # initial values whose energy overflows, a body below the floor
        (
            B + "[initial]\nvel = [1e200, 0, 0]\n" + S,
            "[initial].vel",
            "the kinetic energy 1/2 m |vel|^2 is inf J (mass 1 kg): too large to simulate",
        ),
        (
            B + "[initial]\nomega = [0, 0, 1e200]\n" + S,
            "[initial].omega",
            "the kinetic energy 1/2 omega.J omega is inf J",
        ),
        (
            B.replace("inertia = [1, 2, 3]", '[body.shape]\ntype = "sphere"\nradius = 0.5')
            + "[floor]\nrestitution = 0.5\nheight = 0.2\n[initial]\npos = [0, 0, 0.5]\n"
            + S,
            "[initial].pos",
            "the body starts below the [floor]: its lowest point is 0.2 m under the plane "
            "z = 0.2 m",
        ),
        # an integer too large for a float, a shape whose inertia overflows
        (
            "[body]\nmass = 1" + "0" * 400 + "\ninertia = [1, 2, 3]\n" + S,
            "[body].mass",
            "must be finite, got 1000",
        ),
        (
            '[body]\nmass = 1.0\n[body.shape]\ntype = "sphere"\nradius = 1e200\n' + S,
            "[body].shape",
            "inertia",
        ),
        # unknown field (typo)
        (
            B + "shpe = 1\n" + S,
            "[body].shpe",
            "unknown field (did you mean 'shape'?)",
        ),
        (
            '[body]\nmass = 1.0\ninertia = [1, 2, 3]\n[[forces]]\ntype = "linear_drag"\nk = 1.0\n'
            "" + S,
            "[[forces]][0].k",
            "unknown field",
        ),
        # a key with a line break: quoted, so that the message stays one line
        (
            B + '"\\n" = 0\n' + S,
            "[body].'\\n'",
            "unknown field; allowed here: mass, inertia, shape",
        ),
        # a floor needs a shape
        (
            B + "[floor]\nrestitution = 0.5\n" + S,
            "[floor]",
            "needs a [body.shape]",
        ),
        # motion a joint cannot have
        (
            B + HINGE + "[initial]\nomega = [1, 2, 0]\n" + S,
            "[initial].omega",
            "the [joint] (hinge) turns the body only about its axis [0, 1, 0] (body frame); "
            "omega = [1, 2, 0] rad/s has the part [1, 0, 0] off that axis",
        ),
        (
            B + PIVOT + "[initial]\nomega = [0, 0, 5]\nvel = [1, 0, 0]\n" + S,
            "[initial].vel",
            "the [joint] (pivot) sets the mass centre's velocity from omega, "
            "R (omega x (C - O)) = [0, 0, 0] m/s; got [1, 0, 0] m/s: leave `vel` out",
        ),
    ],
)
def test_invalid_files_name_field_and_problem(text, field, problem):
    with pytest.raises(SceneFileError) as info:
        loads_scene(text, source="bad.toml")
    message = str(info.value)
    assert message.startswith(f"bad.toml: {field}: "), message
    assert problem in message, message


def test_huge_attitude_vectors_are_normalised_without_overflow():
    """A quaternion or axis of norm 1e308 (whose squared norm overflows) is a direction."""
    base = MINIMAL + "[initial]\n"
    q = loads_scene(base + "quat = [1e308, 1e308, 0, 0]\n").state0.quat
    np.testing.assert_allclose(q, [2**-0.5, 2**-0.5, 0.0, 0.0], rtol=1e-15)
    q_axis = loads_scene(base + "axis = [0, 0, 1e308]\nangle_deg = 90\n").state0.quat
    np.testing.assert_allclose(q_axis, [2**-0.5, 0.0, 0.0, 2**-0.5], rtol=1e-15)
    hinge = HINGE.replace("[0, 2, 0]", "[0, 1e308, 0]")
    spec = loads_scene(B + hinge + S)
    np.testing.assert_allclose(spec.scene.joint.axis, [0.0, 1.0, 0.0])


def test_read_scene_text(tmp_path):
    """UTF-8 with or without a byte-order mark; binary, oversized and directories refused."""
    path = tmp_path / "s.toml"
    path.write_bytes("\ufeff".encode() + MINIMAL.encode())
    assert load_scene(path).ts.size == 201
    path.write_bytes(b"\x00\xff")
    with pytest.raises(SceneFileError, match=r"s.toml: not a text file: byte 1 is not UTF-8"):
        load_scene(path)
    path.write_bytes(b"#" * 2_000_000)
    with pytest.raises(SceneFileError, match=r"s.toml: larger than 1000 kB"):
        load_scene(path)
    with pytest.raises(SceneFileError, match="is a directory, not a scene file"):
        load_scene(tmp_path)


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(SceneFileError, match="not valid TOML"):
        loads_scene("[body\nmass = 1")
    with pytest.raises(SceneFileError, match="not valid TOML: nested too deeply"):
        loads_scene("x = " + "[" * 5000 + "]" * 5000)
    with pytest.raises(SceneFileError, match="empty scene: expected at least"):
        loads_scene("# only a comment\n")
    with pytest.raises(SceneFileError, match="no such scene file"):
        load_scene(tmp_path / "nope.toml")


def test_joint_motion_that_fits_is_accepted():
    """omega along a hinge's axis, and the velocity the joint gives the mass centre."""
    spec = loads_scene(B + HINGE + "[initial]\nomega = [0, 3, 0]\nvel = [0, 0, -0.75]\n" + S)
    np.testing.assert_allclose(spec.state0.vel, [0.0, 0.0, -0.75])
    spec = loads_scene(B + PIVOT + "[initial]\nomega = [2, 0, 5]\nvel = [0, -0.2, 0]\n" + S)
    np.testing.assert_allclose(spec.state0.omega, [2.0, 0.0, 5.0])


def test_with_t_end_keeps_the_file_and_sets_t_end():
    text = load_scene(default_scene_path()).data
    new = with_t_end(default_scene_path().read_text(), 0.25)
    assert loads_scene(new).data == {**text, "simulation": {**text["simulation"], "t_end": 0.25}}
    assert "# A 16 mm plastic die" in new and "set by --t-end (the file had 0.6)" in new
    inline = "simulation = {t_end = 1.0}\n" + B
    with pytest.raises(SceneFileError, match=r"\[simulation\].t_end: --t-end cannot rewrite"):
        with_t_end(inline, 2.0, "inline.toml")


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_examples_parse(name):
    spec = load_scene(example_path(name))
    assert spec.title and spec.ts.size >= 2


def test_pendulum_example_is_the_sample_problem():
    """m = 7.5 kg, rbar = 0.25 m, k_O = 0.295 m, released from rest with OC horizontal."""
    from jaxrb._reaction import released_pendulum

    spec = load_scene(example_path("pendulum"))
    release = released_pendulum(spec.scene, spec.state0)
    assert release is not None and release.sign == 1.0
    np.testing.assert_allclose(
        [release.mass, release.rbar, release.k_O, release.g], [7.5, 0.25, 0.295, 9.81], rtol=1e-14
    )
