"""The `jaxrb` command line, called in-process through `main([...])` (one subprocess test)."""

import csv
import re
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import numpy as np
import pytest

import jaxrb.analytic
from jaxrb._cli import main
from jaxrb._scene_examples import EXAMPLES, example_path

G = 9.81
# A ball falling with linear drag: exact z(t) = z0 + (v0 + g/c) (1 - exp(-c t)) / c - g t / c,
# c = drag / mass (per unit mass).
SCENE = """
title = "ball with linear drag"
[body]
mass = 2.0
[body.shape]
type = "sphere"
radius = 0.1
[initial]
pos = [0.0, 0.0, 1.0]
vel = [0.5, 0.0, 3.0]
omega = [0.0, 0.0, 4.0]
[[forces]]
type = "gravity"
[[forces]]
type = "linear_drag"
coefficient = 0.6
[simulation]
t_end = 0.4
num_saves = 21
rtol = 1e-10
atol = 1e-10
"""


def exact_z(t, c, z0=1.0, v0=3.0):
    return z0 + (v0 + G / c) * (1 - np.exp(-c * t)) / c - G * t / c


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "ball.toml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def run_dir(scene_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "out"
    assert main(["run", str(scene_file), "-o", str(out), "-q"]) == 0
    return out


def test_run_writes_outputs(run_dir):
    for name in (
        "trajectory.npz",
        "trajectory.csv",
        "summary.txt",
        "scene.toml",
        "height_attitude.png",
        "angular_velocity.png",
        "energy.png",
    ):
        assert (run_dir / name).stat().st_size > 0, name
    data = np.load(run_dir / "trajectory.npz")
    t = data["t"]
    assert t.shape == (21,) and data["pos"].shape == (21, 3) and data["quat"].shape == (21, 4)
    np.testing.assert_allclose(data["pos"][:, 2], exact_z(t, 0.6 / 2.0), rtol=0, atol=1e-8)
    np.testing.assert_allclose(data["omega"], np.broadcast_to([0.0, 0.0, 4.0], (21, 3)), atol=1e-12)
    energy = 0.5 * 2.0 * np.sum(data["vel"] ** 2, -1) + 2.0 * G * data["pos"][:, 2]
    energy += 0.5 * (0.4 * 2.0 * 0.1**2) * 16.0
    np.testing.assert_allclose(data["energy"], energy, rtol=1e-12)
    assert data["impact_times"].size == 0
    with open(run_dir / "trajectory.csv") as f:
        rows = [r for r in csv.reader(f) if not r[0].startswith("#")]
    assert rows[0][:4] == ["t", "x", "y", "z"] and len(rows) == 22
    np.testing.assert_allclose([float(r[3]) for r in rows[1:]], data["pos"][:, 2], rtol=1e-11)
    summary = (run_dir / "summary.txt").read_text()
    assert "ball with linear drag" in summary and "successful" in summary
    assert _listed_outputs(summary) == sorted(p.name for p in run_dir.iterdir())


def _preload_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name == "jaxrb-plot-preload"]


def test_run_loads_matplotlib_beside_the_simulation_and_waits_for_it(run_dir):
    """`jaxrb run` loads matplotlib on a second thread while XLA loads or compiles; the
    thread has ended when the command returns (the plots above were drawn after it)."""
    assert _preload_threads() == []


def test_plot_preload_keeps_its_errors_to_itself(monkeypatch, capsys):
    """A failure on the preload thread is left for the main thread's own drawing to report:
    nothing raised, nothing printed."""
    from matplotlib.figure import Figure

    from jaxrb._plot_preload import PlotPreload

    def broken(*args, **kwargs):
        raise RuntimeError("no fonts")

    monkeypatch.setattr(Figure, "savefig", broken)
    PlotPreload().wait()
    assert _preload_threads() == []
    assert capsys.readouterr().err == ""


def _listed_outputs(summary: str) -> list[str]:
    """The file names of the summary's `output` row, `DIR/ (a, b, ...)`."""
    line = next(x for x in summary.splitlines() if x.startswith("output "))
    return sorted(re.search(r"\((.*)\)\s*$", line).group(1).split(", "))


