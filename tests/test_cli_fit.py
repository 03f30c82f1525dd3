"""`jaxrb fit` (inertia, restitution, drag) and result messages, called in-process via `main`.
(`jaxrb fit contact`: `test_fit_contact.py`, beside the library fit it shares a compiled
solver with.)

Round trips: `--write-example` writes data from a known synthetic motion, the fit must give the
known values back (noise-free data: tight relative tolerances). The truths are written out
here, independently of the example writers. Bad data files must end in exit status 2 with a
message naming the file and the problem, before anything is fitted or written.
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrb
import jaxrb.fit
from jaxrb._cli import _result_name, main
from jaxrb._cli_common import CLIError
from jaxrb._cli_fit import _fit_report, _known_torque, _read_data

J_TRUE = np.array([[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]])  # kg m^2
OMEGA0_TRUE = np.array([1.0, 0.5, 0.8])  # rad/s, body frame
E_TRUE, H0_TRUE = 0.7, 1.2
K_TRUE = 0.5 * 1.2 * 0.55 * np.pi * 0.033**2  # kg/m: rho C_D A / 2 of a tennis ball
VEL0_TRUE = np.array([12.0, 1.0, 8.0])


def _json(path):
    return json.loads(path.read_text())


def _rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b)))


# ---------------------------------------------------------------------------------------------
# round trips


def test_inertia_round_trip(tmp_path, capsys):
    data = tmp_path / "omega.csv"
    assert main(["fit", "inertia", "--write-example", str(data)]) == 0
    assert "true inertia" in capsys.readouterr().out
    header = [ln for ln in data.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == "t,wx,wy,wz,e0,e1,e2,e3,tx,ty,tz"
    out = tmp_path / "out"
    assert main(["fit", "inertia", str(data), "--inertia0", "2.5,3,3.5", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Jxy" in printed and "omega0_z" in printed and "yes (the Gauss-Newton" in printed
    res = _json(out / "fit_inertia.json")
    assert res["converged"] and res["known_torque"] and res["warnings"] == []
    # a known torque fixes the absolute scale: the tensor itself comes back
    assert _rel(res["values"]["inertia"], J_TRUE) <= 1e-6
    np.testing.assert_allclose(res["values"]["omega0"], OMEGA0_TRUE, rtol=0, atol=1e-8)
    assert res["residual_norm"] < 1e-8 and res["samples"] == 21


def test_restitution_round_trip_and_force(tmp_path, capsys):
    data = tmp_path / "bounces.csv"
    assert main(["fit", "restitution", "--write-example", str(data)]) == 0
    before = data.read_bytes()
    # the example file is not overwritten without --force
    assert main(["fit", "restitution", "--write-example", str(data)]) == 2
    err = capsys.readouterr().err
    assert "output already exists" in err and str(data) in err and "--force" in err
    assert main(["fit", "restitution", "--write-example", str(data), "--force"]) == 0
    assert data.read_bytes() == before  # deterministic

    out = tmp_path / "out"
    assert main(["fit", "restitution", str(data), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "restitution e" in printed and "residual norm" in printed and "yes" in printed
    result = out / "fit_restitution.json"
    res = _json(result)
    # closed-form data and closed-form model: agreement to round-off
    assert abs(res["values"]["restitution"] / E_TRUE - 1) <= 1e-9
    assert abs(res["values"]["h0"] / H0_TRUE - 1) <= 1e-9
    assert res["impacts"] == 5 and res["apexes"] == 5 and res["dof"] == 8

    # the results file is not overwritten without --force either
    result.write_text("{}")
    assert main(["fit", "restitution", str(data), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "output already exists" in err and "fit_restitution.json" in err
    assert result.read_text() == "{}"
    assert main(["fit", "restitution", str(data), "-o", str(out), "--force"]) == 0
    assert _json(result)["converged"] is True


def test_restitution_npz_with_radius_and_known_h0(tmp_path, capsys):
    """Centre apex heights of a ball of radius R, h0 (centre) given: only e is fitted."""
    radius = 0.05
    k = np.arange(1, 5)
    path = tmp_path / "apex.npz"
    np.savez(path, apex_heights=E_TRUE ** (2 * k) * H0_TRUE + radius)
    args = ["fit", "restitution", str(path), "--radius", "0.05", "-o", str(tmp_path)]
    assert main([*args, "--h0", str(H0_TRUE + radius)]) == 0
    printed = capsys.readouterr().out
    assert "fixed" in printed  # the given h0 has no standard error
    res = _json(tmp_path / "fit_restitution.json")
    assert abs(res["values"]["restitution"] / E_TRUE - 1) <= 1e-9
    assert res["values"]["h0"] == pytest.approx(H0_TRUE + radius, rel=1e-12)
    assert res["std"]["h0"] == 0.0 and res["h0_given"]


def test_drag_round_trip_npz(tmp_path, capsys):
    data = tmp_path / "flight.npz"
    assert main(["fit", "drag", "--write-example", str(data)]) == 0
    capsys.readouterr()
    assert sorted(np.load(data).files) == ["description", "t", "x", "y", "z"]
    out = tmp_path / "out"
    args = ["fit", "drag", str(data), "--mass", "0.057", "--drag0", "0.002", "-o", str(out)]
    assert main(args) == 0
    assert "terminal speed" in capsys.readouterr().out
    res = _json(out / "fit_drag.json")
    assert res["converged"]
    assert abs(res["values"]["drag"] / K_TRUE - 1) <= 1e-6
    np.testing.assert_allclose(res["values"]["vel0"], VEL0_TRUE, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res["values"]["pos0"], [0.0, 0.0, 1.5], rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# bad data and options


def _npz(path, **arrays):
    np.savez(path, **arrays)


BAD_DATA = [
    # (id, kind, file name, content (str: CSV text, bytes, dict: npz arrays, None: no file),
    #  extra arguments, expected message parts)
    ("missing column", "inertia", "a.csv", "t,wx,wy\n0,1,2\n", [], ["missing column 'wz'"]),
    (
        "no motion columns",
        "inertia",
        "a.csv",
        "t,x\n0,1\n",
        [],
        ["no motion data", "wx, wy, wz", "columns found: t, x"],
    ),
    (
        "ragged row",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n1,2,3\n",
        [],
        ["line 3: 3 values but the header has 4 columns"],
    ),
    (
        "npz lengths differ",
        "inertia",
        "a.npz",
        {"t": np.arange(5.0), "omega": np.ones((4, 3))},
        [],
        ["column 'wx' has 4 values but 't' has 5"],
    ),
    (
        "npz wrong width",
        "inertia",
        "a.npz",
        {"t": np.arange(5.0), "omega": np.ones((5, 2))},
        [],
        ["array 'omega' must have shape (N, 3)"],
    ),
    (
        "nan",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n0.1,1,2,3\n0.2,1,2,3\n0.3,1,nan,3\n0.4,1,2,3\n",
        [],
        ["column 'wy': NaN at line 5"],
    ),
    (
        "inf",
        "drag",
        "a.npz",
        {"t": np.arange(4.0), "pos": np.array([[0, 0, 1], [1, 0, 2], [2, 0, np.inf], [3, 0, 1]])},
        ["--mass", "1", "--drag0", "0.1"],
        ["column 'z': infinite value at index 2"],
    ),
    (
        "empty cell",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n1,,2,3\n2,1,1,1\n",
        [],
        ["column 'wx': empty value at line 3"],
    ),
    (
        "not a number",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n1,2,x,3\n",
        [],
        ["line 3, column 'wy': not a number: 'x'"],
    ),
    (
        "too few samples",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n1,2,3,3\n",
        [],
        ["too few samples", "6 residuals for 8 free parameters"],
    ),
    (
        "times not increasing",
        "inertia",
        "a.csv",
        "t,wx,wy,wz\n0,1,2,3\n0.2,1,2,3\n0.1,1,2,3\n",
        [],
        ["column 't' must be strictly increasing", "line 4"],
    ),
    (
        "quaternion not unit",
        "inertia",
        "a.csv",
        "t,e0,e1,e2,e3\n0,1,0,0,0\n1,2,0,0,0\n",
        ["--omega0", "1,0,0"],
        ["|q| = 2 at line 3", "unit quaternions"],
    ),
    ("no such file", "inertia", "a.csv", None, [], ["no such data file"]),
    ("empty file", "inertia", "a.csv", "# only a comment\n\n", [], ["empty"]),
    ("no header", "restitution", "a.csv", "0.5\n1.1\n", [], ["header of column names"]),
    ("binary csv", "inertia", "a.csv", b"\x89PNG\x00\xff\xfe", [], ["not a UTF-8 text CSV"]),
    ("not an npz", "inertia", "a.npz", b"t,wx\n0,1\n", [], ["not a NumPy .npz archive"]),
    (
        "restitution columns",
        "restitution",
        "a.csv",
        "bounce,time\n1,0.5\n",
        [],
        ["missing column 'impact_time' and/or 'apex_height'"],
    ),
    (
        "impact times decreasing",
        "restitution",
        "a.csv",
        "impact_time\n0.5\n1.2\n1.1\n",
        [],
        ["'impact_time' must be strictly increasing", "line 4"],
    ),
    (
        "apex below radius",
        "restitution",
        "a.csv",
        "apex_height\n0.5\n0.2\n0.04\n",
        ["--radius", "0.05"],
        ["'apex_height' must be > 0.05", "line 4"],
    ),
    (
        "too few bounces",
        "restitution",
        "a.csv",
        "impact_time\n0.5\n1.2\n",
        [],
        ["too few samples", "2 residuals for 2 free parameters"],
    ),
    (
        "drag position missing",
        "drag",
        "a.csv",
        "t,x,y\n0,0,0\n1,1,1\n",
        ["--mass", "1", "--drag0", "0.1"],
        ["missing column 'z'"],
    ),
]


@pytest.mark.parametrize(
    "kind, name, content, extra, message", [c[1:] for c in BAD_DATA], ids=[c[0] for c in BAD_DATA]
)
def test_bad_data_file(tmp_path, capsys, kind, name, content, extra, message):
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content)
    elif isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, dict):
        _npz(path, **content)
    if kind == "inertia" and "--inertia0" not in extra:
        extra = [*extra, "--inertia0", "1,2,2.5"]
    out = tmp_path / "out"
    assert main(["fit", kind, str(path), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"jaxrb fit {kind}: error: {path}: "), err
    assert len(err.strip().splitlines()) == 1, err  # one clear line, no traceback
    for part in message:
        assert part in err, (part, err)
    assert not (out / f"fit_{kind}.json").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["fit"], "say what to fit"),
        (["fit", "inertia"], "give a DATA file"),
        (["fit", "inertia", "DATA"], "--inertia0 is required"),
        (["fit", "inertia", "DATA", "--inertia0", "1,1,3"], "--inertia0 violates the triangle"),
        (["fit", "inertia", "DATA", "--inertia0", "1,2"], "expected 3 or 9 comma-separated"),
        (["fit", "inertia", "DATA", "--inertia0=-1,2,2"], "--inertia0 is not positive definite"),
        (["fit", "drag", "DATA", "--drag0", "0.1"], "--mass is required"),
        (["fit", "drag", "DATA", "--mass", "1"], "--drag0 is required"),
        (["fit", "drag", "DATA", "--mass", "-1", "--drag0", "1"], "--mass must be"),
        (["fit", "restitution", "DATA", "--restitution0", "1.5"], "--restitution0 must be in"),
        (["fit", "restitution", "DATA", "--write-example", "x.csv"], "give no DATA"),
        (["fit", "restitution", "DATA", "--max-steps", "0"], "--max-steps must be"),
        (["fit", "drag", "DATA", "--mass", "1", "--drag0", "1", "--rtol", "-1"], "--rtol must be"),
        (["fit", "inertia", "DATA", "--inertia0", "1,2,2.5", "--atol", "nan"], "--atol must be"),
        (["fit", "contact", "DATA"], "--scene is required"),
        (["fit", "contact", "DATA", "--scene", "nowhere.toml"], "no such scene file"),
        (["fit", "contact", "DATA", "--scene", "pendulum"], "the scene has no [floor]"),
        (["fit", "contact", "DATA", "--scene", "coin", "--restitution0", "1"], "--restitution0"),
        (["fit", "contact", "DATA", "--scene", "coin", "--friction0", "0"], "--friction0 must"),
        (["fit", "contact", "DATA", "--scene", "coin", "--max-impacts", "0"], "--max-impacts"),
        (["fit", "contact", "--write-example", "x.toml"], "give a .csv or .npz"),
    ],
)
def test_bad_options(tmp_path, monkeypatch, capsys, args, message):
    """Option mistakes are found before the data are fitted (the data file here is fine)."""
    monkeypatch.chdir(tmp_path)  # the default output directory is relative
    data = tmp_path / "d.csv"
    data.write_text(
        "t,wx,wy,wz,impact_time,x,y,z\n"
        + "".join(f"{0.1 * i},1,0.5,0.8,{0.5 + i},{i},0,1\n" for i in range(8))
    )
    args = [str(data) if a == "DATA" else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "jaxrb-output").exists()


# one data file per kind: (header, extra arguments)
_KINDS = {
    "inertia": ("t,wx,wy,wz", ["--inertia0", "1,2,2.5"]),
    "restitution": ("impact_time,apex_height", []),
    "drag": ("t,x,y,z", ["--mass", "1", "--drag0", "0.1"]),
    "contact": ("t,x,y,z", ["--scene", "coin"]),
}


def _rows(header, nan_at=None):
    width = len(header.split(","))
    rows = []
    for i in range(6):
        cells = [f"{0.5 + i}"] + [f"{1.0 / (i + 1) + j}" for j in range(1, width)]
        if i == nan_at:
            cells[-1] = "nan"
        rows.append(",".join(cells))
    return header + "\n" + "\n".join(rows) + "\n"


@pytest.mark.parametrize("kind", list(_KINDS))
@pytest.mark.parametrize(
    "case, message",
    [
        ("missing file", "no such data file"),
        ("malformed", None),
        ("nan", "NaN at line 5"),
    ],
)
def test_hostile_data_per_kind(tmp_path, capsys, kind, case, message):
    """Each kind refuses a missing file, a malformed CSV and NaN in the data: exit status 2,
    one line naming the file, nothing written."""
    header, extra = _KINDS[kind]
    path = tmp_path / "data.csv"
    width = len(header.split(","))
    if case == "malformed":  # one value too many on line 4
        lines = _rows(header).splitlines()
        lines[3] += ",1"
        path.write_text("\n".join(lines) + "\n")
        message = f"line 4: {width + 1} values but the header has {width} columns"
    elif case == "nan":
        path.write_text(_rows(header, nan_at=3))
    out = tmp_path / "out"
    assert main(["fit", kind, str(path), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"jaxrb fit {kind}: error: {path}: "), err
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_max_steps_and_rtol(tmp_path, capsys):
    """--max-steps is the budget of trial steps (too few: exit 1, one line, results written,
    saying so); --rtol and --atol set the model's integrator (recorded in the results)."""
    data = tmp_path / "flight.csv"
    assert main(["fit", "drag", "--write-example", str(data)]) == 0
    base = ["fit", "drag", str(data), "--mass", "0.057", "--drag0", "0.002"]
    capsys.readouterr()
    assert main([*base, "-o", str(tmp_path / "few"), "--max-steps", "1"]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "did not converge" in err[0] and "raise --max-steps" in err[0]
    assert "NO (the budget of max_steps" in captured.out
    res = _json(tmp_path / "few" / "fit_drag.json")
    assert not res["converged"] and res["reason"] == "max_steps"
    assert res["num_steps"] == 1 and res["max_steps"] == 1

    out = tmp_path / "tight"
    args = [*base, "-o", str(out), "--rtol", "1e-9", "--atol", "1e-10", "--max-steps", "40"]
    assert main(args) == 0
    res = _json(out / "fit_drag.json")
    assert res["converged"] and res["num_steps"] <= 40
    assert res["integrator"] == {"solver": "tsit5 (adaptive)", "rtol": 1e-9, "atol": 1e-10}
    assert abs(res["values"]["drag"] / K_TRUE - 1) <= 1e-6


def test_fit_failure_is_one_line(tmp_path, capsys, monkeypatch):
    """An unexpected failure inside the fit: exit status 1, one line, nothing written."""
    data = tmp_path / "bounces.csv"
    assert main(["fit", "restitution", "--write-example", str(data)]) == 0
    capsys.readouterr()

    def fail(**kwargs):
        raise RuntimeError("solver exploded\n  with a second line")

    monkeypatch.setattr(jaxrb.fit, "fit_restitution", fail)
    out = tmp_path / "out"
    assert main(["fit", "restitution", str(data), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "the fit failed: RuntimeError: solver exploded with a second line" in err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# pieces


def test_csv_columns_of_different_lengths(tmp_path):
    """Restitution data may end one column early (empty trailing cells); elsewhere it's an error."""
    path = tmp_path / "b.csv"
    path.write_text("# a comment\nimpact_time,apex_height\n0.5,0.6\n1.2,0.3\n1.7,\n")
    data = _read_data(path)
    np.testing.assert_array_equal(data.column("impact_time", trailing_empty=True), [0.5, 1.2, 1.7])
    np.testing.assert_array_equal(data.column("apex_height", trailing_empty=True), [0.6, 0.3])
    with pytest.raises(CLIError, match="column 'apex_height': empty value at line 5"):
        data.column("apex_height")


def test_sampled_torque_is_interpolated():
    t = np.array([0.0, 1.0, 2.0])
    torque = np.array([[0.0, 1.0, 2.0], [1.0, 1.0, 0.0], [3.0, 1.0, 0.0]])
    wrench = _known_torque(t, torque)
    assert wrench.frame == "body"
    np.testing.assert_allclose(wrench.torque(jnp.asarray(0.25)), [0.25, 1.0, 1.5], rtol=1e-15)
    np.testing.assert_allclose(wrench.torque(jnp.asarray(1.5)), [2.0, 1.0, 0.0], rtol=1e-15)
    constant = _known_torque(t, np.tile([0.3, -0.2, 0.5], (3, 1)))
    np.testing.assert_array_equal(constant.torque, [0.3, -0.2, 0.5])


def test_report_shows_warnings_and_fixed_values():
    res = jaxrb.fit.FitResult(
        values={"restitution": np.array(0.7), "h0": np.array(1.2)},
        std={"restitution": np.array(0.01), "h0": np.array(0.0)},
        covariance=np.zeros((2, 2)),
        names=("restitution", "h0"),
        residuals=np.array([3e-3, -4e-3, 0.0]),
        sigma2=1.0,
        dof=2,
        jacobian=np.zeros((3, 1)),
        condition_number=2e9,
        converged=False,
        num_steps=200,
        message="max steps",
        warnings=("poorly identifiable: condition number 2.00e+09",),
        reason="max_steps",
        num_rejected=7,
    )
    rows = [("restitution e", 0.7, 0.01, ""), ("h0", 1.2, 0.0, "m")]
    text = _fit_report(res, rows, [], "d.csv", "out/fit.json", list(res.warnings))
    assert "warning: poorly identifiable: condition number 2.00e+09" in text
    assert "NO (max steps; 200 steps, 7 rejected)" in text
    assert "0.005" in text  # |r| = 5e-3
    h0_row = [ln for ln in text.splitlines() if ln.startswith("h0")][0]
    assert "fixed" in h0_row


def test_result_name_gives_the_message():
    """Equinox enumerations are not indexed by int: the message must still come through."""
    R = jaxrb.RESULTS
    assert _result_name(R.successful) == "successful"
    assert _result_name(R.max_impacts_reached) == (
        "the maximum number of impacts was reached before the end time."
    )
    code = int(np.asarray(R.max_steps_reached._value))
    # batched codes (a vmapped trajectory's result): the first failure is named
    success = int(np.asarray(R.successful._value))
    batched = np.array([success, code, int(np.asarray(R.invalid_mass._value))])
    assert "maximum number of" in _result_name(batched) and "steps" in _result_name(batched)
    assert _result_name(np.array([success, success])) == "successful"
    assert _result_name(np.array(999)) == "failed (code 999)"
    assert "code" not in _result_name(R.starts_below_floor)


@pytest.mark.parametrize(
    "command, words",
    [
        (["fit"], ["inertia", "restitution", "drag", "contact", "--write-example"]),
        (["fit", "inertia"], ["wx, wy, wz", "e0, e1, e2, e3", "tx, ty, tz", "--inertia0"]),
        (["fit", "restitution"], ["impact_time", "apex_height", "--radius", "--h0"]),
        (["fit", "drag"], ["x, y, z", "--mass", "--drag0", "fit_drag.json", "--max-steps"]),
        (["fit", "contact"], ["x, y, z", "wx, wy, wz", "--scene", "--fix-friction", "--rtol"]),
    ],
)
def test_fit_help(command, words, capsys):
    with pytest.raises(SystemExit) as info:
        main([*command, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for w in words:
        assert w in out, w
