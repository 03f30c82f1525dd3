"""Hostile input to `jaxrb run` and `jaxrb sweep`, through `main(argv)` in-process.

Every case ends with exit status 2 (bad scene file, option or output path) or 1 (the
simulation failed), exactly one line on stderr naming the field, option or file, no
traceback, and no output left behind: no output directory, no staging directory. Most are
refused before anything is compiled; the few that simulate share one small free-body scene
(5 saves over 0.1 s), so they reuse one compiled solver.
"""

import errno
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxrb.plotting
from jaxrb._cli import main
from jaxrb._scene_examples import example_path

# A free body under gravity: quick to compile, and no floor (the contact engine is slow to
# compile). Every case that simulates has this structure, so the compiled solver is reused.
BASE = """title = "free body"
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
pos = [0.0, 0.0, 1.0]
vel = [1.0, 0.0, 0.0]
omega = [0.1, 2.0, 0.1]
[[forces]]
type = "gravity"
g = [0.0, 0.0, -9.81]
[simulation]
t_end = 0.1
num_saves = 5
"""
DIE = example_path("die").read_text()
SPHERE = "[body.shape]\ntype = 'sphere'\nradius = 0.1\n"


def edit(old, new, text=BASE):
    """`text` with `old` replaced by `new` (which must occur once)."""
    assert text.count(old) == 1, old
    return text.replace(old, new)


