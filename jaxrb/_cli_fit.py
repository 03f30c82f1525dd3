"""`jaxrb fit`: fit inertia, restitution, drag or contact to measured motion.

    jaxrb fit inertia DATA --inertia0 J       inertia tensor from angular velocity / attitude
    jaxrb fit restitution DATA        restitution (and drop height) from bounce times / apexes
    jaxrb fit drag DATA --mass M --drag0 K    drag coefficient from a tracked flight
    jaxrb fit contact DATA --scene SCENE      restitution and friction from a tracked bounce
    jaxrb fit KIND --write-example FILE       an example data file from a known motion

This file holds the data-file readers (CSV with a header row, or .npz) and their checks, the
example-data writers, one `_fit_KIND` per kind (option checks, the call into `jaxrb.fit`, the
rows of the summary), the summary and results file (`fit_KIND.json`), `cmd_fit`, and
`add_fit_parser`, which adds `fit` and its kinds to the `jaxrb` parser (`_cli.py`). Every
failure is one line on stderr, never a traceback: exit status 2 for a bad data file, scene or
option (naming the file and the column or field), 1 for a fit that fails or does not converge.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from ._cli_common import (
    CLIError,
    StagedOutput,
    _fmt,
    _table,
    add_cache_option,
    add_output_options,
    check_output,
    one_line,
)

_EPILOG_FIT = """\
kinds:
  inertia      the inertia tensor (products included) from body angular velocity and/or
               attitude samples of a tumbling body
  restitution  Newton's coefficient of restitution from the bounces of a dropped ball
  drag         a drag coefficient from the tracked flight of a body
  contact      the floor's restitution and friction from a tracked body bouncing on it

each kind reads a data file: CSV (a header row of column names, then one row per sample;
lines starting with '#' are comments; extra columns are ignored) or .npz (one array per
column). `jaxrb fit KIND --write-example FILE` writes an example from a known synthetic
motion; `jaxrb fit KIND --help` lists the columns and options.
"""

_FIT_OUTPUT = """
output: OUTPUT/fit_{kind}.json: fitted values and one-sigma standard errors (Gauss-Newton,
noise level estimated from the residuals), covariance, residual norm, degrees of freedom,
condition number, converged or not and why, steps taken and rejected, warnings. The summary
table is printed.

the fit: Levenberg-Marquardt; a trial step where the model cannot be evaluated (an invalid
parameter, a failed simulation) is rejected and a shorter one tried. --max-steps is its
budget of trial steps.

exit status: 0 converged; 1 the fit did not converge or failed (one line on stderr; the
results file is still written when the fit ran); 2 a bad data file or option (one line
naming the file and the column, or the option).
"""

_EPILOG_FIT_INERTIA = (
    """\
data columns (CSV header names, or .npz array names):
  t               sample times (s), strictly increasing
  wx, wy, wz      angular velocity in the BODY frame (rad/s), e.g. a gyro      } one or
  e0, e1, e2, e3  attitude: unit quaternion, scalar first, body -> world       } both
  tx, ty, tz      optional: known torque about the mass centre, BODY frame (N m),
                  linearly interpolated between samples
  .npz may instead hold arrays omega (N, 3), quat (N, 4), torque (N, 3). The
  trajectory.csv / .npz of `jaxrb run` can be read directly (if the motion fits the
  model: no impacts, no aerodynamic moment).

model: a free rigid body (jaxrb.simulate; uniform gravity exerts no torque about the mass
centre, so it is left out) with the fitted inertia tensor and initial state. Without a known
torque the motion determines the tensor only up to a positive factor: the fit then keeps
trace(J) = trace(--inertia0) and says so. With torque columns the absolute scale is fitted.
Reported: the tensor entries Jxx .. Jyz (kg m^2, body axes, about the mass centre; the
off-diagonal entries are minus the products of inertia), omega0 and quat0.

example:
  jaxrb fit inertia --write-example omega.csv
  jaxrb fit inertia omega.csv --inertia0 2.5,3,3.5
"""
    + _FIT_OUTPUT.format(kind="inertia")
    + "vectors are comma separated; write one with a leading minus as --omega0=-1,0,2.\n"
)

_EPILOG_FIT_RESTITUTION = """\
data columns (one row per bounce k = 1, 2, ...; either or both):
  impact_time     time of impact k (s), counted from a release from rest at t = 0
  apex_height     height of the ball's lowest point above the floor at the top after
                  bounce k (m); with --radius R: the height of its centre
  a shorter column may leave its last cells empty; .npz arrays may differ in length
  (names impact_time / impact_times, apex_height / apex_heights).

model: the exact bouncing ball, t_1 = sqrt(2 h0 / g), t_(k+1) - t_k = 2 e^k sqrt(2 g h0) / g,
apex after bounce k = e^(2k) h0. Fitted: e (and the drop height h0 unless --h0 is given).

example:
  jaxrb fit restitution --write-example bounces.csv
  jaxrb fit restitution bounces.csv
""" + _FIT_OUTPUT.format(kind="restitution")

_EPILOG_FIT_DRAG = """\
data columns:
  t               sample times (s), strictly increasing
  x, y, z         mass-centre position, WORLD frame, z up (m)
  vx, vy, vz      optional: velocity, world frame (m/s)
  .npz may instead hold arrays pos (N, 3), vel (N, 3).

model: the mass centre under gravity (0, 0, -g) and quadratic drag F = -k |v| v
(k = rho C_D A / 2, kg/m) or linear drag F = -c v (N s/m, --model linear), integrated by
jaxrb.simulate. Drag acts through k / mass, so --mass is needed. Fitted: the coefficient and
the initial position and velocity (unless --no-fit-initial).

example:
  jaxrb fit drag --write-example flight.csv
  jaxrb fit drag flight.csv --mass 0.057 --drag0 0.002
""" + _FIT_OUTPUT.format(kind="drag")

_EPILOG_FIT_CONTACT = """\
data columns:
  t               sample times (s), strictly increasing; t[0] is the time of the scene's
                  [initial] state
  x, y, z         mass-centre position, WORLD frame, z up (m)
  wx, wy, wz      optional: angular velocity in the BODY frame (rad/s), e.g. a gyro,
                  weighted by --omega-weight (m per rad/s) against the positions
  .npz may instead hold arrays pos (N, 3), omega (N, 3).

the scene (--scene, a scene file or the name of a shipped example; see jaxrb run
--show-default): its body (mass, inertia, [body.shape]), [[forces]], [floor] height and
[initial] state are known; the floor's restitution and friction are the initial guesses
(--restitution0, --friction0 override them). [simulation] is not used: the model is saved
at the data's times, integrated with --rtol / --atol.

model: jaxrb.simulate with the floor (impacts located as events, Newton's restitution and
Coulomb friction), differentiated in forward mode across the impacts. Fitted: the
restitution e in (0, 1) and, unless --fix-friction, the friction coefficient mu > 0.
Friction is identifiable only if the contact slides at some impact.

