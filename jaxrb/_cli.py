"""The `jaxrb` command line: run a scene file, sweep a parameter grid, fit, benchmark.

    jaxrb run [SCENE]                 simulate, write trajectory (npz, CSV), plots, summary
    jaxrb run --list                  the example scenes shipped with jaxrb
    jaxrb sweep [SCENE] -p PATH=SPEC ...   a batch over a parameter grid -> results CSV
    jaxrb fit KIND DATA ...           fit inertia, restitution or drag to measured motion
    jaxrb bench [ARGS...]             the benchmark report (source checkout only)

This file holds `run`, `sweep` and `bench`, the argument parser and `main` (the console script
entry point). `jaxrb fit` lives in `_cli_fit.py`; the helpers both use in `_cli_common.py`.
SCENE is a scene file (TOML) or the name of a shipped example (`_scene_examples.py`); with
none, the default scene is used (the die: thrown with spin onto a table).
Outputs go to `jaxrb-output/` (change with `-o`); existing files are never overwritten unless
`--force` is given. User errors exit with status 2, a failed simulation or a fit that does not
converge with 1. `run` and `sweep` write atomically (`StagedOutput`: all their files appear
together, or none) and report every failure, an unexpected one included (status 1), as one
line on stderr, never a traceback. The command line computes in float64 (it enables
`jax_enable_x64`).
"""

from __future__ import annotations

import argparse
import atexit
import copy
import csv
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from ._cli_common import (
    CLIError,
    StagedOutput,
    _fmt,
    _table,
    add_cache_option,
    add_output_options,
    one_line,
)
from ._cli_fit import add_fit_parser
from ._compilation import speed_up_compilation
from ._compile_notice import CompileNotice
from ._plot_preload import PlotPreload
from ._run_files import run_outputs

MAX_SWEEP_RUNS = 100_000
"""The most grid points (runs) one `jaxrb sweep` may have."""

_EPILOG_RUN = """\
examples (SCENE may name one; an existing file of that name takes precedence):
  die, coin, pendulum, heavy_top, ball_in_bowl, thick_coin, roulette
                                     list them: jaxrb run --list; print one: jaxrb run NAME --show

outputs (in OUTPUT):
  trajectory.npz     arrays t, pos, quat, vel, omega, energy, impact_times, impact_energy_lost;
                     with a joint also reaction (T, 3), reaction_magnitude, and for a hinge
                     joint_angle, reaction_normal, reaction_tangential, reaction_axial
  trajectory.csv     one row per save time: t, x, y, z, e0..e3, vx, vy, vz, wx, wy, wz, energy;
                     with a joint also [theta,] Ox, Oy, Oz, [On, Ot, Oa,] Omag
  scene.toml         the scene that was run (the file, with t_end changed by --t-end)
  height_attitude.png, angular_velocity.png, energy.png (energy, physical losses, and the
                     solver's drift on its own axes), reaction.png (a scene with a joint)
  animation.gif      with --animate (fixed camera, the floor in view)
  summary.txt        the printed summary table
the files appear together once all are written (a failed run writes none); existing ones
are replaced only with --force.

exit status: 0 done; 2 bad input (scene file, option, output path: one line names it);
1 the simulation failed (solver failure, or a value that overflowed: nothing written).

frames: pos/vel world frame (z up); omega body frame; quat scalar first, body -> world.
joint reaction O (N): the force the joint exerts on the body, world frame; for a hinge, theta
(rad) is its angle about the axis (0 at the start), On its component along the line from the
mass centre to the axis (positive towards the axis), Ot across it (positive against
increasing theta), Oa along the axis. A pendulum released from rest with its mass centre
level with a horizontal axis gets the closed forms On = m g (1 + 2 rbar^2/k_O^2) sin(theta),
Ot = m g (1 - rbar^2/k_O^2) cos(theta) in reaction.png (example: pendulum).
the scene file format is documented in the default scene: jaxrb run --show-default
"""

_EPILOG_SWEEP = f"""\
grid parameters (-p/--param, repeatable; the grid is their Cartesian product):
  PATH=START:STOP:NUM   NUM evenly spaced values (inclusive), e.g. floor.restitution=0.2:0.8:4
  PATH=V1,V2,...        explicit values, e.g. body.mass=0.004,0.005
random parameters (-r/--random, repeatable; --draws N runs per grid point, --seed S):
  PATH=LOW:HIGH         uniform in [LOW, HIGH], e.g. initial.omega.0=-40:40
  --random-attitude     the initial attitude uniform over all rotations (columns quat0-3)
PATH is a dotted path into the scene file: body.mass, floor.friction, initial.omega.2,
forces.1.coefficient (the second [[forces]] table), simulation.t_end, ...
The same draws (from the seed) are used at every grid point.

output: OUTPUT/sweep.csv, one row per run: the parameters, the solver result,
final position and speed, |omega|, energies, max height, impacts, solver steps, and how the
body ends up: the body axis nearest the world's up (up_axis: a coin on a face shows +z or
-z), its tilt from the vertical (tilt_deg) and, for a die (type = "die"), the number on top
(face_up). Every grid
point is checked before the first run; a run whose solver fails or whose motion overflows
is a row with a failed result. At most {MAX_SWEEP_RUNS} grid points.

exit status: 0 done; 2 bad input (scene file, --param, output path: one line names it).
"""


