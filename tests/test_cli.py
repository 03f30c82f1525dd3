"""The `jaxrb` command line, called in-process through `main([...])` (one subprocess test)."""

import csv
import subprocess
import sys

import numpy as np
import pytest

from jaxrb._cli import main

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


def test_run_bad_scene_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE.replace("mass = 2.0", "mass = -2.0"))
    assert main(["run", str(bad), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: [body].mass: must be > 0, got -2.0" in err
    assert main(["run", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "out")]) == 2
    assert "no such scene file" in capsys.readouterr().err


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


def test_console_entry_point():
    """`python -m jaxrb` is the console script; --help works and is quick."""
    proc = subprocess.run(
        [sys.executable, "-m", "jaxrb", "--help"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert "usage: jaxrb" in proc.stdout
