"""Scene files: a TOML description of a body, its forces, a floor or joint, and the run.

`load_scene(path)` reads a file with `tomllib`, checks every field and returns a
`SceneSpec` (the `Scene`, the initial `State`, the save times and the solver options).
Every mistake raises a `SceneFileError` naming the file, the field and the problem, e.g.
``scene.toml: [body].mass: must be > 0, got -1.0``.

The format is documented, field by field, in the annotated example shipped with the package,
`jaxrb/scenes/default.toml` (`default_scene_path()`). Sections:

- `title`, `description`: optional strings.
- `[body]`: `mass` (kg, required); `inertia` (kg m^2 about the mass centre, body axes: three
  principal moments or a 3x3 tensor; optional when a shape is given); `[body.shape]` with
  `type` = "box" (`half_extents`), "sphere" (`radius`), "cylinder" (`radius`,
  `half_height`), "polyhedron" (`vertices`: the convex hull's points, m) or "die" (`sides`
  4, 6, 8, 12 or 20 and optional `edge`, m: a regular die of `jaxrb.dice`); every shape
  takes an optional `offset` (m, body frame: its centre relative to the mass centre).
- `[initial]`: `pos`, `vel` (world frame, m and m/s), `omega` (BODY frame, rad/s) and the
  attitude as one of `quat` (scalar first, body to world), `axis` + `angle_deg`, or
  `euler_deg` + `sequence` (e.g. "313": R = R_a(phi1) R_b(phi2) R_c(phi3), moving axes).
- `[[forces]]`: tables with `type` = "gravity" (`g`), "linear_drag" (`coefficient`),
  "quadratic_drag" (`coefficient`, or `rho`, `drag_coefficient`, `area`), "damping_moment"
  (`linear`, `quadratic`), "wrench" (`force`, `torque`, `point`, `frame`).
- `[floor]`: `restitution` in [0, 1], `friction` >= 0, `height` (m), and `type`: "plane"
  (the default; optionally `normal`: a tilted plane through (0, 0, height), its normal,
  world frame, default [0, 0, 1]), "bowl" (`radius`, m: the inside of a sphere whose
  lowest point is (0, 0, height)), "cone" (`inclination_deg` in (0, 90): the inside of
  an upright cone with its apex at (0, 0, height); optional `tip_radius`, m, rounds the
  apex) or "wheel" (a roulette wheel's stator: that cone as its track, bounded by a smooth
  vertical wall of radius `wall_radius`, m, about the z axis); a bowl, cone or wheel meets
  only a sphere.
  Optionally `rolling_resistance` and `spin_resistance` >= 0 (a sphere's; see `Floor`).
- `[joint]`: `type` = "pivot" or "hinge", `point` (body frame, m), `axis` (hinge). A joint
  fixes part of the initial motion: `[initial].vel`, if given, must equal the velocity the
  joint gives the mass centre, and a hinge's `omega` must lie along its axis; anything else
  is an error naming the field.
- `[simulation]`: `t_end` (s, required), `t_start`, `num_saves`, `rtol`, `atol`,
  `max_steps`, `solver` ("tsit5", "dopri5", "dopri8"), and for a scene with a floor
  `max_impacts` (default 64; the run may have 4 max_impacts + 16 contact events).

Beyond each field's own checks, a scene is refused when its initial energy overflows, when
the body starts below the floor, and when its saves would make more than `MAX_OUTPUT_BYTES`
of output arrays. The model classes (`RigidBody`, the shapes, forces, joints and `Floor`)
check their own parameters; their `ValueError`s become `SceneFileError`s naming the table.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import sys
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ._scene_examples import example_path

__all__ = [
    "MAX_OUTPUT_BYTES",
    "SceneFileError",
    "SceneSpec",
    "default_scene_path",
    "load_scene",
    "loads_scene",
    "parse_scene",
    "read_scene_text",
    "check_time_span",
    "with_t_end",
]

MAX_SCENE_BYTES = 1_000_000
"""The largest scene file read (bytes); a scene file is a page of TOML."""

MAX_OUTPUT_BYTES = 1e9
"""The most output arrays a scene's saves may make (bytes of float64 in `trajectory.npz`;
the CSV copy is about twice as large, and both are held in memory while written)."""

MAX_STEPS_LIMIT = 10**12
MAX_IMPACTS_LIMIT = 100_000  # the impact record's static size
"""The largest `[simulation].max_steps` accepted."""


class SceneFileError(ValueError):
    """A scene file is invalid; the message names the file, the field and the problem."""


@dataclasses.dataclass
class SceneSpec:
    """A parsed scene file.

    **Fields:**

    - `scene`: the `jaxrb.Scene`.
    - `state0`: the initial `jaxrb.State` (world-frame pos/vel, body-frame omega, quaternion
      scalar first body -> world).
    - `ts`: save times (s), numpy array of shape (num_saves,).
    - `options`: keyword arguments for `jaxrb.simulate` (`rtol`, `atol`, `max_steps`, `solver`).
    - `title`, `description`: strings from the file (may be empty).
    - `data`: the raw TOML dictionary (used by `jaxrb sweep` to override fields).
    - `source`: the file name used in error messages.
    """

    scene: Any
    state0: Any
    ts: np.ndarray
    options: dict
    title: str
    description: str
    data: dict
    source: str


def default_scene_path() -> Path:
    """Path of the annotated default scene shipped with jaxrb (a die thrown onto a table)."""
    return example_path("die")


def read_scene_text(path) -> str:
    """The text of a scene file (UTF-8, a byte-order mark allowed); raises `SceneFileError`
    for a missing, unreadable, binary or oversized (> `MAX_SCENE_BYTES`) file."""
    path = Path(path)
    if path.is_dir():
        raise SceneFileError(f"{path}: is a directory, not a scene file")
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_SCENE_BYTES + 1)
    except FileNotFoundError:
        raise SceneFileError(f"{path}: no such scene file") from None
    except OSError as e:
        raise SceneFileError(f"{path}: cannot read: {e.strerror or e}") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneFileError(
            f"{path}: larger than {MAX_SCENE_BYTES // 1000} kB: not a scene file (TOML text)"
        )
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise SceneFileError(
            f"{path}: not a text file: byte {e.start} is not UTF-8 (a scene file is TOML text)"
        ) from None


def load_scene(path) -> SceneSpec:
    """Read and validate a TOML scene file; raises `SceneFileError` naming field and problem."""
    return loads_scene(read_scene_text(path), source=str(path))


def loads_scene(text: str, source: str = "<scene>") -> SceneSpec:
    """Parse a scene from TOML text (see `load_scene`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{source}: not valid TOML: {e}") from None
    except RecursionError:
        raise SceneFileError(f"{source}: not valid TOML: nested too deeply") from None
    if not data:
        raise SceneFileError(
            f"{source}: empty scene: expected at least [body] and [simulation] "
            "(the format: jaxrb run --show-default)"
        )
    return parse_scene(data, source=source)


# ---------------------------------------------------------------------------------------------
# typed field readers

_MISSING = object()


class _Table:
    """A TOML table with its location (e.g. "[body]") for error messages."""

    def __init__(self, data, where: str, source: str, known: tuple[str, ...]):
        self.source = source
        self.where = where
        if not isinstance(data, dict):
            self.fail(None, f"must be a table, got {_type_name(data)}")
        self.data = data
        for key in data:
            if key not in known:
                close = difflib.get_close_matches(key, known, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                allowed = ", ".join(known)
                self.fail(key, f"unknown field{hint}; allowed here: {allowed}")

    def fail(self, key, problem):
        if key is None:
            field = self.where
        else:
            # a key with a line break or another unprintable character is shown quoted, so
            # that the message stays one line
            key = key if str(key).isprintable() else repr(key)
            field = f"{self.where}.{key}" if self.where else _TOP_NAMES.get(key, key)
        raise SceneFileError(f"{self.source}: {field + ': ' if field else ''}{problem}")

    def model(self, key, make, *args, **kwargs):
        """`make(*args, **kwargs)` (a jaxrb model class); its `ValueError` names `key`."""
        try:
            return make(*args, **kwargs)
        except ValueError as e:
            self.fail(key, " ".join(str(e).split()))

    def has(self, key):
        return key in self.data

    def number(self, key, default=_MISSING, *, positive=False, nonnegative=False, lo=None, hi=None):
        if key not in self.data:
            if default is _MISSING:
                self.fail(key, "missing required field")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(key, f"must be a number, got {_type_name(value)} {_short(value)}")
        if not math.isfinite(_float(value)):
            self.fail(key, f"must be finite, got {_short(value)}")
        value = float(value)
        if positive and value < sys.float_info.min:  # a subnormal number computes as 0
            self.fail(key, f"must be > 0, got {value}")
        if nonnegative and value < 0:
            self.fail(key, f"must be >= 0, got {value}")
        if lo is not None and hi is not None and not lo <= value <= hi:
            self.fail(key, f"must be in [{lo}, {hi}], got {value}")
        return value

    def integer(self, key, default=_MISSING, *, minimum=None, maximum=None):
        if key not in self.data:
            if default is _MISSING:
                self.fail(key, "missing required field")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(key, f"must be an integer, got {_type_name(value)} {_short(value)}")
        if minimum is not None and value < minimum:
            self.fail(key, f"must be >= {minimum}, got {_short(value)}")
        if maximum is not None and value > maximum:
            self.fail(key, f"must be <= {maximum}, got {_short(value)}")
        return value

    def string(self, key, default=_MISSING, *, choices=None):
        if key not in self.data:
            if default is _MISSING:
                self.fail(key, "missing required field")
            return default
        value = self.data[key]
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {_type_name(value)} {_short(value)}")
        if choices is not None and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            self.fail(
                key, f"unknown value {_short(value)}{hint}; choose one of: {', '.join(choices)}"
            )
        return value

    def vector(self, key, n=3, default=_MISSING):
        if key not in self.data:
            if default is _MISSING:
                self.fail(key, "missing required field")
            return None if default is None else np.asarray(default, dtype=float)
        value = self.data[key]
        if not isinstance(value, list) or len(value) != n:
            self.fail(
                key, f"must be a list of {n} numbers, got {_type_name(value)} {_short(value)}"
            )
        for i, x in enumerate(value):
            if isinstance(x, bool) or not isinstance(x, int | float):
                self.fail(key, f"element {i} must be a number, got {_type_name(x)} {_short(x)}")
            if not math.isfinite(_float(x)):
                self.fail(key, f"element {i} must be finite, got {_short(x)}")
        return np.asarray(value, dtype=float)

    def table(self, key, known, default=_MISSING):
        if key not in self.data:
            if default is _MISSING:
                self.fail(key, "missing required table")
            return default
        return _Table(
            self.data[key], f"{self.where}.{key}" if self.where else f"[{key}]", self.source, known
        )


def _float(value: int | float) -> float:
    """`value` as a float; inf for an integer too large for one."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _short(value, limit=60) -> str:
    """`repr(value)`, cut to `limit` characters (a message stays one readable line)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _unit(vector):
    """`vector` divided by its length, computed without overflow; None for the zero vector."""
    v = np.asarray(vector, dtype=float)
    scale = np.max(np.abs(v))
    if scale == 0:
        return None
    v = v / scale
    return v / np.linalg.norm(v)


def _type_name(value) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "a list",
        dict: "a table",
    }.get(type(value), type(value).__name__)


# ---------------------------------------------------------------------------------------------
# sections

_TOP_NAMES = {k: f"[{k}]" for k in ("body", "initial", "floor", "joint", "simulation")} | {
    "forces": "[[forces]]"
}
_TOP = ("title", "description", "body", "initial", "forces", "floor", "joint", "simulation")
_SOLVERS = ("tsit5", "dopri5", "dopri8")


def _vertices(t: "_Table"):
    raw = t.data.get("vertices")
    if not isinstance(raw, list) or not 4 <= len(raw) <= 200:
        t.fail("vertices", f"must be a list of 4 to 200 [x, y, z] points, got {_short(raw)}")
    points = []
    for i, p in enumerate(raw):
        ok = isinstance(p, list) and len(p) == 3
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in p)
        if not ok or not all(math.isfinite(_float(x)) for x in p):
            t.fail("vertices", f"point {i} must be 3 finite numbers, got {_short(p)}")
        points.append([float(x) for x in p])
    return np.asarray(points)