# (id, scene file content (str, bytes or None for the example die), extra arguments,
#  exit status, a part of the error line)
RUN_CASES = [
    ("binary file", b"\xff\xfe\x00\x01 not text", [], 2, "not a text file: byte 0 is not UTF-8"),
    ("empty file", "", [], 2, "empty scene: expected at least [body] and [simulation]"),
    ("comments only", "# nothing\n", [], 2, "empty scene"),
    ("TOML syntax error", "[body\nmass = 1", [], 2, "not valid TOML: Expected ']'"),
    ("nested too deeply", BASE + "x = " + "[" * 5000 + "]" * 5000, [], 2, "nested too deeply"),
    ("unknown key", edit("mass = 1.0", "mass = 1.0\ncolour = 1"), [], 2, "[body].colour: unknown"),
    (
        "string for a number",
        edit("mass = 1.0", 'mass = "1.0"'),
        [],
        2,
        "[body].mass: must be a number, got a string '1.0'",
    ),
    (
        "missing body",
        edit("[body]\nmass = 1.0\ninertia = [1.0, 2.0, 3.0]\n", ""),
        [],
        2,
        "[body]: missing required table",
    ),
    ("negative mass", edit("mass = 1.0", "mass = -1.0"), [], 2, "[body].mass: must be > 0"),
    (
        "negative size",
        edit("inertia = [1.0, 2.0, 3.0]\n", SPHERE.replace("0.1", "-0.1")),
        [],
        2,
        "[body.shape].radius: must be > 0, got -0.1",
    ),
    ("NaN mass", edit("mass = 1.0", "mass = nan"), [], 2, "[body].mass: must be finite, got nan"),
    (
        "NaN in a vector",
        edit("omega = [0.1, 2.0, 0.1]", "omega = [0.1, nan, 0.1]"),
        [],
        2,
        "[initial].omega: element 1 must be finite",
    ),
    (
        "integer too large for a float",
        edit("mass = 1.0", "mass = " + "9" * 400),
        [],
        2,
        "[body].mass: must be finite",
    ),
    (
        "size whose inertia overflows",
        edit("inertia = [1.0, 2.0, 3.0]\n", SPHERE.replace("0.1", "1e200")),
        [],
        2,
        "[body].shape: ",
    ),
    (
        "zero quaternion",
        edit("[initial]\n", "[initial]\nquat = [0, 0, 0, 0]\n"),
        [],
        2,
        "[initial].quat: must not be zero",
    ),
    (
        "velocity of 1e308",
        edit("vel = [1.0, 0.0, 0.0]", "vel = [1e308, 0, 0]"),
        [],
        2,
        "[initial].vel: the kinetic energy 1/2 m |vel|^2 is inf J",
    ),
    (
        "spin whose energy overflows",
        edit("omega = [0.1, 2.0, 0.1]", "omega = [1e200, 0, 0]"),
        [],
        2,
        "[initial].omega: the kinetic energy",
    ),
    (
        "body below the floor",
        edit(
            "inertia = [1.0, 2.0, 3.0]\n", SPHERE, edit("pos = [0.0, 0.0, 1.0]", "pos = [0, 0, -1]")
        )
        + "[floor]\nrestitution = 0.5\n",
        [],
        2,
        "[initial].pos: the body starts below the [floor]: its lowest point is 1.1 m under",
    ),
    ("NaN t_end", edit("t_end = 0.1", "t_end = nan"), [], 2, "[simulation].t_end: must be finite"),
    (
        "negative t_end",
        edit("t_end = 0.1", "t_end = -1.0"),
        [],
        2,
        "[simulation].t_end: must be greater than t_start = 0.0, got -1.0",
    ),
    (
        "time span overflows",
        edit("t_end = 0.1", "t_start = -1e308\nt_end = 1e308"),
        [],
        2,
        "[simulation].t_end: t_end - t_start overflows",
    ),
    (
        "1e8 saves",
        edit("num_saves = 5", "num_saves = 100000000"),
        [],
        2,
        "[simulation].num_saves: 100000000 saves would make 12 GB of output arrays",
    ),
    (
        "huge max_steps",
        edit("num_saves = 5", "num_saves = 5\nmax_steps = " + "9" * 30),
        [],
        2,
        "[simulation].max_steps: must be <=",
    ),
    (
        "unknown solver",
        edit("num_saves = 5", "num_saves = 5\nsolver = 'euler'"),
        [],
        2,
        "[simulation].solver: unknown value 'euler'",
    ),
    (
        "title matplotlib cannot parse",
        edit('"free body"', '"$\\\\frac{$"'),
        [],
        2,
        "title: matplotlib cannot draw it (ParseSyntaxException",
    ),
    ("title too long", edit("free body", "x" * 500), [], 2, "title: 500 characters"),
    (
        "shape type a list",
        BASE + "[body.shape]\ntype = [1]\n",
        [],
        2,
        "[body.shape].type: must be a string, got a list [1]",
    ),
    ("die: --t-end nan", None, ["--t-end", "nan"], 2, "--t-end must be a finite number"),
    ("die: --t-end inf", None, ["--t-end", "inf"], 2, "--t-end must be a finite number"),
    (
        "die: --t-end negative",
        None,
        ["--t-end", "-1"],
        2,
        "--t-end -1: must be greater than t_start = 0.0",
    ),
    ("die: --t-end 0", None, ["--t-end", "0"], 2, "--t-end 0: must be greater than t_start"),
    ("--t-end not a number", None, ["--t-end", "abc"], 2, "invalid float value: 'abc'"),
    ("unknown option", None, ["--no-such-option"], 2, "unrecognized arguments: --no-such"),
    # the simulation runs and fails: exit status 1
    (
        "motion overflows",
        edit("g = [0.0, 0.0, -9.81]", "g = [0.0, 0.0, -1e308]"),
        [],
        1,
        "simulation failed: energy became nan at t = ",
    ),
    (
        "solver gives up",
        edit("num_saves = 5", "num_saves = 5\nmax_steps = 1"),
        [],
        1,
        "simulation failed: The maximum number of solver steps was reached",
    ),
]


def run_cli(capsys, argv):
    """(exit status, stderr) of `jaxrb ARGV`."""
    code = main(argv)
    return code, capsys.readouterr().err


def assert_one_line(err, command, message):
    assert "Traceback" not in err, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"jaxrb {command}: "), err
    assert message in err, (message, err)


def scene_arg(tmp_path, content) -> str:
    if content is None:
        return "die"
    path = tmp_path / "scene.toml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return str(path)


@pytest.mark.parametrize(
    "content, extra, status, message", [c[1:] for c in RUN_CASES], ids=[c[0] for c in RUN_CASES]
)
def test_run_refuses_hostile_input(tmp_path, capsys, content, extra, status, message):
    scene = scene_arg(tmp_path, content)
    before = sorted(tmp_path.iterdir())
    out = tmp_path / "out"
    code, err = run_cli(capsys, ["run", scene, "-o", str(out), "-q", *extra])
    assert code == status, err
    assert_one_line(err, "run", message)
    if content is not None and status == 2 and "--t-end" not in extra:
        assert scene in err  # the message names the file
    assert sorted(tmp_path.iterdir()) == before  # no output, no staging directory