example (--write-example FILE also writes the scene, FILE with the suffix .toml):
  jaxrb fit contact --write-example bounce.csv
  jaxrb fit contact bounce.csv --scene bounce.toml
""" + _FIT_OUTPUT.format(kind="contact")


# ---------------------------------------------------------------------------------------------
# fit: data files


class _Data:
    """The columns of a data file (1-D float arrays by name) and how to name a row in errors."""

    def __init__(self, path: Path, columns: dict, lines=None, empty=None):
        self.path = path
        self.columns = columns  # name -> 1-D array (float for CSV; any dtype for .npz)
        self.lines = lines  # CSV: the file line number of each data row
        self.empty = empty or {}  # CSV: name -> bool mask of empty cells

    def fail(self, problem: str):
        raise CLIError(f"{self.path}: {problem}")

    def where(self, i: int) -> str:
        return f"line {self.lines[i]}" if self.lines is not None else f"index {i}"

    def has(self, name: str) -> bool:
        return name in self.columns

    def found(self) -> str:
        return ", ".join(self.columns) or "none"

    def column(self, name: str, *, trailing_empty: bool = False) -> np.ndarray:
        """A finite float column; `trailing_empty`: empty CSV cells at the end shorten it."""
        if name not in self.columns:
            self.fail(f"missing column '{name}' (columns found: {self.found()})")
        raw = np.asarray(self.columns[name])
        if raw.ndim != 1 or not (
            np.issubdtype(raw.dtype, np.floating) or np.issubdtype(raw.dtype, np.integer)
        ):
            self.fail(
                f"column '{name}' must be a 1-D array of numbers, got {raw.dtype} {raw.shape}"
            )
        values = raw.astype(float)
        empty = self.empty.get(name, np.zeros(values.shape, bool))
        if empty.any():
            first = int(np.argmax(empty))
            if trailing_empty and empty[first:].all():
                values, empty = values[:first], empty[:first]
            else:
                self.fail(f"column '{name}': empty value at {self.where(first)}")
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            what = "NaN" if np.isnan(values[i]) else "infinite value"
            self.fail(f"column '{name}': {what} at {self.where(i)}; values must be finite")
        return values

    def group(self, names, what: str):
        """An (N, len(names)) array of columns that must all be present, or None if none is."""
        present = [n for n in names if n in self.columns]
        if not present:
            return None
        missing = [n for n in names if n not in self.columns]
        if missing:
            self.fail(
                f"missing column '{missing[0]}': {what} needs all of {', '.join(names)} "
                f"(columns found: {self.found()})"
            )
        cols = [self.column(n) for n in names]
        return np.stack(cols, axis=-1)

    def same_length(self, arrays: dict):
        """All named arrays have the same number of rows (only an .npz can disagree)."""
        (name0, a0), *rest = arrays.items()
        for name, a in rest:
            if len(a) != len(a0):
                self.fail(
                    f"column '{name}' has {len(a)} values but '{name0}' has {len(a0)}: "
                    "every column needs one value per sample"
                )

    def times(self, name: str = "t") -> np.ndarray:
        t = self.column(name)
        if t.size and np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            self.fail(
                f"column '{name}' must be strictly increasing: {t[i]:g} at {self.where(i)} "
                f"follows {t[i - 1]:g}"
            )
        return t


# .npz arrays of shape (N, k) that stand for k columns
_NPZ_GROUPS = {
    "omega": ("wx", "wy", "wz"),
    "quat": ("e0", "e1", "e2", "e3"),
    "torque": ("tx", "ty", "tz"),
    "pos": ("x", "y", "z"),
    "vel": ("vx", "vy", "vz"),
    "impact_times": ("impact_time",),
    "apex_heights": ("apex_height",),
}


def _read_data(path: Path) -> _Data:
    """Read a CSV (header row, '#' comment lines) or .npz data file into columns."""
    if not path.exists():
        raise CLIError(f"{path}: no such data file")
    if path.is_dir():
        raise CLIError(f"{path}: is a directory, not a data file")
    if path.suffix.lower() == ".npz":
        return _read_npz(path)
    return _read_csv(path)


def _read_npz(path: Path) -> _Data:
    import zipfile

    if not zipfile.is_zipfile(path):
        raise CLIError(f"{path}: cannot read: not a NumPy .npz archive (not a zip file)")
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {k: np.asarray(archive[k]) for k in archive.files}
    except Exception as e:  # noqa: BLE001 - any failure to read is the same user error
        raise CLIError(f"{path}: cannot read as a NumPy .npz archive: {e}") from None
    columns = {}
    for key, a in arrays.items():
        if key in _NPZ_GROUPS and a.ndim == 2:
            names = _NPZ_GROUPS[key]
            if a.shape[1] != len(names):
                raise CLIError(
                    f"{path}: array '{key}' must have shape (N, {len(names)}) "
                    f"(columns {', '.join(names)}), got {a.shape}"
                )
            for j, n in enumerate(names):
                columns.setdefault(n, a[:, j])
        elif key in _NPZ_GROUPS and len(_NPZ_GROUPS[key]) == 1 and a.ndim == 1:
            columns.setdefault(_NPZ_GROUPS[key][0], a)
        elif a.ndim == 1:
            columns[key] = a
    return _Data(path, columns)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_csv(path: Path) -> _Data:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise CLIError(
            f"{path}: cannot read: not a UTF-8 text CSV file (NumPy archives need the .npz "
            "extension)"
        ) from None
    except OSError as e:
        raise CLIError(f"{path}: cannot read: {e.strerror or e}") from None
    numbered = [
        (i + 1, line)
        for i, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not numbered:
        raise CLIError(f"{path}: empty: expected a header row of column names, then data rows")
    rows = list(csv.reader([line for _, line in numbered]))
    header = [h.strip() for h in rows[0]]
    first_line = numbered[0][0]
    if any(_is_number(h) for h in header):
        raise CLIError(
            f"{path}: line {first_line}: the first row must be a header of column names "
            f"(e.g. t,wx,wy,wz), got {','.join(header)}"
        )
    if any(not h for h in header):
        raise CLIError(f"{path}: line {first_line}: empty column name in the header")
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes:
        raise CLIError(f"{path}: line {first_line}: column '{dupes[0]}' appears more than once")
    values = np.zeros((len(rows) - 1, len(header)))
    empty = np.zeros(values.shape, bool)
    lines = []
    for k, ((lineno, _), row) in enumerate(zip(numbered[1:], rows[1:], strict=True)):
        lines.append(lineno)
        if len(row) != len(header):
            raise CLIError(
                f"{path}: line {lineno}: {len(row)} values but the header has {len(header)} "
                f"columns ({', '.join(header)})"
            )
        for j, (name, cell) in enumerate(zip(header, row, strict=True)):
            cell = cell.strip()
            if not cell:
                empty[k, j] = True
                continue
            try:
                values[k, j] = float(cell)
            except ValueError:
                raise CLIError(
                    f"{path}: line {lineno}, column '{name}': not a number: {cell!r}"
                ) from None
    columns = {h: values[:, j] for j, h in enumerate(header)}
    return _Data(path, columns, lines=lines, empty={h: empty[:, j] for j, h in enumerate(header)})


def _vector(text, option: str, sizes=(3,)) -> np.ndarray | None:
    """Parse a comma-separated option value like "1,2,3"."""
    if text is None:
        return None
    try:
        v = np.array([float(x) for x in str(text).replace(" ", "").split(",") if x], dtype=float)
    except ValueError:
        v = np.zeros(0)
    if v.size not in sizes or not np.all(np.isfinite(v)):
        want = " or ".join(str(s) for s in sizes)
        raise CLIError(
            f"{option} {text!r}: expected {want} comma-separated finite numbers "
            f"(write a leading minus as {option}=-1,2,3)"
        )
    return v


def _positive(value, option: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise CLIError(f"{option} must be a finite number > 0, got {value:g}")
    return value


def _write_columns(path: Path, columns: dict, comment: str):
    """Write equal-length columns as CSV (with '#' comment lines) or .npz (by extension)."""
    if path.suffix.lower() == ".npz":
        np.savez(path, description=np.array(comment), **columns)
        return
    names = list(columns)
    n = max(len(c) for c in columns.values())
    with open(path, "w", newline="") as f:
        for line in comment.splitlines():
            f.write(f"# {line}\n")
        w = csv.writer(f)
        w.writerow(names)
        for i in range(n):
            w.writerow(
                [f"{float(columns[c][i]):.17g}" if i < len(columns[c]) else "" for c in names]
            )


# ---------------------------------------------------------------------------------------------
# fit: the three kinds. `_fit_KIND(data, args)` checks the data and options and returns
# (run, describe): `run()` fits and returns the `FitResult`; `describe(result)` gives the table
# rows (parameter, value, std, unit), the extra facts for the results file, and extra summary
# lines.

_INERTIA_EXAMPLE = dict(
    inertia=[[2.0, -0.3, 0.1], [-0.3, 3.0, 0.2], [0.1, 0.2, 4.0]],
    omega0=[1.0, 0.5, 0.8],
    axis=[1.0, 2.0, 0.5],
    angle=0.7,
    torque=[0.3, -0.2, 0.5],
    t_end=2.0,
    num=21,
)
_RESTITUTION_EXAMPLE = dict(restitution=0.7, h0=1.2, g=9.81, bounces=5)
_DRAG_EXAMPLE = dict(
    mass=0.057,
    drag=0.5 * 1.2 * 0.55 * np.pi * 0.033**2,
    pos0=[0.0, 0.0, 1.5],
    vel0=[12.0, 1.0, 8.0],
    t_end=1.5,
    num=16,
)
_CONTACT_EXAMPLE = dict(
    mass=0.2,
    radius=0.05,
    restitution=0.6,
    friction=0.1,
    pos0=[0.0, 0.0, 0.5],
    vel0=[1.5, 0.3, 0.0],
    omega0=[5.0, -40.0, 0.0],
    g=9.81,
    t_end=0.8,
    num=25,
    guesses=(0.5, 0.2),
)


def _tolerances(args) -> tuple[float, float]:
    """--rtol and --atol of the model's adaptive integrator (--atol defaults to --rtol)."""
    rtol = _positive(args.rtol, "--rtol")
    atol = rtol if args.atol is None else _positive(args.atol, "--atol")
    return rtol, atol