def _shape(body: _Table):
    import jaxrb

    if not body.has("shape"):
        return None
    raw = body.data["shape"]
    kind = raw.get("type") if isinstance(raw, dict) else None
    kind = kind if isinstance(kind, str) else None
    known = {
        "box": ("type", "half_extents", "offset"),
        "sphere": ("type", "radius", "offset"),
        "cylinder": ("type", "radius", "half_height", "offset"),
        "polyhedron": ("type", "vertices", "offset"),
        "die": ("type", "sides", "edge", "offset"),
    }
    t = _Table(
        raw,
        "[body.shape]",
        body.source,
        known.get(kind, tuple({k: 0 for v in known.values() for k in v})),
    )
    kind = t.string("type", choices=tuple(known))
    offset = t.vector("offset", default=(0.0, 0.0, 0.0))
    if kind == "box":
        half = t.vector("half_extents")
        if np.any(half <= 0):
            t.fail("half_extents", f"must all be > 0, got {half.tolist()}")
        return t.model(None, jaxrb.Box, half, offset)
    if kind == "sphere":
        return t.model(None, jaxrb.Sphere, t.number("radius", positive=True), offset)
    if kind == "polyhedron":
        return t.model("vertices", jaxrb.ConvexPolyhedron, _vertices(t), offset)
    if kind == "die":
        sides = t.integer("sides")
        if sides not in jaxrb.dice.BUILDERS:
            t.fail("sides", f"must be one of 4, 6, 8, 12, 20, got {sides}")
        build = jaxrb.dice.BUILDERS[sides]
        if t.has("edge"):
            return t.model(None, build, t.number("edge", positive=True), offset).shape
        return t.model(None, build, offset=offset).shape
    radius, half_height = t.number("radius", positive=True), t.number("half_height", positive=True)
    return t.model(None, jaxrb.Cylinder, radius, half_height, offset)