SWEEP_CASES = [
    (["-p", "floor.restitution=0.2:0.8:0"], "NUM must be an integer >= 1, got '0'"),
    (["-p", "nosuch.key=1:2:3"], "--param nosuch.key: nosuch: no such table in the scene file"),
    (["-p", "floor.restitution=abc"], "'abc' is not a number"),
    (["-p", "floor.restitution=nan"], "'nan' is not a finite number"),
    (["-p", "body.mass=1e400"], "'1e400' is not a finite number"),
    (["-p", "floor.restitution=0.2:0.8"], "expected START:STOP:NUM"),
    (["-p", "body.mass=1e308:-1e308:3"], "STOP - START overflows"),
    (["-p", "body.mass=,"], "no values"),
    (["-p", "body.mass"], "expected PATH=START:STOP:NUM or PATH=V1,V2,..."),
    (["-p", "body.mass=1:2:1000000000"], "a sweep has at most 100000 runs"),
    (["-p", "body.mass=1:2:1000", "-p", "floor.friction=0:1:1000"], "the grid has 1000000 points"),
    (["-p", "body.mass=1", "-p", "body.mass=2"], "each --param PATH may be given once"),
    (["-p", "initial.vel.5=1"], "initial.vel.5: index out of range (list of 3)"),
    (["-p", "body.mass.x=1"], "body.mass is a value, not a table or list"),
    (["-p", "body.mass=0.0045,-1"], "with body.mass=-1: [body].mass: must be > 0, got -1.0"),
    (["-p", "simulation.num_saves=1e9"], "[simulation].num_saves: 1000000000 saves would make"),
    ([], "sweep needs at least one -p/--param"),
]


@pytest.mark.parametrize(
    "params, message", SWEEP_CASES, ids=[" ".join(c[0]) or "no -p" for c in SWEEP_CASES]
)
def test_sweep_refuses_malformed_grids(tmp_path, capsys, params, message):
    out = tmp_path / "out"
    code, err = run_cli(capsys, ["sweep", "die", "-o", str(out), *params])
    assert code == 2, err
    assert_one_line(err, "sweep", message)
    assert list(tmp_path.iterdir()) == []


def output_cases(tmp_path):
    """(-o value, part of the error line) for output paths that cannot be used."""
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    cases = [
        (str(a_file), f"{a_file}: is a file, not a directory"),
        (str(a_file / "out"), f"{a_file / 'out'}: cannot create it: {a_file} is not a directory"),
        ("", "-o/--output: empty path"),
    ]
    if sys.platform.startswith("linux"):  # no directory can be made in /proc, even by root
        cases.append(("/proc/jaxrb-no-such/out", "cannot write in /proc"))
    if os.name == "posix" and os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        cases.append((str(locked / "out"), "permission denied"))
    return cases


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_unusable_output_paths(tmp_path, capsys, command):
    scene = scene_arg(tmp_path, BASE)
    extra = ["-p", "body.mass=1"] if command == "sweep" else ["-q"]
    for output, message in output_cases(tmp_path):
        before = sorted(tmp_path.rglob("*"))
        code, err = run_cli(capsys, [command, scene, "-o", output, *extra])
        assert code == 2, err
        assert_one_line(err, command, message)
        assert sorted(tmp_path.rglob("*")) == before
    assert (tmp_path / "a_file").read_text() == "keep me"


def test_show_of_a_binary_file(tmp_path, capsys):
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n")
    code, err = run_cli(capsys, ["run", str(path), "--show"])
    assert code == 2
    assert_one_line(err, "run", f"{path}: not a text file")


def test_scene_that_is_a_directory_or_missing(tmp_path, capsys):
    code, err = run_cli(capsys, ["run", str(tmp_path), "-o", str(tmp_path / "out")])
    assert code == 2
    assert_one_line(err, "run", f"{tmp_path}: is a directory, not a scene file")
    code, err = run_cli(capsys, ["run", "no_such_scene", "-o", str(tmp_path / "out")])
    assert code == 2
    assert_one_line(err, "run", "no_such_scene: no such scene file, nor a shipped example")
    assert list(tmp_path.iterdir()) == []


def test_refused_without_quiet_is_one_line(tmp_path, capsys):
    """Without -q, a scene refused before the run prints nothing but the error."""
    scene = scene_arg(tmp_path, edit("vel = [1.0, 0.0, 0.0]", "vel = [1e308, 0, 0]"))
    code, err = run_cli(capsys, ["run", scene, "-o", str(tmp_path / "out")])
    assert code == 2
    assert_one_line(err, "run", "[initial].vel")