def _sim_kwargs(args) -> dict:
    """Simulation settings of the fitted model: adaptive (--rtol, --atol) or fixed step (--dt)."""
    rtol, atol = _tolerances(args)
    if args.dt is not None:
        import diffrax as dfx

        dt = _positive(args.dt, "--dt")
        return dict(solver=dfx.Tsit5(), stepsize_controller=dfx.ConstantStepSize(), dt0=dt)
    return dict(sim_rtol=rtol, sim_atol=atol)


def _integrator(args) -> dict:
    """The model's integrator settings, for the results file."""
    if getattr(args, "dt", None) is not None:
        return {"solver": "tsit5", "dt": float(args.dt)}
    rtol, atol = _tolerances(args)
    return {"solver": "tsit5 (adaptive)", "rtol": rtol, "atol": atol}


def _max_steps(args) -> int:
    """--max-steps, the Levenberg-Marquardt budget of trial steps."""
    if args.max_steps < 1:
        raise CLIError(f"--max-steps must be an integer >= 1, got {args.max_steps}")
    return int(args.max_steps)


def _rk4(f, y0, ts, h):
    """Classical Runge-Kutta (NumPy) with steps of at most `h`; the states at the times `ts`."""
    ys = [np.asarray(y0, float)]
    for t0, t1 in zip(ts[:-1], ts[1:], strict=True):
        n = int(np.ceil((t1 - t0) / h))
        dt, y, t = (t1 - t0) / n, ys[-1], t0
        for _ in range(n):
            k1 = f(t, y)
            k2 = f(t + dt / 2, y + dt / 2 * k1)
            k3 = f(t + dt / 2, y + dt / 2 * k2)
            k4 = f(t + dt, y + dt * k3)
            y, t = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), t + dt
        ys.append(y)
    return np.stack(ys)


def _example_inertia():
    # Data from NumPy RK4 (steps of 1 ms: error ~1e-12), independent of jaxrb.simulate:
    # Euler's equations J w' = M - w x (J w) (body frame) and q' = q (x) (0, w) / 2.
    ex = _INERTIA_EXAMPLE
    J, M = np.asarray(ex["inertia"]), np.asarray(ex["torque"])
    J_inv = np.linalg.inv(J)

    def f(t, y):
        q, w = y[:4], y[4:]
        q_dot = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
        return np.concatenate([q_dot, J_inv @ (M - np.cross(w, J @ w))])

    axis = np.asarray(ex["axis"]) / np.linalg.norm(ex["axis"])
    q0 = np.concatenate([[np.cos(ex["angle"] / 2)], np.sin(ex["angle"] / 2) * axis])
    ts = np.linspace(0.0, ex["t_end"], ex["num"])
    y = _rk4(f, np.concatenate([q0, ex["omega0"]]), ts, 1e-3)
    quat = y[:, :4] / np.linalg.norm(y[:, :4], axis=-1, keepdims=True)
    omega = y[:, 4:]
    columns = {"t": ts}
    columns.update({n: omega[:, i] for i, n in enumerate(("wx", "wy", "wz"))})
    columns.update({n: quat[:, i] for i, n in enumerate(("e0", "e1", "e2", "e3"))})
    columns.update({n: np.full(ts.size, v) for n, v in zip(("tx", "ty", "tz"), M, strict=True)})
    comment = (
        "jaxrb fit inertia example: a body tumbling under a known constant body-frame torque.\n"
        "t (s); wx, wy, wz: angular velocity, body frame (rad/s); e0..e3: attitude quaternion,\n"
        "scalar first, body -> world; tx, ty, tz: known torque, body frame (N m).\n"
        f"true inertia (kg m^2, body axes) {J.tolist()};\n"
        f"true omega0 {ex['omega0']} rad/s; true quat0 {np.round(q0, 12).tolist()}"
    )
    return columns, comment, "--inertia0 2.5,3,3.5"