def _body(root: _Table):
    import jaxrb

    body = root.table("body", ("mass", "inertia", "shape"))
    mass = body.number("mass", positive=True)
    shape = _shape(body)
    inertia = None
    if body.has("inertia"):
        raw = body.data["inertia"]
        if isinstance(raw, list) and len(raw) == 3 and all(isinstance(r, list) for r in raw):
            rows = [
                _Table({"row": r}, "[body].inertia", body.source, ("row",)).vector("row")
                for r in raw
            ]
            inertia = np.stack(rows)
        else:
            try:
                inertia = body.vector("inertia")
            except SceneFileError:
                body.fail(
                    "inertia", f"must be 3 principal moments or a 3x3 list of lists, got {raw!r}"
                )
    elif shape is None:
        body.fail("inertia", "missing: give `inertia` or a [body.shape] to compute it from")
    # without `inertia`, the shape and the mass give it: a bad one is the shape's
    key = "inertia" if inertia is not None else "shape"
    return body.model(key, jaxrb.RigidBody, mass, inertia, shape=shape)


_SEQUENCES = ("121", "123", "131", "132", "212", "213", "231", "232", "312", "313", "321", "323")


def _initial(root: _Table):
    import jaxrb

    from . import _host as host

    init = root.table(
        "initial",
        ("pos", "vel", "omega", "quat", "axis", "angle_deg", "euler_deg", "sequence"),
        default=None,
    )
    if init is None:
        return jaxrb.make_state(), None
    given = [k for k in ("quat", "axis", "euler_deg") if init.has(k)]
    if len(given) > 1:
        init.fail(given[1], f"give the attitude once: `{given[0]}` is already set")
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    if init.has("quat"):
        quat = _unit(init.vector("quat", 4))
        if quat is None:
            init.fail("quat", "must not be zero")
    elif init.has("axis"):
        axis = _unit(init.vector("axis"))
        if axis is None:
            init.fail("axis", "must not be the zero vector")
        angle = math.radians(init.number("angle_deg"))
        quat = np.asarray(host.axis_angle_to_quat(axis, angle))
    elif init.has("euler_deg"):
        angles = np.radians(init.vector("euler_deg"))
        quat = np.asarray(host.euler_to_quat(angles, init.string("sequence", choices=_SEQUENCES)))
    else:
        for k in ("angle_deg", "sequence"):
            if init.has(k):
                init.fail(k, "given without `axis` / `euler_deg`")
    state = init.model(
        None,
        jaxrb.make_state,
        pos=init.vector("pos", default=(0.0, 0.0, 0.0)),
        quat=quat,
        vel=init.vector("vel", default=(0.0, 0.0, 0.0)),
        omega=init.vector("omega", default=(0.0, 0.0, 0.0)),
    )
    return state, init