# ---------------------------------------------------------------------------------------------
# atomic outputs


def fill(directory: Path) -> dict:
    """Put an old run's files and an unrelated file into `directory`; return their bytes."""
    directory.mkdir()
    files = {"trajectory.npz": b"old npz", "summary.txt": b"old summary", "notes.txt": b"mine"}
    for name, data in files.items():
        (directory / name).write_bytes(data)
    return files


def contents(directory: Path) -> dict:
    return {p.name: p.read_bytes() for p in directory.iterdir()}


def test_late_failure_leaves_nothing(tmp_path, capsys, monkeypatch):
    """A write that fails after the data files are written (here: the disk fills up while
    the plots are saved) leaves no output directory; with --force into an existing one, its
    files are as they were. Then the same run succeeds: nothing blocks it."""

    def full_disk(traj, scene, outdir, title=None):
        (Path(outdir) / "height_attitude.png").write_bytes(b"half a png")
        raise OSError(errno.ENOSPC, "No space left on device")

    scene = scene_arg(tmp_path, BASE)
    out = tmp_path / "out"
    kept = tmp_path / "kept"
    old = fill(kept)
    with monkeypatch.context() as patch:
        patch.setattr(jaxrb.plotting, "save_run_plots", full_disk)
        code, err = run_cli(capsys, ["run", scene, "-o", str(out), "-q"])
        assert code == 2
        assert_one_line(err, "run", f"{out}: cannot write: No space left on device")
        assert not out.exists()
        code, err = run_cli(capsys, ["run", scene, "-o", str(kept), "-q", "--force"])
        assert code == 2
        assert_one_line(err, "run", "No space left on device")
        assert contents(kept) == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept", "scene.toml"]
    assert main(["run", scene, "-o", str(out), "-q"]) == 0
    assert (out / "height_attitude.png").stat().st_size > 1000


def test_unexpected_error_is_one_line_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    def broken(traj, scene, outdir, title=None):
        (Path(outdir) / "energy.png").write_bytes(b"half a png")
        raise RuntimeError("a bug")

    monkeypatch.setattr(jaxrb.plotting, "save_run_plots", broken)
    scene = scene_arg(tmp_path, BASE)
    code, err = run_cli(capsys, ["run", scene, "-o", str(tmp_path / "out"), "-q"])
    assert code == 1
    assert_one_line(err, "run", "unexpected RuntimeError: a bug")
    assert [p.name for p in tmp_path.iterdir()] == ["scene.toml"]


def test_existing_directory_gets_new_files_only_on_success(tmp_path, capsys):
    """Into an existing directory: refused while an output exists (files unchanged); with
    --force the outputs are replaced, other files kept, and no staging directory is left."""
    scene = scene_arg(tmp_path, BASE)
    out = tmp_path / "out"
    old = fill(out)
    code, err = run_cli(capsys, ["run", scene, "-o", str(out), "-q", "--no-plots"])
    assert code == 2
    assert_one_line(err, "run", "output already exists: ")
    assert "trajectory.npz" in err and "--force" in err
    assert contents(out) == old
    assert main(["run", scene, "-o", str(out), "-q", "--no-plots", "--force"]) == 0
    new = contents(out)
    assert sorted(new) == [
        "notes.txt",
        "scene.toml",
        "summary.txt",
        "trajectory.csv",
        "trajectory.npz",
    ]
    assert new["notes.txt"] == b"mine" and new["summary.txt"] != old["summary.txt"]
    assert np.load(out / "trajectory.npz")["t"].shape == (5,)


def test_sweep_marks_overflowing_runs_failed(tmp_path, capsys):
    """A grid point whose motion overflows is a failed row, not a NaN result."""
    scene = scene_arg(tmp_path, BASE)
    out = tmp_path / "out"
    args = ["sweep", scene, "-o", str(out), "-p", "forces.0.g.2=-9.81,-1e308"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "2 runs" in printed and "(1 failed)" in printed
    rows = (out / "sweep.csv").read_text().splitlines()
    assert rows[1].split(",")[1] == "successful"
    assert "failed: energy became nan" in rows[2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene.toml"]