def _example_restitution():
    ex = _RESTITUTION_EXAMPLE
    e, h0, g, n = ex["restitution"], ex["h0"], ex["g"], ex["bounces"]
    k = np.arange(1, n + 1)
    u1 = np.sqrt(2 * g * h0)  # speed at the first impact
    times = u1 / g + np.concatenate([[0.0], np.cumsum(2 * e ** k[:-1] * u1 / g)])
    columns = {"bounce": k.astype(float), "impact_time": times, "apex_height": e ** (2 * k) * h0}
    comment = (
        "jaxrb fit restitution example: a ball dropped from rest at t = 0 onto a floor.\n"
        "impact_time: time of bounce k (s); apex_height: height of the ball's lowest point at\n"
        f"the top after bounce k (m). true restitution {e}, drop height h0 {h0} m, g {g} m/s^2"
    )
    return columns, comment, ""


def _example_drag():
    # NumPy RK4 (1 ms steps), independent of jaxrb.simulate: x'' = g - (k / m) |v| v.
    ex = _DRAG_EXAMPLE
    g, c = np.array([0.0, 0.0, -9.81]), ex["drag"] / ex["mass"]

    def f(t, y):
        v = y[3:]
        return np.concatenate([v, g - c * np.linalg.norm(v) * v])

    ts = np.linspace(0.0, ex["t_end"], ex["num"])
    pos = _rk4(f, np.concatenate([ex["pos0"], ex["vel0"]]), ts, 1e-3)[:, :3]
    columns = {"t": ts, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]}
    comment = (
        "jaxrb fit drag example: a tennis ball thrown through air (gravity and quadratic drag).\n"
        "t (s); x, y, z: mass-centre position, world frame, z up (m).\n"
        f"true mass {ex['mass']} kg, true drag k = rho C_D A / 2 = {ex['drag']:.12g} kg/m,\n"
        f"true pos0 {ex['pos0']} m, vel0 {ex['vel0']} m/s; g = 9.81 m/s^2"
    )
    return columns, comment, f"--mass {ex['mass']} --drag0 0.002"


def _quat_multiply(a, b):
    """Quaternion product a (x) b (scalar first)."""
    return np.concatenate(
        [[a[0] * b[0] - a[1:] @ b[1:]], a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])]
    )


def _quat_of_rotation(rotvec):
    """The unit quaternion of a rotation vector (rad)."""
    angle = np.linalg.norm(rotvec)
    if angle == 0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rotvec / angle])


def _bouncing_ball(ts, ex):
    """Closed-form motion of a solid sphere bouncing on the floor z = 0 under gravity alone:
    parabolic flights (constant world angular velocity), and at each impact Newton's
    restitution on the normal velocity and Coulomb friction on the slip of the contact point
    (it stops if mu P_n suffices, else P_t = -mu P_n along the slip). Returns the positions
    (world, m) and body-frame angular velocities (rad/s) at `ts` (from t = 0, identity
    attitude at the start)."""
    m, radius, e, mu = ex["mass"], ex["radius"], ex["restitution"], ex["friction"]
    inertia = 0.4 * m * radius**2
    m_slip = m / (1 + m * radius**2 / inertia)  # effective mass of the contact point's slip
    acc, arm = np.array([0.0, 0.0, -ex["g"]]), np.array([0.0, 0.0, -radius])
    t, quat = 0.0, np.array([1.0, 0.0, 0.0, 0.0])
    pos, vel, omega = (np.array(ex[k], float) for k in ("pos0", "vel0", "omega0"))

    def fly(tau):
        turn = _quat_multiply(_quat_of_rotation(omega * tau), quat)
        return pos + vel * tau + 0.5 * acc * tau**2, vel + acc * tau, turn

    positions, rates = [], []
    for t_k in ts:
        while True:
            tau = (vel[2] + np.sqrt(vel[2] ** 2 + 2 * ex["g"] * (pos[2] - radius))) / ex["g"]
            if t + tau > t_k:
                break
            pos, vel, quat = fly(tau)
            t, pos[2] = t + tau, radius
            p_n = -m * (1 + e) * vel[2]
            slip = vel + np.cross(omega, arm)
            slip[2] = 0.0
            speed = np.linalg.norm(slip)
            p_t = -m_slip * slip if mu * p_n >= m_slip * speed else -mu * p_n * slip / speed
            vel = vel + (np.array([0.0, 0.0, p_n]) + p_t) / m
            omega = omega + np.cross(arm, p_t) / inertia
        p_k, _, q_k = fly(t_k - t)
        conj = q_k * np.array([1.0, -1.0, -1.0, -1.0])
        rates.append(_quat_multiply(_quat_multiply(conj, np.concatenate([[0.0], omega])), q_k)[1:])
        positions.append(p_k)
    return np.array(positions), np.array(rates)


def _example_contact():
    ex = _CONTACT_EXAMPLE
    ts = np.linspace(0.0, ex["t_end"], ex["num"])
    pos, omega = _bouncing_ball(ts, ex)
    columns = {"t": ts}
    columns.update({n: pos[:, i] for i, n in enumerate(("x", "y", "z"))})
    columns.update({n: omega[:, i] for i, n in enumerate(("wx", "wy", "wz"))})
    comment = (
        "jaxrb fit contact example: a ball thrown with backspin, bouncing twice on a floor\n"
        "(closed form: parabolic flights, Newton restitution and Coulomb friction at impacts).\n"
        "t (s); x, y, z: mass-centre position, world frame, z up (m); wx, wy, wz: angular\n"
        f"velocity, body frame (rad/s). true restitution {ex['restitution']}, true friction "
        f"{ex['friction']} (the first impact slides)"
    )
    return columns, comment, ""


def _example_contact_scene() -> str:
    """The scene file of the contact example: the known ball, forces and initial state."""
    ex = _CONTACT_EXAMPLE
    e0, mu0 = ex["guesses"]
    return f"""\
# jaxrb fit contact example scene: the tracked ball (known), its forces and its state at the
# first sample time. The floor's restitution and friction are the fit's initial guesses.
title = "Ball bouncing with backspin"
description = "A {ex["mass"]} kg ball of radius {ex["radius"]} m thrown with backspin."

[body]
mass = {ex["mass"]}                            # kg
[body.shape]
type = "sphere"                       # solid sphere: inertia 2/5 m r^2
radius = {ex["radius"]}                         # m

[initial]                             # at t = 0, the first sample
pos = {ex["pos0"]}                # m, world frame
vel = {ex["vel0"]}                # m/s, world frame
omega = {ex["omega0"]}            # rad/s, BODY frame (identity attitude)

[[forces]]
type = "gravity"
g = [0.0, 0.0, {-ex["g"]}]

[floor]
restitution = {e0}                     # initial guess
friction = {mu0}                        # initial guess
height = 0.0

[simulation]                          # used by jaxrb run, not by jaxrb fit
t_end = {ex["t_end"]}
num_saves = {ex["num"]}
"""