def _initial_energy(root: _Table, init: _Table | None, scene, state0):
    """Refuse an initial state whose energy (J) overflows, naming the part that does:
    1/2 m vel.vel (`vel`), 1/2 omega.J omega (`omega`), else the potential (`pos`)."""
    from ._host import energy as host_energy

    with np.errstate(all="ignore"):
        total = float(host_energy(scene, state0))
        if math.isfinite(total):
            return
        mass = float(scene.body.mass)
        vel, omega = (np.asarray(x, dtype=float) for x in (state0.vel, state0.omega))
        inertia = np.asarray(scene.body.inertia_matrix, dtype=float)
        translational = 0.5 * mass * float(vel @ vel)
        rotational = 0.5 * float(omega @ inertia @ omega)
    if not math.isfinite(translational):
        key, part = "vel", f"the kinetic energy 1/2 m |vel|^2 is {translational} J"
    elif not math.isfinite(rotational):
        key, part = "omega", f"the kinetic energy 1/2 omega.J omega is {rotational} J"
    else:
        key, part = "pos", f"the potential energy is {total} J"
    problem = f"{part} (mass {mass:g} kg): too large to simulate"
    if init is None:
        root.fail("initial", problem)
    init.fail(key, problem)


def _above_floor(root: _Table, init: _Table | None, scene, state0):
    """Refuse a body that starts below the floor (its lowest point more than the contact
    tolerance under the plane z = height, m)."""
    import jaxrb
    from jaxrb.contact import ContactOptions

    from ._host import floor_gap

    if scene.floor is None:
        return
    with np.errstate(all="ignore"):
        gap = float(floor_gap(scene, state0))
    tolerance = ContactOptions().resolved(state0.pos.dtype).contact
    if not gap < -tolerance:
        return
    if isinstance(scene.floor, jaxrb.Floor):
        height, normal = float(scene.floor.height), scene.floor.normal
        where = (
            f"plane z = {height:g} m"
            if float(normal[2]) == 1.0
            else f"tilted plane through (0, 0, {height:g}) m"
        )
        what = f"its lowest point is {-gap:.3g} m under the {where}"
        fix = "raise pos[2] or lower [floor].height"
    else:
        name = type(scene.floor).__name__.lower()
        what = f"the ball reaches {-gap:.3g} m beyond the {name}'s surface"
        fix = "move pos inside it"
    problem = f"the body starts below the [floor]: {what} ({fix})"
    if init is None or not init.has("pos"):
        root.fail("initial", problem)
    init.fail("pos", problem)