def test_run_refuses_to_overwrite(scene_file, run_dir, capsys):
    before = (run_dir / "trajectory.npz").read_bytes()
    assert main(["run", str(scene_file), "-o", str(run_dir), "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "output already exists" in err and "--force" in err
    assert (run_dir / "trajectory.npz").read_bytes() == before
    assert (
        main(
            [
                "run",
                str(scene_file),
                "-o",
                str(run_dir),
                "-q",
                "--no-plots",
                "--force",
                "--t-end",
                "0.2",
            ]
        )
        == 0
    )
    assert "0 .. 0.2" in capsys.readouterr().out
    assert np.load(run_dir / "trajectory.npz")["t"][-1] == 0.2
    # the saved scene is the one that was run: the file with t_end = 0.2, comments kept
    saved = (run_dir / "scene.toml").read_text()
    expected = tomllib.loads(SCENE)
    expected["simulation"]["t_end"] = 0.2
    assert tomllib.loads(saved) == expected and "set by --t-end" in saved


def test_run_bad_scene_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE.replace("mass = 2.0", "mass = -2.0"))
    assert main(["run", str(bad), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: [body].mass: must be > 0, got -2.0" in err
    assert main(["run", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no such scene file" in err and "pendulum" in err


PENDULUM = example_path("pendulum").read_text()


@pytest.mark.parametrize(
    "initial, field, problem",
    [
        ("vel = [0.0, 0.0, 1.0]", "[initial].vel", "the [joint] (hinge) sets the mass centre's"),
        ("omega = [3.0, 0.0, 0.0]", "[initial].omega", "the [joint] (hinge) turns the body only"),
    ],
)
def test_run_refuses_motion_the_joint_cannot_have(tmp_path, capsys, initial, field, problem):
    """A hinge scene given a velocity, or an omega off the axis: exit status 2, one line
    naming the field and the joint, nothing written."""
    scene = tmp_path / "hinge.toml"
    scene.write_text(PENDULUM.replace("[initial]\n", f"[initial]\n{initial}\n"))
    out = tmp_path / "out"
    assert main(["run", str(scene), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"jaxrb run: error: {scene}: {field}: {problem}"), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()
    assert _preload_threads() == []  # waited for on the way out, too


def test_pendulum_example_bearing_force(tmp_path, capsys):
    """`jaxrb run pendulum` (the sample problem: m = 7.5 kg, rbar = 0.25 m, k_O = 0.295 m,
    released from rest with OC horizontal) writes the bearing force, and it matches the closed
    forms O_n = m g (1 + 2 rbar^2/k_O^2) sin(theta), O_t = m g (1 - rbar^2/k_O^2) cos(theta).

    Tolerance 20 rtol m g: the reaction is an exact function of (theta, theta_dot) at each
    save, so its error is the solver's global error in theta_dot^2 (O_n; O_t depends on theta
    alone, through theta_ddot), which the step-size control keeps at a few rtol relative
    (measured: 4 rtol m g for O_n at rtol = 1e-10, 2e-15 m g for O_t); 20 leaves room for
    other platforms. The CSV holds 12 significant digits (1e-10 N here).
    """
    out = tmp_path / "pendulum"
    assert main(["run", "pendulum", "-o", str(out), "-q"]) == 0
    rtol = tomllib.loads(PENDULUM)["simulation"]["rtol"]
    m, rbar, k_O, g = 7.5, 0.25, 0.295, 9.81
    tol = 20 * rtol * m * g
    data = np.load(out / "trajectory.npz")
    with open(out / "trajectory.csv") as f:
        rows = [r for r in csv.reader(f) if not r[0].startswith("#")]
    csv_cols = {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}
    theta = data["joint_angle"]
    assert theta[0] == 0 and abs(theta[-1] - np.pi) < 1e-6 and np.all(np.diff(theta) > 0)
    np.testing.assert_allclose(
        theta, jaxrb.analytic.pendulum_theta(data["t"], rbar, k_O, g), rtol=0, atol=20 * rtol
    )
    On, Ot, mag = (
        np.asarray(x) for x in jaxrb.analytic.pendulum_bearing_force(theta, m, rbar, k_O, g)
    )
    # world components: e_n = (-cos, 0, sin), e_t = (-sin, 0, -cos) at theta, O = On e_n - Ot e_t
    c, s = np.cos(theta), np.sin(theta)
    world = np.stack([-On * c + Ot * s, 0 * c, On * s + Ot * c], axis=-1)
    for got in (
        data,
        {key: csv_cols[col] for key, col in _CSV.items()} | {"reaction": _xyz(csv_cols)},
    ):
        np.testing.assert_allclose(got["reaction_normal"], On, rtol=0, atol=tol)
        np.testing.assert_allclose(got["reaction_tangential"], Ot, rtol=0, atol=tol)
        np.testing.assert_allclose(got["reaction_magnitude"], mag, rtol=0, atol=tol)
        np.testing.assert_allclose(got["reaction_axial"], 0.0, atol=tol)
        np.testing.assert_allclose(got["reaction"], world, rtol=0, atol=tol)
    np.testing.assert_allclose(csv_cols["theta"], theta, rtol=1e-11, atol=1e-12)
    summary = (out / "summary.txt").read_text()
    assert "reaction.png" in summary and (out / "reaction.png").stat().st_size > 10_000
    assert _listed_outputs(summary) == sorted(p.name for p in out.iterdir())


_CSV = {
    "reaction_normal": "On",
    "reaction_tangential": "Ot",
    "reaction_axial": "Oa",
    "reaction_magnitude": "Omag",
}


def _xyz(cols):
    return np.stack([cols["Ox"], cols["Oy"], cols["Oz"]], axis=-1)


def test_examples_listed_shown_and_run(tmp_path, capsys):
    """`jaxrb run --list` names every shipped example, `--show` prints one, and a name runs it
    (the heavy top, briefly; its scene.toml says what was run)."""
    assert main(["run", "--list"]) == 0
    listing = capsys.readouterr().out
    for name in ("die", "coin", "pendulum", "heavy_top", "ball_in_bowl"):
        assert name in EXAMPLES and re.search(rf"^{name}\s+\S", listing, re.M), listing
    assert main(["run", "pendulum", "--show"]) == 0
    assert capsys.readouterr().out == PENDULUM
    out = tmp_path / "top"
    assert main(["run", "heavy_top", "-o", str(out), "-q", "--no-plots", "--t-end", "0.05"]) == 0
    data = np.load(out / "trajectory.npz")
    assert data["reaction"].shape == (data["t"].size, 3) and "reaction_normal" not in data
    magnitude = np.linalg.norm(data["reaction"], axis=-1)
    np.testing.assert_allclose(data["reaction_magnitude"], magnitude, rtol=1e-15)
    header = (out / "trajectory.csv").read_text().splitlines()[1].split(",")
    assert header[-4:] == ["Ox", "Oy", "Oz", "Omag"]
    saved = tomllib.loads((out / "scene.toml").read_text())
    assert saved["simulation"]["t_end"] == 0.05 and data["t"][-1] == 0.05


def test_readme_commands_name_existing_scenes():
    """Every `jaxrb run` / `jaxrb sweep` line of the README names a shipped example or none
    (so it runs as written on a fresh clone)."""
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    commands = re.findall(r"^jaxrb (?:run|sweep)\b[^#\n]*", readme, re.M)
    assert len(commands) >= 4
    for command in commands:
        words = [w for w in command.split()[2:] if not w.startswith("-")]
        scene = words[0] if words and not re.match(r"^[\w.]+=", words[0]) else None
        if scene is not None and not Path(scene).suffix:
            assert scene in EXAMPLES, command


def test_sweep(scene_file, tmp_path, capsys):
    out = tmp_path / "sweep"
    args = [
        "sweep",
        str(scene_file),
        "-o",
        str(out),
        "-p",
        "forces.1.coefficient=0.2:0.6:3",
        "-p",
        "initial.vel.2=3.0,1.0",
    ]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "6 runs" in printed and "0 failed" in printed
    with open(out / "sweep.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 6
    for r in rows:
        c, v0 = float(r["forces.1.coefficient"]), float(r["initial.vel.2"])
        assert r["result"] == "successful"
        np.testing.assert_allclose(float(r["final_z"]), exact_z(0.4, c / 2.0, v0=v0), atol=1e-8)
    assert sorted({float(r["forces.1.coefficient"]) for r in rows}) == [0.2, 0.4, 0.6]
    assert main(args) == 2  # never overwrite without --force
    assert "output already exists" in capsys.readouterr().err


def test_sweep_draws_random_parameters_reproducibly(scene_file, tmp_path, capsys):
    """-r draws uniformly per run (the same draws at every grid point, from --seed);
    --random-attitude draws a unit quaternion; each row matches its own closed form."""

    def sweep(out, *extra):
        args = [
            "sweep",
            str(scene_file),
            "-o",
            str(tmp_path / out),
            "-p",
            "forces.1.coefficient=0.2,0.6",
        ]
        assert main([*args, "-r", "initial.vel.2=1:3", "--draws", "3", *extra]) == 0
        with open(tmp_path / out / "sweep.csv") as f:
            return list(csv.DictReader(f))

    rows = sweep("a", "--seed", "5", "--random-attitude")
    assert "6 runs" in capsys.readouterr().out and len(rows) == 6
    v0 = [float(r["initial.vel.2"]) for r in rows]
    assert all(1 <= v <= 3 for v in v0) and v0[:3] == v0[3:] and len(set(v0[:3])) == 3
    for r in rows:
        c, v = float(r["forces.1.coefficient"]), float(r["initial.vel.2"])
        np.testing.assert_allclose(float(r["final_z"]), exact_z(0.4, c / 2.0, v0=v), atol=1e-8)
        quat = [float(r[f"quat{k}"]) for k in range(4)]
        np.testing.assert_allclose(np.linalg.norm(quat), 1.0, rtol=1e-9)
        assert r["up_axis"] in {"+x", "-x", "+y", "-y", "+z", "-z"} and r["face_up"] == ""
    assert [r["initial.vel.2"] for r in sweep("b", "--seed", "5")] == [
        r["initial.vel.2"] for r in rows
    ]
    assert [r["initial.vel.2"] for r in sweep("c", "--seed", "6")] != [
        r["initial.vel.2"] for r in rows
    ]


@pytest.mark.parametrize(
    "extra, message",
    [
        (["-r", "initial.vel.2=3:1"], "LOW must be <= HIGH"),
        (["-r", "initial.vel.2=1"], "LOW:HIGH"),
        (["-p", "body.mass=1,2", "--draws", "4"], "--draws needs a random parameter"),
        (["-r", "initial.vel.2=1:2", "--draws", "0"], "--draws must be >= 1"),
    ],
)
def test_sweep_refuses_bad_random_parameters(scene_file, tmp_path, capsys, extra, message):
    assert main(["sweep", str(scene_file), "-o", str(tmp_path), *extra]) == 2
    assert message in capsys.readouterr().err


def test_sweep_reads_the_number_a_die_shows():
    """`face_up` of a `type = "die"` scene: the number on the face whose normal is up."""
    import types

    from jaxrb._cli import _final_attitude_metrics
    from jaxrb._scene_file import loads_scene

    spec = loads_scene(
        '[body]\nmass = 0.005\n[body.shape]\ntype = "die"\nsides = 20\n'
        "[initial]\npos = [0, 0, 0.1]\n[floor]\nrestitution = 0.5\n[simulation]\nt_end = 1.0\n"
    )
    die = jaxrb.dice.d20()
    normals = np.asarray(die.shape.face_normals())
    for face in (0, 7, 19):
        # the attitude that turns this face's normal to the world's up
        axis = np.cross(normals[face], [0.0, 0.0, 1.0])
        angle = np.arccos(np.clip(normals[face][2], -1, 1))
        quat = np.asarray(jaxrb.axis_angle_to_quat(axis, angle))
        traj = types.SimpleNamespace(states=types.SimpleNamespace(quat=quat[None]))
        metrics = _final_attitude_metrics(spec, traj)
        assert metrics["face_up"] == die.numbers[face]


@pytest.mark.parametrize(
    "param, message",
    [
        ("floor.restitution=0.5", "floor: no such table"),
        ("body.mass=1:2", "START:STOP:NUM"),
        ("forces.7.coefficient=1", "index out of range"),
        ("body.mass=-1", "[body].mass: must be > 0"),
    ],
)
def test_sweep_bad_params(scene_file, tmp_path, capsys, param, message):
    assert main(["sweep", str(scene_file), "-o", str(tmp_path), "-p", param]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("command", [[], ["run"], ["sweep"], ["bench"]])
def test_help(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([*command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: jaxrb")
    if not command:
        assert "run" in out and "sweep" in out and "bench" in out
    if command == ["run"]:
        assert "SCENE.toml" in out and "--force" in out and "trajectory.npz" in out
    if command == ["sweep"]:
        assert "START:STOP:NUM" in out


def test_bench_passes_its_options_to_the_report(capfd):
    """`jaxrb bench OPTIONS` runs benchmarks/run_all.py in a fresh process with OPTIONS (a
    report script's option errors come back as its exit code, jaxrb's own are not raised)."""
    assert main(["bench", "--", "--help"]) == 0
    assert "usage: run_all.py" in capfd.readouterr().out
    assert main(["bench", "--no-such-option"]) == 2
    assert "unrecognized arguments: --no-such-option" in capfd.readouterr().err


def test_show_default(capsys):
    assert main(["run", "--show-default"]) == 0
    out = capsys.readouterr().out
    assert "[body]" in out and "restitution" in out


def test_console_entry_point(tmp_path):
    """`python -m jaxrb` is the console script; --help works and is quick; the process ends
    without the interpreter's teardown, with `main`'s exit status and its output whole."""
    proc = subprocess.run(
        [sys.executable, "-m", "jaxrb", "--help"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert "usage: jaxrb" in proc.stdout
    assert proc.stdout.endswith("body->world.\n")  # the help's last words: nothing lost
    missing = tmp_path / "no_such_scene.toml"
    proc = subprocess.run(
        [sys.executable, "-m", "jaxrb", "run", str(missing)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("jaxrb run: error: ") and "no such scene file" in proc.stderr


def test_compilation_cache_in_the_users_cache_directory(scene_file, tmp_path):
    """`jaxrb run` keeps its compiled programs in $JAXRB_CACHE_DIR (by default the user's
    cache directory); `--no-cache` writes none."""
    import os

    from jaxrb import default_cache_dir

    for no_cache in (False, True):
        cache = tmp_path / f"cache-{no_cache}"
        env = {**os.environ, "JAXRB_CACHE_DIR": str(cache)}
        env.pop("JAX_COMPILATION_CACHE_DIR", None)
        args = ["run", str(scene_file), "-o", str(tmp_path / f"out-{no_cache}"), "-q"]
        proc = subprocess.run(
            [sys.executable, "-m", "jaxrb", *args, *(["--no-cache"] if no_cache else [])],
            capture_output=True,
            text=True,
            timeout=300,
            env=env,
        )
        assert proc.returncode == 0, proc.stderr
        files = list(cache.rglob("*")) if cache.exists() else []
        assert (len(files) == 0) == no_cache, files
    env_dir = tmp_path / "elsewhere"
    os.environ["JAXRB_CACHE_DIR"], saved = str(env_dir), os.environ["JAXRB_CACHE_DIR"]
    try:
        assert default_cache_dir() == env_dir
    finally:
        os.environ["JAXRB_CACHE_DIR"] = saved