def _known_torque(t, torque):
    """A body-frame `Wrench` from sampled torque (N m): constant, or linearly interpolated."""
    import jax.numpy as jnp

    import jaxrb

    if np.all(torque == torque[0]):
        return jaxrb.Wrench(torque=jnp.asarray(torque[0]), frame="body")
    tt, tq = jnp.asarray(t), jnp.asarray(torque)

    def torque_fn(time):
        return jnp.stack([jnp.interp(time, tt, tq[:, i]) for i in range(3)])

    return jaxrb.Wrench(torque=torque_fn, frame="body")


def _fit_inertia(data: _Data, args):
    import jax.numpy as jnp

    import jaxrb
    import jaxrb.fit

    if args.inertia0 is None:
        raise CLIError(
            "--inertia0 is required: an initial guess of the inertia tensor (kg m^2, body "
            "axes), 3 principal moments Jxx,Jyy,Jzz or 9 entries row by row"
        )
    J0 = _vector(args.inertia0, "--inertia0", (3, 9))
    J0 = np.diag(J0) if J0.size == 3 else J0.reshape(3, 3)
    try:
        jaxrb.inertia.check_inertia(jnp.asarray(J0), name="--inertia0")
    except ValueError as e:
        raise CLIError(str(e)) from None
    t = data.times("t")
    omega = data.group(("wx", "wy", "wz"), "the angular velocity")
    quat = data.group(("e0", "e1", "e2", "e3"), "the attitude quaternion")
    torque = data.group(("tx", "ty", "tz"), "the known torque")
    if omega is None and quat is None:
        data.fail(
            "no motion data: need angular velocity columns wx, wy, wz (body frame, rad/s) "
            "and/or attitude columns e0, e1, e2, e3 (scalar first, body -> world); "
            f"columns found: {data.found()}"
        )
    data.same_length(
        {k: v for k, v in (("t", t), ("wx", omega), ("e0", quat), ("tx", torque)) if v is not None}
    )
    if quat is not None:
        norm = np.linalg.norm(quat, axis=-1)
        bad = np.abs(norm - 1) > 1e-6
        if bad.any():
            i = int(np.argmax(bad))
            data.fail(
                f"columns e0, e1, e2, e3: |q| = {norm[i]:.8g} at {data.where(i)}; the attitude "
                "must be unit quaternions (within 1e-6)"
            )
    omega0 = _vector(args.omega0, "--omega0")
    if omega is None and omega0 is None:
        raise CLIError(
            f"{data.path} has no angular velocity columns (wx, wy, wz): give --omega0 WX,WY,WZ, "
            "a guess of the initial body-frame angular velocity (rad/s)"
        )
    forces = () if torque is None else (_known_torque(t, torque),)
    kwargs = dict(
        inertia0=J0,
        omega=omega,
        quat=quat,
        forces=forces,
        omega0=omega0,
        fit_initial=not args.no_fit_initial,
        fix_scale=args.fix_scale,
        omega_noise=_positive(args.omega_noise, "--omega-noise"),
        quat_noise=_positive(args.quat_noise, "--quat-noise"),
        max_steps=_max_steps(args),
        **_sim_kwargs(args),
    )
    info = {
        "samples": int(t.size),
        "observed": [n for n, v in (("omega", omega), ("quat", quat)) if v is not None],
        "known_torque": torque is not None,
        "integrator": _integrator(args),
    }
    return (lambda: jaxrb.fit.fit_inertia(t, **kwargs)), (lambda res: _describe_inertia(res, info))


def _describe_inertia(res, info):
    J, dJ = res.values["inertia"], res.std["inertia"]
    rows = [
        (f"J{'xyz'[i]}{'xyz'[j]}", J[i, j], dJ[i, j], "kg m^2")
        for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    ]
    rows += [
        (f"omega0_{c}", res.values["omega0"][i], res.std["omega0"][i], "rad/s")
        for i, c in enumerate("xyz")
    ]
    rows += [(f"quat0_e{i}", res.values["quat0"][i], res.std["quat0"][i], "") for i in range(4)]
    moments = np.linalg.eigvalsh(0.5 * (J + J.T))
    info = {**info, "principal_moments": moments}
    return rows, info, [("principal moments (kg m^2)", _fmt(moments))]


def _fit_restitution(data: _Data, args):
    import jaxrb.fit

    times = heights = None
    if data.has("impact_time"):
        times = data.column("impact_time", trailing_empty=True)
    if data.has("apex_height"):
        heights = data.column("apex_height", trailing_empty=True)
    if times is None and heights is None:
        data.fail(
            "missing column 'impact_time' and/or 'apex_height': need impact times (s, after a "
            "release from rest at t = 0) and/or apex heights (m) of the bounces; "
            f"columns found: {data.found()}"
        )
    if times is not None and times.size and np.any(np.diff(times) <= 0):
        i = int(np.argmax(np.diff(times) <= 0)) + 1
        data.fail(
            f"column 'impact_time' must be strictly increasing: {times[i]:g} at "
            f"{data.where(i)} follows {times[i - 1]:g}"
        )
    if times is not None and times.size and times[0] <= 0:
        data.fail(f"column 'impact_time' must be > 0 (time since release), {data.where(0)}")
    radius = float(args.radius)
    if not (np.isfinite(radius) and radius >= 0):
        raise CLIError(f"--radius must be a finite number >= 0, got {radius:g}")
    if heights is not None:
        heights = heights - radius
        if heights.size and np.any(heights <= 0):
            i = int(np.argmax(heights <= 0))
            data.fail(
                f"column 'apex_height' must be > {radius:g} (the --radius) "
                f"at {data.where(i)}, got {heights[i] + radius:g}"
            )
    h0 = None if args.h0 is None else _positive(args.h0, "--h0") - radius
    if h0 is not None and h0 <= 0:
        raise CLIError(f"--h0 must exceed --radius {radius:g}, got {args.h0:g}")
    h0_guess = None if args.h0_guess is None else _positive(args.h0_guess, "--h0-guess") - radius
    e0 = float(args.restitution0)
    if not 0 < e0 < 1:
        raise CLIError(f"--restitution0 must be in (0, 1), got {e0:g}")
    g = _positive(args.g, "--g")
    kwargs = dict(
        impact_times=times,
        apex_heights=heights,
        h0=h0,
        h0_guess=h0_guess,
        restitution0=e0,
        g=g,
        time_noise=_positive(args.time_noise, "--time-noise"),
        height_noise=_positive(args.height_noise, "--height-noise"),
        max_steps=_max_steps(args),
    )
    info = {
        "impacts": 0 if times is None else int(times.size),
        "apexes": 0 if heights is None else int(heights.size),
        "radius": radius,
        "h0_given": h0 is not None,
    }
    return (lambda: jaxrb.fit.fit_restitution(**kwargs)), (
        lambda res: _describe_restitution(res, info, g)
    )