def _joint_motion(init: _Table | None, joint, state0):
    """Refuse initial motion the joint cannot have: a hinge's `omega` off its axis, or a `vel`
    other than the one the joint gives the mass centre, R (omega x (C - O))."""
    import jax.numpy as jnp

    import jaxrb

    if joint is None or init is None:
        return
    name = f"the [joint] ({'hinge' if isinstance(joint, jaxrb.Hinge) else 'pivot'})"
    omega = np.asarray(state0.omega, dtype=float)
    if isinstance(joint, jaxrb.Hinge):
        axis = np.asarray(joint.axis, dtype=float)
        off = omega - (omega @ axis) * axis
        if np.linalg.norm(off) > 1e-9 * np.linalg.norm(omega):
            init.fail(
                "omega",
                f"{name} turns the body only about its axis {_fmt_vec(axis)} (body frame); "
                f"omega = {_fmt_vec(omega)} rad/s has the part {_fmt_vec(off)} off that axis",
            )
    if init.has("vel"):
        r_body = -np.asarray(joint.point, dtype=float)
        v_body = jnp.asarray(np.cross(omega, r_body), dtype=state0.quat.dtype)
        implied = np.asarray(jaxrb.quat_rotate(state0.quat, v_body), dtype=float)
        vel = np.asarray(state0.vel, dtype=float)
        if np.linalg.norm(vel - implied) > 1e-9 * max(np.linalg.norm(implied), 1.0):
            init.fail(
                "vel",
                f"{name} sets the mass centre's velocity from omega, R (omega x (C - O)) = "
                f"{_fmt_vec(implied)} m/s; got {_fmt_vec(vel)} m/s: leave `vel` out",
            )