# ---------------------------------------------------------------------------------------------
# helpers


def _scene_path(scene_arg) -> Path:
    """The scene file a SCENE argument names (a file, or a shipped example's name)."""
    from ._scene_examples import EXAMPLES, scene_path

    path = scene_path(scene_arg)
    if not path.exists():
        raise CLIError(
            f"{path}: no such scene file, nor a shipped example ({', '.join(EXAMPLES)}; "
            "see jaxrb run --list)"
        )
    return path


def _load(scene_arg):
    from ._scene_file import load_scene

    path = _scene_path(scene_arg)
    return load_scene(path), path


def _show(args) -> int:
    """`jaxrb run [SCENE] --show` / `--show-default`: print the scene file."""
    from ._scene_file import read_scene_text

    path = _scene_path(None if args.show_default else args.scene)
    print(read_scene_text(path), end="")
    return 0


def _list_examples() -> int:
    from ._scene_examples import example_titles

    print(_table(example_titles(), header=("name", "title"), right=False))
    print("\nrun one: jaxrb run NAME; print its scene file: jaxrb run NAME --show")
    return 0


# result codes of `jaxrb.RESULTS` that report bad input (exit status 2), not a failed solve
_INPUT_RESULTS = (
    "invalid_mass",
    "invalid_inertia",
    "nonfinite_state",
    "zero_quaternion",
    "decreasing_times",
    "nonfinite_times",
    "invalid_shape",
    "invalid_force",
    "invalid_joint",
    "invalid_floor_height",
    "invalid_floor_normal",
    "invalid_resistance",
    "invalid_surface",
    "invalid_tolerances",
    "invalid_restitution",
    "invalid_friction",
    "starts_below_floor",
)


def _simulate_checked(spec, progress=False):
    """`_simulate` with `throw=False`; bad input the library finds, as a `ValueError` or as
    one of its input result codes, becomes a CLIError naming the scene."""
    import jaxrb

    try:
        traj = _simulate(spec, progress=progress, throw=False)
    except ValueError as e:
        raise CLIError(f"{spec.source}: {one_line(e)}") from None
    for name in _INPUT_RESULTS:
        code = getattr(jaxrb.RESULTS, name, None)
        if code is not None and bool(np.all(np.asarray(traj.result == code))):
            raise CLIError(f"{spec.source}: {_result_name(traj.result)}")
    return traj


def _nonfinite(ts, arrays: dict) -> str | None:
    """The earliest non-finite value among `arrays` (one leading index per save time `ts`,
    s), described, or None when all are finite."""
    first = None
    for key, values in arrays.items():
        values = np.asarray(values, dtype=float).reshape(len(ts), -1)
        bad = ~np.all(np.isfinite(values), axis=1)
        if bad.any() and (first is None or np.argmax(bad) < first[0]):
            k = int(np.argmax(bad))
            first = (k, key, values[k][~np.isfinite(values[k])][0])
    if first is None:
        return None
    k, key, value = first
    return f"{key} became {value} at t = {float(ts[k]):.6g} s"


def _simulate(spec, progress=False, throw=True):
    import diffrax as dfx

    import jaxrb

    from ._scene_file import make_solver

    kwargs = dict(
        solver=make_solver(spec.options["solver"]),
        rtol=spec.options["rtol"],
        atol=spec.options["atol"],
        max_steps=spec.options["max_steps"],
        throw=throw,
    )
    if spec.scene.floor is not None:
        kwargs["max_impacts"] = spec.options["max_impacts"]
    if progress and spec.scene.floor is None:
        kwargs["progress_meter"] = dfx.TqdmProgressMeter()
    return jaxrb.simulate(spec.scene, spec.state0, spec.ts, **kwargs)


def _metrics(traj, scene) -> dict:
    """Scalar summary metrics of one unbatched trajectory."""
    from ._host import energy as host_energy
    from .plotting import impact_summary as impact_records

    s = traj.states
    energy = np.asarray(host_energy(scene, s), dtype=float)
    impacts = impact_records(traj, scene)
    lost_impacts = float(np.nansum(impacts["energy_lost"])) if impacts["times"].size else 0.0
    pos = np.asarray(s.pos, dtype=float)
    return {
        "result": _result_name(traj.result),
        "final_x": pos[-1, 0],
        "final_y": pos[-1, 1],
        "final_z": pos[-1, 2],
        "max_height": float(pos[:, 2].max()),
        "final_speed": float(np.linalg.norm(np.asarray(s.vel)[-1])),
        "final_omega": float(np.linalg.norm(np.asarray(s.omega)[-1])),
        "energy_start": energy[0],
        "energy_end": energy[-1],
        "energy_lost": energy[0] - energy[-1],
        "energy_lost_impacts": lost_impacts,
        "impacts": int(impacts["times"].size),
        "steps": int(np.sum(np.asarray(traj.num_steps))),
        "quat_norm_drift": float(np.max(np.asarray(traj.quat_norm_drift))),
    }