def _describe_restitution(res, info, g):
    radius = info["radius"]
    where = "centre" if radius > 0 else "lowest point"
    rows = [
        ("restitution e", res.values["restitution"], res.std["restitution"], ""),
        (f"h0 (drop height, {where})", res.values["h0"] + radius, res.std["h0"], "m"),
    ]
    e = float(res.values["restitution"])
    t1 = np.sqrt(2 * float(res.values["h0"]) / g)
    extra = [("bounces end at (s, drop from rest)", _fmt(t1 * (1 + e) / (1 - e)))]
    # the results file reports h0 as the table does (of the centre when --radius is given)
    info = {**info, "h0_of": where, "values": {"h0": res.values["h0"] + radius}}
    return rows, info, extra


def _fit_drag(data: _Data, args):
    import jaxrb.fit

    if args.mass is None:
        raise CLIError("--mass is required: the body mass (kg); drag acts through k / mass")
    mass = _positive(args.mass, "--mass")
    if args.drag0 is None:
        raise CLIError(
            "--drag0 is required: an initial guess of the drag coefficient (quadratic: "
            "k = rho C_D A / 2 in kg/m; linear: c in N s/m)"
        )
    drag0 = _positive(args.drag0, "--drag0")
    t = data.times("t")
    pos = data.group(("x", "y", "z"), "the position")
    if pos is None:
        data.fail(
            "missing column 'x': need mass-centre positions x, y, z (world frame, z up, m); "
            f"columns found: {data.found()}"
        )
    vel = data.group(("vx", "vy", "vz"), "the velocity")
    data.same_length({k: v for k, v in (("t", t), ("x", pos), ("vx", vel)) if v is not None})
    if t.size < 2:
        data.fail(f"too few samples: {t.size} row(s); a flight needs many samples")
    g = _positive(args.g, "--g")
    kwargs = dict(
        mass=mass,
        drag0=drag0,
        model=args.model,
        vel=vel,
        fit_initial=not args.no_fit_initial,
        g=(0.0, 0.0, -g),
        max_steps=_max_steps(args),
        **_sim_kwargs(args),
    )
    info = {
        "samples": int(t.size),
        "mass": mass,
        "model": args.model,
        "integrator": _integrator(args),
    }
    return (lambda: jaxrb.fit.fit_drag(t, pos, **kwargs)), (
        lambda res: _describe_drag(res, info, g)
    )


def _describe_drag(res, info, g):
    mass, model = info["mass"], info["model"]
    unit = "kg/m" if model == "quadratic" else "N s/m"
    name = "k (F = -k |v| v)" if model == "quadratic" else "c (F = -c v)"
    rows = [(f"drag {name}", res.values["drag"], res.std["drag"], unit)]
    rows += [
        (f"pos0_{c}", res.values["pos0"][i], res.std["pos0"][i], "m") for i, c in enumerate("xyz")
    ]
    rows += [
        (f"vel0_{c}", res.values["vel0"][i], res.std["vel0"][i], "m/s") for i, c in enumerate("xyz")
    ]
    k = float(res.values["drag"])
    v_t = np.sqrt(mass * g / k) if model == "quadratic" else mass * g / k
    return rows, {**info, "terminal_speed": v_t}, [("terminal speed (m/s)", _fmt(v_t))]


def _fit_contact(data: _Data, args):
    import equinox as eqx
    import jax.numpy as jnp

    import jaxrb
    import jaxrb.fit

    from ._scene_examples import scene_path
    from ._scene_file import SceneFileError, load_scene

    if args.scene is None:
        raise CLIError(
            "--scene is required: a scene file (or a shipped example's name) giving the body "
            "and its shape, the forces, the floor and the state at the first sample time"
        )
    t = data.times("t")
    pos = data.group(("x", "y", "z"), "the position")
    if pos is None:
        data.fail(
            "missing column 'x': need mass-centre positions x, y, z (world frame, z up, m); "
            f"columns found: {data.found()}"
        )
    omega = data.group(("wx", "wy", "wz"), "the angular velocity")
    data.same_length({k: v for k, v in (("t", t), ("x", pos), ("wx", omega)) if v is not None})
    if t.size < 2:
        data.fail(f"too few samples: {t.size} row(s); a tracked bounce needs many samples")
    try:
        spec = load_scene(scene_path(args.scene))
    except SceneFileError as e:
        raise CLIError(str(e)) from None
    scene = spec.scene
    if scene.floor is None:
        raise CLIError(
            f"{spec.source}: the scene has no [floor]; jaxrb fit contact fits the floor's "
            "restitution and friction"
        )
    e0 = float(scene.floor.restitution if args.restitution0 is None else args.restitution0)
    if not 0 < e0 < 1:
        where = "--restitution0" if args.restitution0 is not None else "[floor].restitution"
        raise CLIError(
            f"{where}: the initial guess of the restitution must be in (0, 1), got {e0:g}"
            + ("; give --restitution0" if args.restitution0 is None else "")
        )
    friction0 = None if args.friction0 is None else _positive(args.friction0, "--friction0")
    if args.fix_friction:
        if friction0 is not None:  # held at the given value instead of the scene's
            floor = eqx.tree_at(lambda f: f.friction, scene.floor, jnp.asarray(friction0))
            scene = jaxrb.Scene(scene.body, scene.forces, floor=floor)
        friction0 = None
    elif friction0 is None:
        friction0 = float(scene.floor.friction)
        if friction0 <= 0:
            raise CLIError(
                f"{spec.source}: [floor].friction is 0: give --friction0 > 0 as the initial "
                "guess, or --fix-friction to hold it"
            )
    if args.max_impacts < 1:
        raise CLIError(f"--max-impacts must be an integer >= 1, got {args.max_impacts}")
    rtol, atol = _tolerances(args)
    kwargs = dict(
        omega=omega,
        restitution0=e0,
        friction0=friction0,
        omega_weight=_positive(args.omega_weight, "--omega-weight"),
        max_steps=_max_steps(args),
        sim_rtol=rtol,
        sim_atol=atol,
        max_impacts=int(args.max_impacts),
    )
    gap = float(np.linalg.norm(pos[0] - np.asarray(spec.state0.pos)))
    info = {
        "samples": int(t.size),
        "scene": spec.source,
        "observed": ["pos"] + (["omega"] if omega is not None else []),
        "friction_fitted": friction0 is not None,
        "initial_position_gap": gap,
        "integrator": _integrator(args),
    }
    return (lambda: jaxrb.fit.fit_contact(scene, spec.state0, t, pos, **kwargs)), (
        lambda res: _describe_contact(res, info)
    )


def _describe_contact(res, info):
    rows = [
        ("restitution e", res.values["restitution"], res.std["restitution"], ""),
        ("friction mu", res.values["friction"], res.std["friction"], ""),
    ]
    extra = [
        ("scene", info["scene"]),
        ("first sample - scene start (m)", _fmt(info["initial_position_gap"], 3)),
    ]
    return rows, info, extra


