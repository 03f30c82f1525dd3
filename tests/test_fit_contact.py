"""Restitution and friction through the impact simulation: `jaxrb.fit.fit_contact` and
`jaxrb fit contact`.

The data are the closed-form motion of a solid ball thrown with backspin onto a floor
(parabolic flights; at each impact Newton's restitution and Coulomb friction), independent of
`jaxrb.simulate`. The library fit and the command line fit the same kind of data (positions
and gyro, the same scene structure and sample count), so they share one compiled solver: the
contact engine takes about a minute to compile, the fits a fraction of a second. (The
closed form agrees with `jaxrb.simulate` to 5e-12 m: the round trip recovers the true values
only if it does.)
"""

import json

import numpy as np
import pytest
from programs import traces

import jaxrb
import jaxrb.fit as jf
from jaxrb._cli import main
from jaxrb._cli_fit import _bouncing_ball
from jaxrb.fit._least_squares import _solve

E_BALL, MU_BALL, R_BALL, M_BALL = 0.6, 0.1, 0.05, 0.2
BALL = dict(
    mass=M_BALL,
    radius=R_BALL,
    restitution=E_BALL,
    friction=MU_BALL,
    pos0=[0.0, 0.0, 0.5],
    vel0=[1.5, 0.3, 0.0],
    omega0=[5.0, -40.0, 0.0],  # backspin: the first impact slides (it sticks for mu > 0.21)
    g=9.81,
)
BALL_STATE0 = jaxrb.make_state(pos=BALL["pos0"], vel=BALL["vel0"], omega=BALL["omega0"])
BALL_TS = np.linspace(0.0, 0.8, 25)  # two bounces, before the ball starts to roll


def _scene(e, mu):
    body = jaxrb.RigidBody(M_BALL, shape=jaxrb.Sphere(R_BALL))
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(e, mu))


@pytest.fixture(scope="module")
def tracked_ball():
    pos, omega = _bouncing_ball(BALL_TS, BALL)
    assert np.sum(np.abs(np.diff(np.sign(np.diff(pos[:, 2]))))) >= 4  # two bounces
    return pos, omega


def test_contact_fit_from_tracked_trajectory(tracked_ball):
    """Restitution and friction from positions and gyro data, from starts 30 % off."""
    pos, omega = tracked_ball
    res = jf.fit_contact(
        _scene(0.5, 0.5),
        BALL_STATE0,
        BALL_TS,
        pos,
        omega=omega,
        omega_weight=0.01,
        restitution0=0.42,
        friction0=0.13,
    )
    assert res.converged, res.message
    assert abs(res.values["restitution"] / E_BALL - 1) <= 1e-6
    assert abs(res.values["friction"] / MU_BALL - 1) <= 1e-6
    assert np.all(np.isfinite(res.std["restitution"])) and not res.warnings


def test_cli_contact_round_trip(tmp_path, capsys):
    """`--write-example` writes the data and the scene; fitting them from the scene's guesses
    gives the true values back, with the solver compiled by the test above."""
    before = traces(_solve)
    data = tmp_path / "bounce.csv"
    assert main(["fit", "contact", "--write-example", str(data)]) == 0
    printed = capsys.readouterr().out
    scene = tmp_path / "bounce.toml"
    assert f"--scene {scene}" in printed and scene.exists()
    header = [ln for ln in data.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == "t,x,y,z,wx,wy,wz"
    # both files are refused without --force, and neither is touched
    data.write_text("keep")
    assert main(["fit", "contact", "--write-example", str(data)]) == 2
    err = capsys.readouterr().err
    assert "output already exists" in err and len(err.strip().splitlines()) == 1
    assert data.read_text() == "keep"
    assert main(["fit", "contact", "--write-example", str(data), "--force"]) == 0
    capsys.readouterr()

    out = tmp_path / "out"
    args = ["fit", "contact", str(data), "--scene", str(scene), "-o", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "restitution e" in printed and "friction mu" in printed and "yes (" in printed
    res = json.loads((out / "fit_contact.json").read_text())
    assert res["converged"] and res["friction_fitted"] and res["observed"] == ["pos", "omega"]
    assert abs(res["values"]["restitution"] / E_BALL - 1) <= 1e-6
    assert abs(res["values"]["friction"] / MU_BALL - 1) <= 1e-6
    assert res["integrator"]["rtol"] == 1e-10 and res["num_steps"] < 100
    assert res["initial_position_gap"] == 0.0
    if before is not None:  # the solver compiled for the library fit was reused
        assert traces(_solve) == max(before, 1)


def test_contact_fit_bad_input(tracked_ball):
    pos, _ = tracked_ball
    scene = _scene(0.5, 0.5)
    with pytest.raises(ValueError, match="pos"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, pos[:-1])
    with pytest.raises(ValueError, match="pos"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, np.where(pos > 0.4, np.nan, pos))
    with pytest.raises(ValueError, match="restitution0"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, pos, restitution0=1.2)
    with pytest.raises(ValueError, match="sim_rtol"):
        jf.fit_contact(scene, BALL_STATE0, BALL_TS, pos, sim_rtol=np.inf)
    with pytest.raises(ValueError, match="Floor"):
        no_floor = jaxrb.Scene(jaxrb.RigidBody(M_BALL, shape=jaxrb.Sphere(R_BALL)))
        jf.fit_contact(no_floor, BALL_STATE0, BALL_TS, pos)