def _printable(name) -> str:
    """A file name from the command line as printable text (bytes that are not UTF-8, kept
    by Python as lone surrogates, shown as U+FFFD)."""
    return str(name).encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def _result_name(result) -> str:
    import jaxrb

    codes = np.asarray(result._value if hasattr(result, "_value") else result).reshape(-1)
    success = int(np.asarray(jaxrb.RESULTS.successful._value))
    failed = codes[codes != success]
    if failed.size == 0:
        return "successful"
    code = int(failed[0])  # a batch reports its first failure
    # equinox enumerations are indexed by their items, not by integers; the messages are
    # stored in a list indexed by the integer code
    messages = getattr(jaxrb.RESULTS, "_index_to_message", ())
    if 0 <= code < len(messages) and messages[code]:
        return " ".join(str(messages[code]).split())
    return f"failed (code {code})"


# ---------------------------------------------------------------------------------------------
# run


def _scene_text(path: Path, t_end) -> str:
    """The scene file's text as run: with `[simulation].t_end` set to `--t-end` if given."""
    from ._scene_file import read_scene_text, with_t_end

    text = read_scene_text(path)
    return text if t_end is None else with_t_end(text, t_end, str(path))


def _run_times(spec, t_end) -> np.ndarray:
    """The save times (s) of `jaxrb run --t-end T`: the scene's number of saves up to T."""
    from ._scene_file import check_time_span

    if not math.isfinite(t_end):
        raise CLIError(f"--t-end must be a finite number of seconds, got {t_end}")
    try:
        check_time_span(float(spec.ts[0]), t_end)
    except ValueError as e:
        raise CLIError(f"--t-end {t_end:g}: {e}") from None
    return np.linspace(spec.ts[0], t_end, spec.ts.size)


MAX_TITLE_CHARS = 200
"""The longest scene title `jaxrb run` draws on its plots (characters)."""


def _check_title(spec) -> None:
    """Refuse a title that matplotlib cannot draw (its mathtext, between `$` signs) or that
    is too long for a plot, before the simulation rather than at the first plot."""
    if not spec.title:
        return
    if len(spec.title) > MAX_TITLE_CHARS:
        raise CLIError(
            f"{spec.source}: title: {len(spec.title)} characters: a plot title has at most "
            f"{MAX_TITLE_CHARS} (put the rest in `description`, or use --no-plots)"
        )
    if "$" not in spec.title:  # plain text: no mathtext to parse
        return
    import io

    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.0, 3.0))
    fig.add_subplot().set_title(spec.title)
    try:
        fig.savefig(io.BytesIO(), format="png", dpi=20, bbox_inches="tight")
    except Exception as e:  # mathtext's parse errors, an image too large to make, ...
        lines = [line.strip() for line in str(e).splitlines() if line.strip()]
        reason = lines[-1] if lines else type(e).__name__
        raise CLIError(
            f"{spec.source}: title: matplotlib cannot draw it ({reason}); "
            "write a literal dollar sign as \\\\$ in the TOML string"
        ) from None


def cmd_run(args) -> int:
    spec, path = _load(args.scene)
    if args.t_end is not None:
        spec.ts = _run_times(spec, args.t_end)
    scene_text = _scene_text(path, args.t_end)
    if not args.no_plots or args.animate:
        _check_title(spec)
    label = "built-in default scene" if args.scene is None else _printable(args.scene)
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    with StagedOutput(
        args.output,
        run_outputs(spec.scene, plots=not args.no_plots, animate=args.animate),
        args.force,
    ) as out:
        say(
            f"jaxrb run: {spec.title or label} ({label}); "
            f"integrating t = {spec.ts[0]:g} .. {spec.ts[-1]:g} s ..."
        )
        # matplotlib loads on another thread while XLA loads or compiles the program
        preload = PlotPreload() if not args.no_plots or args.animate else None
        try:
            t0 = time.perf_counter()
            with CompileNotice(say, cached=not args.no_cache):
                traj = _simulate_checked(spec, progress=args.progress)
                traj.ts.block_until_ready()
            wall = time.perf_counter() - t0
        finally:  # nothing else uses matplotlib while that thread does
            if preload is not None:
                preload.wait()
        from ._trajectory_files import file_arrays

        m = _metrics(traj, spec.scene)
        arrays = file_arrays(traj, spec.scene) if m["result"] == "successful" else None
        failure = _run_failure(m, arrays)
        if failure is not None:
            print(f"jaxrb run: simulation failed: {failure}; nothing written", file=sys.stderr)
            return 1
        try:
            written = _write_run(args, spec, traj, arrays, scene_text, out.path, say)
            rows = _run_summary(spec, label, traj, m, arrays, wall)
            listing = ", ".join([*written, "summary.txt"])
            rows.append(("output", f"{_printable(args.output)}/ ({listing})"))
            text = _table(rows, header=("quantity", "value"), right=False)
            (out.path / "summary.txt").write_text(text + "\n", encoding="utf-8")
        except OSError as e:
            raise CLIError(f"{args.output}: cannot write: {e.strerror or e}") from None
        out.commit()
    print(text)
    return 0