# kind -> (checks and fit, example data, example scene or None)
_FITS = {
    "inertia": (_fit_inertia, _example_inertia, None),
    "restitution": (_fit_restitution, _example_restitution, None),
    "drag": (_fit_drag, _example_drag, None),
    "contact": (_fit_contact, _example_contact, _example_contact_scene),
}


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray | np.generic | float) and not isinstance(x, bool | np.bool_):
        a = np.asarray(x)
        if a.dtype.kind in "fc":
            if a.ndim == 0:
                v = float(a)
                return v if np.isfinite(v) else str(v)
            return [_jsonable(v) for v in a]
        return a.tolist()
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _fit_report(res, rows, extra, data_path, results_path, notes) -> str:
    """The printed summary: parameter table, diagnostics, then warnings."""
    params = [
        (
            name,
            _fmt(v, 10),
            "fixed" if float(s) == 0 else _fmt(s, 3),
            unit,
        )
        for name, v, s, unit in rows
    ]
    r = np.asarray(res.residuals)
    diag = [
        ("data", str(data_path)),
        (
            "converged",
            f"{'yes' if res.converged else 'NO'} ({res.message}; {res.num_steps} steps, "
            f"{res.num_rejected} rejected)",
        ),
        ("residuals (n, dof)", f"{r.size}, {res.dof}"),
        ("residual norm |r|", _fmt(np.linalg.norm(r), 4)),
        ("rms residual", _fmt(np.sqrt(np.mean(r**2)), 4)),
        ("condition number", _fmt(res.condition_number, 3)),
        *extra,
        ("results", str(results_path)),
    ]
    text = _table(params, header=("parameter", "value", "std error", "unit"))
    text += "\n\n" + _table(diag, header=("fit", "value"), right=False)
    if notes:
        text += "\n\n" + "\n".join(f"warning: {w}" for w in notes)
    return text


def cmd_fit(args) -> int:
    """`jaxrb fit KIND`: every failure is one line on stderr, never a traceback: exit status
    2 for a bad data file, scene, option or output path; 1 for a fit that fails or does not
    converge (or an unexpected error); 130 when interrupted."""
    import warnings

    name = " ".join(filter(None, ("jaxrb fit", args.fit_kind)))

    def one_line_warning(message, category, filename, lineno, file=None, line=None):
        print(f"{name}: warning: {one_line(message)}", file=sys.stderr)

    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.showwarning = one_line_warning
            return _cmd_fit(args, name)
    except CLIError as e:
        print(f"{name}: error: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted; nothing written", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"{name}: error: out of memory; nothing written", file=sys.stderr)
        return 1
    except Exception as e:  # noqa: BLE001 - a failed fit or a bug: still one line
        print(
            f"{name}: error: the fit failed: {type(e).__name__}: {one_line(e)}; nothing written",
            file=sys.stderr,
        )
        return 1


def _write_example(kind: str, path: Path, force: bool) -> int:
    """`--write-example FILE`: the example data (and scene) files, written together."""
    _, example_fn, scene_fn = _FITS[kind]
    files = [path]
    if scene_fn is not None:
        files.append(path.with_suffix(".toml"))
        if files[1] == path:
            raise CLIError(f"--write-example {path}: give a .csv or .npz data file name")
    existing = [f for f in files if f.exists()]
    if existing and not force:
        raise CLIError(
            f"output already exists: {existing[0]}; use --force to overwrite, or give another FILE"
        )
    columns, comment, hint = example_fn()
    with StagedOutput(path.parent, [f.name for f in files], force) as staged:
        _write_columns(staged.path / path.name, columns, comment)
        if scene_fn is not None:
            (staged.path / files[1].name).write_text(scene_fn(), encoding="utf-8")
            hint = f"--scene {files[1]} {hint}"
        staged.commit()
    print("\n".join(f"# {line}" for line in comment.splitlines()))
    written = " and ".join(str(f) for f in files)
    print(f"wrote {written}; try: jaxrb fit {kind} {path} {hint}".rstrip())
    return 0


def _cmd_fit(args, name: str) -> int:
    import warnings

    kind = args.fit_kind
    if kind is None:
        raise CLIError(f"say what to fit: jaxrb fit {{{','.join(_FITS)}}} DATA (see --help)")
    if args.write_example is not None:
        if args.data is not None:
            raise CLIError("--write-example writes an example data file: give no DATA with it")
        return _write_example(kind, Path(args.write_example), args.force)
    if args.data is None:
        raise CLIError(
            f"give a DATA file (CSV or .npz), or create one with "
            f"`jaxrb fit {kind} --write-example FILE`; see jaxrb fit {kind} --help"
        )
    data = _read_data(Path(args.data))
    outdir = Path(args.output)
    results_name = f"fit_{kind}.json"
    prepare = _FITS[kind][0]
    run_fit, describe = prepare(data, args)  # all data and option checks
    check_output(outdir, [results_name], args.force)  # before the (slow) fit
    import jaxrb.fit

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = run_fit()
        except ValueError as e:  # the library's own checks of the data
            raise CLIError(f"{data.path}: {e}") from None
    rows, info, extra = describe(res)
    values = {k: res.values[k] for k in res.names} | info.pop("values", {})
    notes = list(res.warnings)
    fit_warnings = (jaxrb.fit.IdentifiabilityWarning, jaxrb.fit.ConvergenceWarning)
    for w in caught:  # identifiability / convergence warnings go into the table
        if issubclass(w.category, fit_warnings):
            if str(w.message) not in notes:
                notes.append(str(w.message))
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    notes = [n.replace("use fix_scale=True", "use --fix-scale") for n in notes]
    report = {
        "kind": kind,
        "data": str(data.path),
        "names": list(res.names),
        "values": values,
        "std": {k: res.std[k] for k in res.names},
        "converged": bool(res.converged),
        "reason": res.reason,
        "message": res.message,
        "num_steps": int(res.num_steps),
        "num_rejected": int(res.num_rejected),
        "num_invalid": int(res.num_invalid),
        "max_steps": int(args.max_steps),
        "residual_norm": float(np.linalg.norm(res.residuals)),
        "residual_rms": float(np.sqrt(np.mean(np.asarray(res.residuals) ** 2))),
        "num_residuals": int(np.size(res.residuals)),
        "dof": int(res.dof),
        "sigma2": float(res.sigma2),
        "condition_number": float(res.condition_number),
        "covariance": res.covariance,
        "warnings": notes,
        **info,
    }
    path = outdir / results_name
    with StagedOutput(outdir, [results_name], args.force) as staged:
        text = json.dumps(_jsonable(report), indent=2) + "\n"
        (staged.path / results_name).write_text(text, encoding="utf-8")
        staged.commit()
    print(_fit_report(res, rows, extra, data.path, path, notes))
    if not res.converged:
        hint = "; raise --max-steps" if res.reason == "max_steps" else ""
        print(
            f"{name}: error: the fit did not converge: {res.message} ({res.num_steps} steps, "
            f"{res.num_rejected} rejected){hint}; results in {path}",
            file=sys.stderr,
        )
        return 1
    return 0


# ---------------------------------------------------------------------------------------------
# parser