def _fmt_vec(v) -> str:
    return "[" + ", ".join(f"{float(x):.6g}" for x in v) + "]"


_FORCES = {
    "gravity": ("type", "g"),
    "linear_drag": ("type", "coefficient"),
    "quadratic_drag": ("type", "coefficient", "rho", "drag_coefficient", "area"),
    "damping_moment": ("type", "linear", "quadratic"),
    "wrench": ("type", "force", "torque", "point", "frame"),
}


def _force(raw, where, source):
    import jaxrb

    if not isinstance(raw, dict):
        raise SceneFileError(f"{source}: {where}: must be a table, got {_type_name(raw)}")
    if "type" not in raw:
        raise SceneFileError(f"{source}: {where}.type: missing required field")
    kind = raw["type"]
    if not isinstance(kind, str) or kind not in _FORCES:
        close = difflib.get_close_matches(str(kind), _FORCES, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise SceneFileError(
            f"{source}: {where}.type: unknown force {kind!r}{hint}; "
            f"choose one of: {', '.join(_FORCES)}"
        )
    f = _Table(raw, where, source, _FORCES[kind])
    if kind == "gravity":
        return f.model(None, jaxrb.Gravity, f.vector("g", default=(0.0, 0.0, -9.81)))
    if kind == "linear_drag":
        return f.model(None, jaxrb.LinearDrag, f.number("coefficient", nonnegative=True))
    if kind == "quadratic_drag":
        if f.has("coefficient"):
            for k in ("rho", "drag_coefficient", "area"):
                if f.has(k):
                    f.fail(
                        k,
                        "give either `coefficient` or (`rho`, `drag_coefficient`, `area`), "
                        "not both",
                    )
            return f.model(None, jaxrb.QuadraticDrag, f.number("coefficient", nonnegative=True))
        if not f.has("area"):
            f.fail(
                "coefficient",
                "missing: give `coefficient` (kg/m) or `area` (m^2) with `rho`, `drag_coefficient`",
            )
        return f.model(
            None,
            jaxrb.QuadraticDrag.from_air,
            f.number("rho", 1.225, nonnegative=True),
            f.number("drag_coefficient", 1.0, nonnegative=True),
            f.number("area", nonnegative=True),
        )
    if kind == "damping_moment":
        return f.model(
            None,
            jaxrb.DampingMoment,
            f.number("linear", 0.0, nonnegative=True),
            f.number("quadratic", 0.0, nonnegative=True),
        )
    return f.model(
        None,
        jaxrb.Wrench,
        force=f.vector("force", default=None),
        torque=f.vector("torque", default=None),
        point=f.vector("point", default=None),
        frame=f.string("frame", "world", choices=("world", "body")),
    )


def _forces(root: _Table):
    raw = root.data.get("forces", [])
    if not isinstance(raw, list):
        root.fail("forces", "must be an array of tables, written [[forces]]")
    return tuple(_force(item, f"[[forces]][{i}]", root.source) for i, item in enumerate(raw))


_FLOOR_KEYS = {
    "plane": ("normal",),
    "bowl": ("radius",),
    "cone": ("inclination_deg", "tip_radius"),
    "wheel": ("inclination_deg", "tip_radius", "wall_radius"),
}


def _floor(root: _Table):
    import jaxrb

    common = ("type", "restitution", "friction", "rolling_resistance", "spin_resistance")
    known = (*common, "height", *dict.fromkeys(sum(_FLOOR_KEYS.values(), ())))
    floor = root.table("floor", known, default=None)
    if floor is None:
        return None
    kind = floor.string("type", "plane", choices=tuple(_FLOOR_KEYS))
    for other, keys in _FLOOR_KEYS.items():
        for key in keys:
            if key not in _FLOOR_KEYS[kind] and floor.has(key):
                floor.fail(key, f"belongs to a floor of type {other!r}, not {kind!r}")
    contact = (
        floor.number("restitution", lo=0.0, hi=1.0),
        floor.number("friction", 0.0, nonnegative=True),
    )
    resistance = {
        key: floor.number(key, 0.0, nonnegative=True)
        for key in ("rolling_resistance", "spin_resistance")
    }
    height = floor.number("height", 0.0)
    if kind == "bowl":
        radius = floor.number("radius", positive=True)
        return floor.model(
            "radius", jaxrb.Bowl, *contact, radius=radius, height=height, **resistance
        )
    if kind in ("cone", "wheel"):
        inclination = floor.number("inclination_deg", lo=0.0, hi=90.0)
        if not 0.0 < inclination < 90.0:
            floor.fail("inclination_deg", f"must be in (0, 90) degrees, got {inclination:g}")
        track = dict(
            inclination=math.radians(inclination),
            height=height,
            tip_radius=floor.number("tip_radius", 0.0, nonnegative=True),
            **resistance,
        )
        if kind == "wheel":
            wall = floor.number("wall_radius", positive=True)
            return floor.model("wall_radius", jaxrb.Wheel, *contact, wall_radius=wall, **track)
        return floor.model("inclination_deg", jaxrb.Cone, *contact, **track)
    normal = floor.vector("normal", default=(0.0, 0.0, 1.0))
    if not np.any(normal):
        floor.fail("normal", "must be a non-zero direction, got [0, 0, 0]")
    return floor.model("normal", jaxrb.Floor, *contact, height, normal, **resistance)


def _joint(root: _Table):
    import jaxrb

    joint = root.table("joint", ("type", "point", "axis"), default=None)
    if joint is None:
        return None
    kind = joint.string("type", choices=("pivot", "hinge"))
    point = joint.vector("point", default=(0.0, 0.0, 0.0))
    if kind == "pivot":
        if joint.has("axis"):
            joint.fail("axis", 'a pivot has no axis (use type = "hinge")')
        return joint.model(None, jaxrb.Pivot, point)
    axis = _unit(joint.vector("axis"))
    if axis is None:
        joint.fail("axis", "must not be the zero vector")
    return joint.model(None, jaxrb.Hinge, point, axis)


def _simulation(root: _Table):
    from .contact._options import DEFAULT_MAX_IMPACTS

    sim = root.table(
        "simulation",
        ("t_start", "t_end", "num_saves", "rtol", "atol", "max_steps", "max_impacts", "solver"),
    )
    t0 = sim.number("t_start", 0.0)
    t1 = sim.number("t_end")
    n = sim.integer("num_saves", 201, minimum=2)
    try:
        check_time_span(t0, t1)
    except ValueError as e:
        sim.fail("t_end", str(e))
    options = {
        "rtol": sim.number("rtol", 1e-6, positive=True),
        "atol": sim.number("atol", 1e-6, positive=True),
        "max_steps": sim.integer("max_steps", 100_000, minimum=1, maximum=MAX_STEPS_LIMIT),
        "solver": sim.string("solver", "tsit5", choices=_SOLVERS),
        "max_impacts": sim.integer(
            "max_impacts", DEFAULT_MAX_IMPACTS, minimum=1, maximum=MAX_IMPACTS_LIMIT
        ),
    }
    return (t0, t1, n), options, sim


def check_time_span(t_start: float, t_end: float) -> None:
    """A ValueError (the problem with `t_end`) unless `t_start`, `t_end` (s) are finite,
    `t_end` > `t_start` and `t_end - t_start` is finite."""
    if not (math.isfinite(t_start) and math.isfinite(t_end)):
        raise ValueError(f"must be finite, got t_start = {t_start}, t_end = {t_end}")
    if t_end <= t_start:
        raise ValueError(f"must be greater than t_start = {t_start}, got {t_end}")
    if not math.isfinite(t_end - t_start):
        raise ValueError(f"t_end - t_start overflows (t_start = {t_start}, t_end = {t_end})")


def _output_size(sim: _Table, scene, num_saves: int):
    """Refuse more saves than make `MAX_OUTPUT_BYTES` of output arrays."""
    from ._trajectory_files import bytes_per_save

    per_save = bytes_per_save(scene)
    if num_saves * per_save > MAX_OUTPUT_BYTES:
        sim.fail(
            "num_saves",
            f"{num_saves} saves would make {num_saves * per_save / 1e9:.3g} GB of output "
            f"arrays ({per_save} bytes each); the limit is {MAX_OUTPUT_BYTES / 1e9:g} GB, "
            f"at most {int(MAX_OUTPUT_BYTES // per_save)} saves",
        )


def parse_scene(data: dict, source: str = "<scene>") -> SceneSpec:
    """Build a `SceneSpec` from an already-parsed TOML dictionary (see `load_scene`)."""
    import jaxrb

    root = _Table(data, "", source, _TOP)
    title = root.string("title", "")
    description = root.string("description", "")
    body = _body(root)
    forces = _forces(root)
    floor = _floor(root)
    joint = _joint(root)
    if floor is not None and joint is not None:
        root.fail("joint", "a scene may have a [floor] or a [joint], not both")
    if floor is not None and body.shape is None:
        root.fail("floor", "a scene with a floor needs a [body.shape] to find the contact point")
    if floor is not None and floor.curved and not isinstance(body.shape, jaxrb.Sphere):
        root.fail("floor", f"a {type(floor).__name__.lower()} meets only a sphere [body.shape]")
    state0, init = _initial(root)
    _joint_motion(init, joint, state0)
    (t0, t1, num_saves), options, sim = _simulation(root)
    scene = root.model(None, jaxrb.Scene, body, forces=forces, floor=floor, joint=joint)
    _initial_energy(root, init, scene, state0)
    _above_floor(root, init, scene, state0)
    _output_size(sim, scene, num_saves)
    ts = np.linspace(t0, t1, num_saves)
    return SceneSpec(scene, state0, ts, options, title, description, data, source)


_HEADER = re.compile(r"^\s*\[\[?\s*([^\[\]#]+?)\s*\]\]?\s*(#.*)?$")
_T_END = re.compile(r"^(\s*t_end\s*=\s*)([^#]*?)\s*(#.*)?$")


def with_t_end(text: str, t_end: float, source: str = "<scene>") -> str:
    """The scene file's text with `[simulation].t_end` set to `t_end` (s), comments kept.

    `jaxrb run --t-end` saves this as the scene that was run. Raises `SceneFileError` when
    the field is not written as a `t_end = ...` line of the `[simulation]` table.
    """
    lines = text.splitlines()
    table = None
    for i, line in enumerate(lines):
        header = _HEADER.match(line)
        if header:
            table = header.group(1)
            continue
        match = _T_END.match(line)
        if table == "simulation" and match:
            was = match.group(2)
            lines[i] = f"{match.group(1)}{float(t_end)!r}  # set by --t-end (the file had {was})"
            break
    new = "\n".join(lines) + "\n"
    expected = tomllib.loads(text)
    expected["simulation"]["t_end"] = float(t_end)
    try:
        same = tomllib.loads(new) == expected
    except tomllib.TOMLDecodeError:
        same = False
    if not same:
        raise SceneFileError(
            f"{source}: [simulation].t_end: --t-end cannot rewrite this field in the saved copy "
            "of the scene; write it as a line `t_end = ...` under [simulation], or edit the file"
        )
    return new


def make_solver(name: str):
    """The diffrax solver for a scene file's `solver` name."""
    import diffrax as dfx

    return {"tsit5": dfx.Tsit5, "dopri5": dfx.Dopri5, "dopri8": dfx.Dopri8}[name]()