def _run_failure(m, arrays) -> str | None:
    """Why a run failed (the solver's result, or a value that overflowed), or None."""
    if m["result"] != "successful":
        return (
            f"{m['result'].rstrip('.')}; try smaller rtol/atol or larger max_steps in [simulation]"
        )
    per_save = {k: v for k, v in arrays.items() if not k.startswith("impact_")}
    problem = _nonfinite(arrays["t"], per_save)
    return None if problem is None else f"{problem} (the motion overflowed)"


def _write_run(args, spec, traj, arrays, scene_text, outdir: Path, say) -> list[str]:
    """Write the files of `jaxrb run` but the summary into `outdir`; returns their names."""
    from ._trajectory_files import write_trajectory

    written = write_trajectory(arrays, outdir)
    (outdir / "scene.toml").write_text(scene_text, encoding="utf-8")
    written.append("scene.toml")
    title = spec.title or None
    if not args.no_plots:
        say("writing plots ...")
        from . import plotting

        written += [p.name for p in plotting.save_run_plots(traj, spec.scene, outdir, title=title)]
    if args.animate:
        say("writing animation.gif ...")
        from . import plotting

        plotting.animate(traj, spec.scene, outdir / "animation.gif", title=title)
        written.append("animation.gif")
    return written


def _run_summary(spec, label, traj, m, arrays, wall) -> list[tuple[str, str]]:
    """The rows of `jaxrb run`'s summary table (without the output list)."""
    body = spec.scene.body
    s = traj.states
    floor = spec.scene.floor
    return [
        ("scene", spec.title or label),
        ("body mass (kg)", _fmt(body.mass)),
        ("shape", type(body.shape).__name__ if body.shape is not None else "none"),
        ("forces", ", ".join(type(f).__name__ for f in spec.scene.forces) or "none"),
        (
            "floor (restitution, friction)",
            "none" if floor is None else f"{float(floor.restitution):g}, {float(floor.friction):g}",
        ),
        ("joint", type(spec.scene.joint).__name__ if spec.scene.joint is not None else "none"),
        ("time span (s)", f"{spec.ts[0]:g} .. {spec.ts[-1]:g} ({spec.ts.size} saves)"),
        (
            "solver, rtol, atol",
            f"{spec.options['solver']}, {spec.options['rtol']:g}, {spec.options['atol']:g}",
        ),
        ("result", m["result"]),
        ("solver steps", m["steps"]),
        ("impacts", m["impacts"]),
        ("energy start / end (J)", f"{_fmt(m['energy_start'])} / {_fmt(m['energy_end'])}"),
        ("energy lost: total, E(0) - E(end) (J)", _fmt(m["energy_lost"])),
        ("energy lost: at impacts (J)", _fmt(m["energy_lost_impacts"])),
        *_drift_rows(traj, spec.scene),
        *_reaction_rows(spec, arrays),
        ("max height of mass centre (m)", _fmt(m["max_height"])),
        ("final position (m, world)", _fmt(np.asarray(s.pos)[-1], 5)),
        ("final velocity (m/s, world)", _fmt(np.asarray(s.vel)[-1], 5)),
        ("final omega (rad/s, body)", _fmt(np.asarray(s.omega)[-1], 5)),
        ("final quaternion (body->world)", _fmt(np.asarray(s.quat)[-1], 5)),
        ("max | |q| - 1 | in solver", _fmt(m["quat_norm_drift"], 3)),
        ("wall time incl. compile (s)", f"{wall:.2f}"),
    ]


def _drift_rows(traj, scene) -> list[tuple[str, str]]:
    """The solver's energy drift, max |E(t) - E(0) - W(t)| (J), where it is separable."""
    from ._energy_budget import energy_budget

    budget = energy_budget(traj, scene)
    if budget["drift"] is None:
        return [("solver energy drift (J)", "not separated (sliding friction with the floor)")]
    rows = [("solver energy drift, max |E - E(0) - W| (J)", _fmt(np.max(np.abs(budget["drift"]))))]
    if budget["nonpotential"]:
        rows.insert(0, ("energy removed by drag etc., -W(end) (J)", _fmt(-budget["work"][-1])))
    return rows