def add_fit_parser(sub):
    """Add the `fit` command and its kinds to the subparsers `sub` of the `jaxrb` parser."""
    fit = sub.add_parser(
        "fit",
        help="fit inertia, restitution, drag or contact to measured motion (CSV or .npz data)",
        description="Fit physical parameters to measured motion by least squares through "
        "the model, with standard errors and identifiability warnings.",
        epilog=_EPILOG_FIT,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    kinds = fit.add_subparsers(dest="fit_kind", metavar="KIND")
    fit.set_defaults(func=cmd_fit, fit_kind=None)

    def fit_parser(kind, help, description, epilog, example, max_steps=100):
        p = kinds.add_parser(
            kind,
            help=help,
            description=description,
            epilog=epilog,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        p.add_argument(
            "data", nargs="?", default=None, metavar="DATA", help="data file: .csv or .npz"
        )
        add_output_options(p)
        add_cache_option(p)
        p.add_argument(
            "--write-example",
            metavar="FILE",
            default=None,
            help=f"write an example data file (.csv or .npz) from {example} and exit",
        )
        p.add_argument(
            "--max-steps",
            type=int,
            default=max_steps,
            metavar="N",
            help="budget of Levenberg-Marquardt trial steps, accepted and rejected "
            f"(default {max_steps})",
        )
        p.set_defaults(func=cmd_fit)
        return p

    def tolerance_options(p, default):
        p.add_argument(
            "--rtol",
            type=float,
            default=default,
            metavar="RTOL",
            help=f"relative tolerance of the model's adaptive integrator (default {default:g})",
        )
        p.add_argument(
            "--atol",
            type=float,
            default=None,
            metavar="ATOL",
            help="absolute tolerance of the model's adaptive integrator (default: --rtol)",
        )

    def sim_options(p):
        tolerance_options(p, 1e-11)
        p.add_argument(
            "--dt",
            type=float,
            default=None,
            metavar="DT",
            help="integrate the model with fixed steps DT (s) instead (Tsit5; --rtol and "
            "--atol then unused)",
        )
        p.add_argument(
            "--no-fit-initial",
            action="store_true",
            help="hold the initial state at the first sample instead of fitting it",
        )

    fi = fit_parser(
        "inertia",
        "inertia tensor from body angular velocity and/or attitude samples",
        "Fit the full inertia tensor (products of inertia included) of a tumbling body to "
        "samples of its body-frame angular velocity and/or attitude.",
        _EPILOG_FIT_INERTIA,
        "a body tumbling under a known torque",
    )
    fi.add_argument(
        "--inertia0",
        metavar="J",
        help="initial guess (kg m^2, body axes): Jxx,Jyy,Jzz or 9 entries row by row (required)",
    )
    fi.add_argument(
        "--omega0",
        metavar="WX,WY,WZ",
        help="initial body angular velocity guess (rad/s); default the first sample "
        "(required without wx, wy, wz columns)",
    )
    fi.add_argument(
        "--fix-scale",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="hold trace(J) = trace(--inertia0) (default: on without torque columns)",
    )
    fi.add_argument(
        "--omega-noise",
        type=float,
        default=1.0,
        metavar="S",
        help="relative noise level of wx, wy, wz (rad/s), weighting them against the "
        "attitude (default 1)",
    )
    fi.add_argument(
        "--quat-noise",
        type=float,
        default=1.0,
        metavar="S",
        help="relative noise level of the attitude (rad) (default 1)",
    )
    sim_options(fi)

    fr = fit_parser(
        "restitution",
        "coefficient of restitution from bounce times and/or apex heights",
        "Fit Newton's coefficient of restitution (and the drop height) to the bounces of a "
        "ball dropped from rest onto a floor.",
        _EPILOG_FIT_RESTITUTION,
        "a ball dropped from rest",
        max_steps=200,
    )
    fr.add_argument("--h0", type=float, default=None, help="known drop height (m); else fitted")
    fr.add_argument(
        "--h0-guess", type=float, default=None, help="initial guess of the drop height (m)"
    )
    fr.add_argument(
        "--restitution0",
        type=float,
        default=0.5,
        metavar="E",
        help="initial guess in (0, 1) (default 0.5)",
    )
    fr.add_argument(
        "--radius",
        type=float,
        default=0.0,
        metavar="R",
        help="ball radius (m): apex heights and --h0 are then those of its centre (default 0)",
    )
    fr.add_argument("--g", type=float, default=9.81, help="gravity (m/s^2, default 9.81)")
    fr.add_argument(
        "--time-noise",
        type=float,
        default=1.0,
        metavar="S",
        help="relative noise level of the impact times (s), when both columns are given",
    )
    fr.add_argument(
        "--height-noise",
        type=float,
        default=1.0,
        metavar="S",
        help="relative noise level of the apex heights (m), when both columns are given",
    )

    fd = fit_parser(
        "drag",
        "drag coefficient from a tracked flight (positions over time)",
        "Fit a quadratic (or linear) drag coefficient to the tracked mass-centre positions of "
        "a body flying under gravity.",
        _EPILOG_FIT_DRAG,
        "a thrown tennis ball",
    )
    fd.add_argument("--mass", type=float, default=None, help="body mass (kg, required)")
    fd.add_argument(
        "--drag0",
        type=float,
        default=None,
        metavar="K",
        help="initial guess of the drag coefficient (required)",
    )
    fd.add_argument(
        "--model",
        choices=("quadratic", "linear"),
        default="quadratic",
        help="F = -k |v| v (default) or F = -c v",
    )
    fd.add_argument("--g", type=float, default=9.81, help="gravity (m/s^2, default 9.81)")
    sim_options(fd)

    fc = fit_parser(
        "contact",
        "restitution and friction from a tracked trajectory with bounces",
        "Fit the floor's coefficient of restitution and Coulomb friction coefficient to the "
        "tracked positions (and optionally gyro data) of a body bouncing on it, through the "
        "simulation with impacts.",
        _EPILOG_FIT_CONTACT,
        "a ball thrown with backspin (with its scene file)",
    )
    fc.add_argument(
        "--scene",
        metavar="SCENE",
        help="scene file (TOML) or a shipped example's name: the body and its shape, the "
        "forces, the floor and the state at the first sample time (required)",
    )
    fc.add_argument(
        "--restitution0",
        type=float,
        default=None,
        metavar="E",
        help="initial guess in (0, 1) (default: the scene's [floor].restitution)",
    )
    fc.add_argument(
        "--friction0",
        type=float,
        default=None,
        metavar="MU",
        help="initial guess > 0 (default: the scene's [floor].friction); with "
        "--fix-friction, the value held",
    )
    fc.add_argument(
        "--fix-friction",
        action="store_true",
        help="fit the restitution only; hold the friction (at --friction0 or the scene's)",
    )
    fc.add_argument(
        "--omega-weight",
        type=float,
        default=0.01,
        metavar="W",
        help="weight of the wx, wy, wz residuals against the positions (m per rad/s; "
        "default 0.01: a gyro error of 1 rad/s counts as a position error of 1 cm)",
    )
    fc.add_argument(
        "--max-impacts",
        type=int,
        default=16,
        metavar="K",
        help="most impacts the model may have (default 16)",
    )
    tolerance_options(fc, 1e-10)