def _reaction_rows(spec, arrays) -> list[tuple[str, str]]:
    """The joint reaction's largest magnitude and, for a released pendulum, its largest
    difference from the closed form (N)."""
    from ._reaction import released_pendulum

    if "reaction" not in arrays:
        return []
    rows = [("joint reaction: max |O| (N)", _fmt(np.max(arrays["reaction_magnitude"])))]
    release = released_pendulum(spec.scene, spec.state0)
    if release is not None:
        on, ot = release.reaction(arrays["joint_angle"])
        error = max(
            np.max(np.abs(arrays["reaction_normal"] - on)),
            np.max(np.abs(arrays["reaction_tangential"] - ot)),
        )
        rows.append(("joint reaction: max |O_n, O_t - closed form| (N)", _fmt(error, 3)))
    return rows


# ---------------------------------------------------------------------------------------------
# sweep


def _grid_number(where: str, text: str) -> float:
    """One number of a --param grid; a CLIError unless it is a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise CLIError(f"{where}: {text.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise CLIError(f"{where}: {text.strip()!r} is not a finite number")
    return value


def _parse_param(text: str):
    """PATH and its values from `-p PATH=START:STOP:NUM` or `-p PATH=V1,V2,...`."""
    if "=" not in text:
        raise CLIError(f"--param {text!r}: expected PATH=START:STOP:NUM or PATH=V1,V2,...")
    name, spec = (x.strip() for x in text.split("=", 1))
    where = f"--param {text!r}"
    if not name:
        raise CLIError(f"{where}: empty PATH")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 3:
            raise CLIError(f"{where}: expected START:STOP:NUM (three parts), got {spec!r}")
        start, stop = (_grid_number(where, p) for p in parts[:2])
        try:
            num = int(parts[2])
        except ValueError:
            num = 0
        if num < 1:
            raise CLIError(f"{where}: NUM must be an integer >= 1, got {parts[2].strip()!r}")
        if num > MAX_SWEEP_RUNS:
            raise CLIError(f"{where}: NUM = {num}: a sweep has at most {MAX_SWEEP_RUNS} runs")
        with np.errstate(all="ignore"):
            values = np.linspace(start, stop, num).tolist()
        if not all(math.isfinite(v) for v in values):
            raise CLIError(f"{where}: STOP - START overflows")
    else:
        values = [_grid_number(where, v) for v in spec.split(",") if v.strip()]
        if not values:
            raise CLIError(f"{where}: no values: expected START:STOP:NUM or V1,V2,...")
    return name, values


def _parse_random(text: str):
    """PATH and (LOW, HIGH) from `-r PATH=LOW:HIGH`."""
    where = f"--random {text!r}"
    if "=" not in text:
        raise CLIError(f"{where}: expected PATH=LOW:HIGH")
    name, spec = (x.strip() for x in text.split("=", 1))
    if not name:
        raise CLIError(f"{where}: empty PATH")
    parts = spec.split(":")
    if len(parts) != 2:
        raise CLIError(f"{where}: expected LOW:HIGH (two parts), got {spec!r}")
    low, high = (_grid_number(where, p) for p in parts)
    if not low <= high:
        raise CLIError(f"{where}: LOW must be <= HIGH")
    return name, (low, high)


def _draws(ranges, n: int, attitude: bool, seed: int) -> list[tuple]:
    """`n` random draws (the same for every grid point): per draw, one value per range,
    uniform in [LOW, HIGH], then with `attitude` a unit quaternion uniform on the sphere
    of rotations (a normalised 4-vector of standard normals)."""
    rng = np.random.default_rng(seed)
    values = [rng.uniform(low, high, n) for _, (low, high) in ranges]
    if attitude:
        q = rng.standard_normal((n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        values += [q[:, k] for k in range(4)]
    return [tuple(float(v[i]) for v in values) for i in range(n)]


def _set_path(data: dict, dotted: str, value):
    """Set `value` at a dotted path (e.g. "forces.1.coefficient") in a deep-copied TOML dict."""
    keys = dotted.split(".")
    node = data
    for i, key in enumerate(keys):
        last = i == len(keys) - 1
        where = ".".join(keys[: i + 1])
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise CLIError(
                    f"--param {dotted}: {where}: index out of range (list of {len(node)})"
                )
            key = int(key)
        elif isinstance(node, dict):
            if not last and key not in node:
                raise CLIError(f"--param {dotted}: {where}: no such table in the scene file")
        else:
            raise CLIError(
                f"--param {dotted}: {'.'.join(keys[:i])} is a value, not a table or list"
            )
        if last:
            old = node[key] if (isinstance(node, list) or key in node) else None
            if isinstance(old, dict | list):
                raise CLIError(f"--param {dotted}: {where} is a table or list, not a number")
            node[key] = (
                int(value)
                if isinstance(old, int) and not isinstance(old, bool) and value == int(value)
                else value
            )
        else:
            node = node[key]


def cmd_sweep(args) -> int:
    import itertools

    from tqdm.auto import tqdm

    from ._scene_file import parse_scene

    base, path = _load(args.scene)
    randomised = bool(args.random) or args.random_attitude
    if not args.param and not randomised:
        raise CLIError(
            "sweep needs at least one -p/--param PATH=SPEC or -r/--random PATH=LOW:HIGH "
            "(see jaxrb sweep --help)"
        )
    if args.draws is not None and not randomised:
        raise CLIError("--draws needs a random parameter (-r PATH=LOW:HIGH or --random-attitude)")
    draws = 1 if args.draws is None else args.draws
    if draws < 1:
        raise CLIError(f"--draws must be >= 1, got {draws}")
    params = [_parse_param(p) for p in args.param]
    ranges = [_parse_random(r) for r in args.random]
    grid_names = [n for n, _ in params]
    names = grid_names + [n for n, _ in ranges]
    if len(set(grid_names)) != len(grid_names):
        raise CLIError("each --param PATH may be given once")
    if len(set(names)) != len(names):
        raise CLIError("each PATH may be given once (in --param or --random)")
    points = math.prod(len(v) for _, v in params)
    runs = points * draws
    if runs > MAX_SWEEP_RUNS:
        size = f"{points} points" + (f" x {draws} draws" if randomised else "")
        raise CLIError(f"the grid has {size}: a sweep has at most {MAX_SWEEP_RUNS} runs")
    grid = [
        point + draw
        for point in itertools.product(*[v for _, v in params])
        for draw in _draws(ranges, draws, args.random_attitude, args.seed)
    ]
    if args.random_attitude:
        names = names + ["quat0", "quat1", "quat2", "quat3"]
    # validate every run first: a bad value fails before any simulation runs
    specs = []
    for point in grid:
        data = copy.deepcopy(base.data)
        values = dict(zip(names, point, strict=True))
        for name in names[: len(params) + len(ranges)]:
            _set_path(data, name, values[name])
        if args.random_attitude:
            initial = data.setdefault("initial", {})
            for key in ("quat", "axis", "angle_deg", "euler_deg", "sequence"):
                initial.pop(key, None)
            initial["quat"] = [values[f"quat{k}"] for k in range(4)]
        where = ", ".join(f"{n}={v:g}" for n, v in values.items())
        specs.append(parse_scene(data, source=f"{path} with {where}"))
    outdir = Path(args.output)
    with StagedOutput(args.output, ["sweep.csv"], args.force) as out:
        rows = []
        t0 = time.perf_counter()
        bar = tqdm(
            specs, desc="jaxrb sweep", unit="run", disable=not args.progress, file=sys.stderr
        )
        for point, spec in zip(grid, bar, strict=True):
            rows.append({**dict(zip(names, point, strict=True)), **_sweep_metrics(spec)})
        wall = time.perf_counter() - t0
        try:
            _write_sweep(rows, out.path / "sweep.csv")
        except OSError as e:
            raise CLIError(f"{outdir}: cannot write: {e.strerror or e}") from None
        out.commit()
    show = names + ["result", "final_z", "final_speed", "energy_lost", "impacts", "steps"]
    body = [
        [_fmt(r[k], 5) if not isinstance(r[k], str) else r[k] for k in show]
        for r in rows[: args.show]
    ]
    print(_table(body, header=show))
    if len(rows) > args.show:
        print(f"... {len(rows) - args.show} more rows in {_printable(outdir / 'sweep.csv')}")
    failed = sum(r["result"] != "successful" for r in rows)
    results = _printable(outdir / "sweep.csv")
    print(f"{len(rows)} runs in {wall:.2f} s ({failed} failed); results: {results}")
    return 0


def _final_attitude_metrics(spec, traj) -> dict:
    """How the body ends up: `up_axis`, the body axis (+x ... -z) nearest the world's up;
    `tilt_deg`, the angle between them; `face_up`, the number a die (`type = "die"`) shows
    (empty for other shapes)."""
    import jaxrb

    quat = np.asarray(traj.states.quat, dtype=float)[-1]
    up = np.asarray(jaxrb.quat_to_matrix(jaxrb.quat_normalize(quat)))[2]  # world up, body frame
    k = int(np.argmax(np.abs(up)))
    face = ""
    shape = spec.data.get("body", {}).get("shape", {})
    if isinstance(shape, dict) and shape.get("type") == "die":
        build = jaxrb.dice.BUILDERS[shape["sides"]]
        die = build(shape["edge"]) if "edge" in shape else build()
        face = int(die.outcome(quat))
    return {
        "up_axis": ("+" if up[k] > 0 else "-") + "xyz"[k],
        "tilt_deg": float(np.degrees(np.arccos(min(abs(up[k]), 1.0)))),
        "face_up": face,
    }


def _sweep_metrics(spec) -> dict:
    """`_metrics` of one grid point's run, and how the body ends up
    (`_final_attitude_metrics`); a motion that overflowed is a failed result."""
    import jaxrb

    traj = _simulate_checked(spec)
    metrics = _metrics(traj, spec.scene) | _final_attitude_metrics(spec, traj)
    if metrics["result"] == "successful":
        s = traj.states
        energy = jaxrb.energy(spec.scene, s)
        arrays = {"pos": s.pos, "quat": s.quat, "vel": s.vel, "omega": s.omega, "energy": energy}
        problem = _nonfinite(np.asarray(traj.ts), arrays)
        if problem is not None:
            metrics["result"] = f"failed: {problem}"
    return metrics


def _write_sweep(rows: list[dict], path: Path) -> None:
    """`sweep.csv`: a header of the row keys, then one line per run."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow(
                {
                    k: (f"{v:.10g}" if isinstance(v, float | np.floating) else v)
                    for k, v in r.items()
                }
            )


# ---------------------------------------------------------------------------------------------
# bench


def _benchmarks_dir() -> Path | None:
    here = Path(__file__).resolve().parent.parent / "benchmarks"
    for d in (Path.cwd() / "benchmarks", here):
        if d.is_dir() and any(d.glob("*.py")):
            return d
    return None


def cmd_bench(args) -> int:
    import subprocess

    d = _benchmarks_dir()
    if d is None:
        raise CLIError("benchmarks/ not found: `jaxrb bench` runs from a source checkout of jaxrb")
    if not (d / "run_all.py").exists():
        raise CLIError(f"no benchmark report script in {d} (expected run_all.py)")
    # a fresh process: the benchmarks package sets up one JAX host device per CPU core, which
    # only takes effect before JAX starts (this process has started it already)
    bench_args = list(args.bench_args)
    if bench_args[:1] == ["--"]:  # `jaxrb bench -- --help`
        bench_args = bench_args[1:]
    cmd = [sys.executable, "-m", f"{d.name}.run_all", *bench_args]
    return subprocess.run(cmd, cwd=d.parent).returncode


# ---------------------------------------------------------------------------------------------
# parser


def _add_common(p, output=True):
    p.add_argument(
        "scene",
        nargs="?",
        default=None,
        metavar="SCENE",
        help="a scene file (SCENE.toml) or the name of a shipped example (die, coin, pendulum, "
        "heavy_top, ball_in_bowl, thick_coin, roulette; see jaxrb run --list); default: die, "
        "thrown onto a table",
    )
    if output:
        add_output_options(p)
    add_cache_option(p)
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=sys.stderr.isatty(),
        help="show progress bars (default: on when stderr is a terminal)",
    )


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (no usage block), status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    import jaxrb

    parser = _Parser(
        prog="jaxrb",
        description="jaxrb: JAX-accelerated, differentiable rigid-body dynamics. "
        "Simulate a scene file, sweep parameters, fit parameters to data, benchmark.",
        epilog="run `jaxrb COMMAND --help` for each command's options. "
        "Frames: pos/vel world (z up), omega body, quaternions scalar first body->world.",
    )
    parser.add_argument("--version", action="version", version=f"jaxrb {jaxrb.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    run = sub.add_parser(
        "run",
        help="simulate a scene file: trajectory (npz, CSV), plots, summary table",
        description="Simulate one scene and write its trajectory, plots and a summary table.",
        epilog=_EPILOG_RUN,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_common(run)
    run.add_argument(
        "--t-end", type=float, default=None, metavar="T", help="override [simulation].t_end (s)"
    )
    run.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    run.add_argument(
        "--animate", action="store_true", help="also write a 3D animation (animation.gif)"
    )
    run.add_argument("-q", "--quiet", action="store_true", help="print only the summary table")
    run.add_argument(
        "--list", action="store_true", help="list the example scenes shipped with jaxrb and exit"
    )
    run.add_argument(
        "--show",
        action="store_true",
        help="print the scene file (SCENE, default the die) and exit: copy an example to edit it",
    )
    run.add_argument(
        "--show-default",
        action="store_true",
        help="print the annotated default scene file (the format reference) and exit",
    )
    run.set_defaults(func=cmd_run)

    sweep = sub.add_parser(
        "sweep",
        help="run a batch over a parameter grid and write a results table",
        description="Run the scene once per point of a parameter grid (Cartesian product of "
        "the --param values) and write one results row per run.",
        epilog=_EPILOG_SWEEP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_common(sweep)
    sweep.add_argument(
        "-p",
        "--param",
        action="append",
        default=[],
        metavar="PATH=SPEC",
        help="a grid parameter (repeatable), e.g. floor.restitution=0.2:0.8:4",
    )
    sweep.add_argument(
        "-r",
        "--random",
        action="append",
        default=[],
        metavar="PATH=LOW:HIGH",
        help="a parameter drawn uniformly from [LOW, HIGH] for each run (repeatable), "
        "e.g. initial.omega.0=-40:40",
    )
    sweep.add_argument(
        "--random-attitude",
        action="store_true",
        help="draw each run's initial attitude uniformly at random (replaces the scene's)",
    )
    sweep.add_argument(
        "--draws",
        type=int,
        default=None,
        metavar="N",
        help="random runs per grid point (default 1; needs -r or --random-attitude)",
    )
    sweep.add_argument("--seed", type=int, default=0, help="seed of the random draws (default 0)")
    sweep.add_argument(
        "--show", type=int, default=20, metavar="N", help="rows to print (default 20)"
    )
    sweep.set_defaults(func=cmd_sweep)

    add_fit_parser(sub)

    bench = sub.add_parser(
        "bench",
        help="run the benchmark report (from a source checkout)",
        description="Run benchmarks/ (speed against error, against scipy and MuJoCo where "
        "installed). Arguments after `bench` are passed to the report script.",
    )
    bench.add_argument(
        "bench_args", nargs=argparse.REMAINDER, help="arguments for the benchmark report"
    )
    bench.set_defaults(func=cmd_bench)
    return parser


def _run_or_sweep(args) -> int:
    """`jaxrb run` / `jaxrb sweep`: every failure is one line on stderr, never a traceback:
    exit status 2 for bad input (scene file, option, output path), 1 for a failed simulation
    or an unexpected error. Warnings are one line each."""
    import warnings

    from ._scene_file import SceneFileError

    name = args.command

    def one_line_warning(message, category, filename, lineno, file=None, line=None):
        print(f"jaxrb {name}: warning: {one_line(message)}", file=sys.stderr)

    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.showwarning = one_line_warning
            if name == "run" and args.list:
                return _list_examples()
            if name == "run" and (args.show or args.show_default):
                return _show(args)
            import jax

            speed_up_compilation(cache=not args.no_cache, nan_checks=True)
            jax.config.update("jax_enable_x64", True)
            return args.func(args)
    except (CLIError, SceneFileError) as e:
        print(f"jaxrb {name}: error: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"jaxrb {name}: interrupted; nothing written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout closed early (`jaxrb run | head`): the files are written
        print(f"jaxrb {name}: error: standard output closed early", file=sys.stderr)
        return 1
    except MemoryError:
        print(
            f"jaxrb {name}: error: out of memory (fewer saves or grid points may fit); "
            "nothing written",
            file=sys.stderr,
        )
        return 1
    except Exception as e:  # a bug: still one line, and no partial output
        print(
            f"jaxrb {name}: error: unexpected {type(e).__name__}: {one_line(e)} "
            "(please report this); nothing written",
            file=sys.stderr,
        )
        return 1


def _subparsers(parser) -> dict:
    """The parsers of the commands (run, sweep, ...) of `parser`, by name."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def main(argv=None) -> int:
    """Entry point of the `jaxrb` console script (and `python -m jaxrb`); returns the exit code
    (`--help` and `--version` exit through SystemExit, status 0)."""
    parser = build_parser()
    try:
        args, unknown = parser.parse_known_args(argv)
        if args.command == "bench":  # everything after `bench` belongs to the report script
            args.bench_args = [*unknown, *args.bench_args]
        elif unknown:
            command = _subparsers(parser).get(args.command, parser)
            command.error(f"unrecognized arguments: {' '.join(unknown)}")
    except SystemExit as e:
        if not e.code:
            raise
        return e.code
    if args.command is None:
        parser.print_help()
        return 2
    if args.command in ("run", "sweep"):
        return _run_or_sweep(args)
    import jax

    speed_up_compilation(cache=not getattr(args, "no_cache", False), nan_checks=True)
    jax.config.update("jax_enable_x64", True)
    from ._scene_file import SceneFileError

    name = " ".join(filter(None, (args.command, getattr(args, "fit_kind", None))))
    try:
        return args.func(args)
    except (CLIError, SceneFileError) as e:
        print(f"jaxrb {name}: error: {e}", file=sys.stderr)
        return 2


def console_main() -> None:
    """The `jaxrb` console script and `python -m jaxrb`: `main`, then the process ends at once.

    When `main` has returned, every file it wrote is closed. What is left is the interpreter's
    teardown, in which freeing JAX's loaded programs and its client took 0.4-0.5 s of a warm
    `jaxrb run`'s 4.3-4.7 s (a 2-core x86 CPU). So the standard streams are flushed, the
    `atexit` handlers run (logging's flush among them), and the process exits without the
    teardown (`os._exit`), with the status `sys.exit` would give."""
    try:
        code = main()
    except SystemExit as e:  # --help, --version
        code = e.code
    if code is None:
        code = 0
    elif not isinstance(code, int):
        print(code, file=sys.stderr)
        code = 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed early (`jaxrb run | head`): nothing to keep
            pass
    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)  # CPython's
    if run_exit_handlers is None:  # elsewhere: the usual exit, teardown and all
        sys.exit(code)
    run_exit_handlers()
    os._exit(code)


if __name__ == "__main__":
    console_main()
