# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""B4: a die (16 mm cube, 4.5 g), a coin (radius 12 mm, thickness 2 mm, 7.5 g) and the regular
d4 and d20 of `jaxrb.dice` (same density as the cube; `--n-poly` of each), each thrown
onto the floor (restitution 0.5, Coulomb friction 0.3) under gravity, from heights U(0.1, 0.3) m with a random attitude, spin U(-30, 30) rad/s per
body axis and horizontal speed U(-0.5, 0.5) m/s; T = 1.5 s, batch N dice (default 64: impacts
are expensive) and N/4 coins (`--n-coins`: a coin rolls and spins on its rim with many
stick/slip events), `jaxrb.simulate` of the batch of states (on a CPU the bodies run one after
another, on a GPU side by side under `jax.vmap`) with `throw=False`, `max_impacts` = 64.

Error (per body, against a reference solve of the same throws with diffrax Dopri8 at
rtol = atol = 1e-13, float64): the max over the save times of the position error (m), the max
over the save times of the attitude geodesic angle (rad), and the max over the impact slots
recorded in both runs of the impact-time error (s). The table's `error` is the worst body's
max of the three; b4.md adds a detail table with each part, the first impact's time error
(flight and event location only), the median body, the fraction of bodies with the
reference's impact count, and the fraction of bodies (and of reference bodies) that ended
with a non-successful result code (e.g. max_impacts_reached), by code.

A die's landing is chaotic: a small change in an early impact can change which corner hits next
and the face it ends on, so the worst body's error need not fall with the tolerance; the
median body and the "same impact count" fraction show how much of the batch tracks the
reference.

Peers: scipy `solve_ivp` has terminal events but no impact, friction or resting-contact
model, so there is no fair out-of-the-box scipy peer: jaxrb is reported alone over solvers and
tolerances. MuJoCo (optional) uses soft contacts (no Newton restitution), a different model: its
row is its cost per body for the same throws with its default contact (friction set to 0.3),
N bodies (a box, or a cylinder for the coin) in one scene that do not collide with each other,
and no error column.

Run: python -m benchmarks.b4_die_impacts --n 64 --n-coins 16 --n-poly 16 --out bench_out
"""

import argparse
import dataclasses
import math
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402
from jaxrb._results import RESULTS  # noqa: E402

try:
    from . import _common as C, _generic as G
except ImportError:
    import _common as C  # type: ignore
    import _generic as G  # type: ignore

T_END = 1.5
HALF = 0.008  # m: a 16 mm die
MASS = 0.0045  # kg
COIN_RADIUS, COIN_HALF, COIN_MASS = 0.012, 0.001, 0.0075  # m, m, kg
RESTITUTION = 0.5
FRICTION = 0.3
MAX_IMPACTS = 64
# Step budget per smooth segment (accepted + rejected). Below the library default (1e5) to bound
# the cost of a throw that stalls (under vmap, on a GPU, the whole batch runs as long as its
# slowest member); the table reports any throw that ends in max_steps_reached.
MAX_STEPS = 10_000
REF_TOL = 1e-13
N_SAVE = 16

_CODE_NAMES = {int(item._value): name for name, item in RESULTS._name_to_item.items()}


POLYHEDRA = {"d4": 4, "d20": 20}  # the regular dice of jaxrb.dice, same density as the cube


def make_scene(shape="die"):
    if shape == "die":
        body = jaxrb.RigidBody(jnp.asarray(MASS), shape=jaxrb.Box(jnp.full(3, HALF)))
    elif shape in POLYHEDRA:
        poly = jaxrb.dice.BUILDERS[POLYHEDRA[shape]]().shape
        mass = MASS / (2 * HALF) ** 3 * float(poly.volume)
        body = jaxrb.RigidBody(jnp.asarray(mass), shape=poly)
    else:
        body = jaxrb.RigidBody(jnp.asarray(COIN_MASS), shape=jaxrb.Cylinder(COIN_RADIUS, COIN_HALF))
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), floor=jaxrb.Floor(RESTITUTION, FRICTION))


def initial_states(n, seed=0):
    k1, k2, k3, k4, k5 = jax.random.split(jax.random.key(seed), 5)
    z = jax.random.uniform(k1, (n,), minval=0.1, maxval=0.3, dtype=jnp.float64)
    axis = jax.random.normal(k2, (n, 3), dtype=jnp.float64)
    axis = axis / jnp.linalg.norm(axis, axis=-1, keepdims=True)
    angle = jax.random.uniform(k3, (n,), minval=0.0, maxval=np.pi, dtype=jnp.float64)
    q = jaxrb.axis_angle_to_quat(axis, angle)
    w = jax.random.uniform(k4, (n, 3), minval=-30.0, maxval=30.0, dtype=jnp.float64)
    vxy = jax.random.uniform(k5, (n, 2), minval=-0.5, maxval=0.5, dtype=jnp.float64)
    v = jnp.concatenate([vxy, jnp.zeros((n, 1))], -1)
    pos = jnp.stack([jnp.zeros(n), jnp.zeros(n), z], -1)
    return jaxrb.make_state(pos=pos, quat=q, vel=v, omega=w)


def solve_fn(scene, ts, solver):
    """jit(simulate) of the batch of states (on a CPU one body after another, elsewhere
    vmapped: `simulate`'s batch docs), the tolerance a traced argument (one compilation per
    sweep)."""
    return jax.jit(
        lambda s, tol: jaxrb.simulate(
            scene,
            s,
            ts,
            solver=solver,
            rtol=tol,
            atol=tol,
            max_steps=MAX_STEPS,
            max_impacts=MAX_IMPACTS,
            throw=False,
        )
    )


def codes(tr):
    return np.asarray(tr.result._value).reshape(-1)


def code_summary(c):
    bad = c[c != 0]
    if bad.size == 0:
        return "none"
    vals, counts = np.unique(bad, return_counts=True)
    return ", ".join(f"{_CODE_NAMES.get(int(v), v)} {k}" for v, k in zip(vals, counts, strict=True))


def detail(tr, ref):
    """Per-body error parts and batch statistics of `tr` against the reference `ref`."""
    f64 = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
    e_x = jnp.max(jnp.linalg.norm(f64(tr.states.pos) - ref.states.pos, axis=-1), axis=-1)
    e_q = jnp.max(jaxrb.quat_geodesic_angle(f64(tr.states.quat), ref.states.quat), axis=-1)
    both = tr.impacts.valid & ref.impacts.valid
    e_t = jnp.max(jnp.where(both, jnp.abs(f64(tr.impacts.time) - ref.impacts.time), 0.0), axis=-1)
    e = np.asarray(jnp.maximum(jnp.maximum(e_x, e_q), e_t))
    # the first impact: flight plus event location only, before any chaotic amplification
    first = both[:, 0]
    e_t1 = jnp.where(first, jnp.abs(f64(tr.impacts.time[:, 0]) - ref.impacts.time[:, 0]), 0.0)
    c, cr = codes(tr), codes(ref)
    same = np.asarray(tr.impacts.count == ref.impacts.count)
    clean = same & (c == 0) & (cr == 0)
    return dict(
        error=float(e.max()),
        pos=float(jnp.max(e_x)),
        angle=float(jnp.max(e_q)),
        dt=float(jnp.max(e_t)),
        dt1=float(jnp.max(e_t1)),
        median=float(np.median(e)),
        clean_worst=float(e[clean].max()) if clean.any() else math.nan,
        same=float(same.mean()),
        failed=float((c != 0).mean()),
        failed_codes=code_summary(c),
        impacts=float(jnp.mean(tr.impacts.count)),
    )


def detail_table(items, device):
    head = (
        f"device: `{device}` (shared 2-core CPU when run on one: timings are noisy)\n\n"
        "| method | dtype | setting | N | worst pos (m) | worst angle (rad) | worst impact-time (s) "
        "| worst 1st impact-time (s) | median body | worst body, same count & both successful "
        "| same impact count | non-successful (codes) | mean impacts |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r, d in items:
        lines.append(
            f"| {r.method} | {r.dtype} | {r.setting} | {r.n} | {C.fmt(d['pos'])} | "
            f"{C.fmt(d['angle'])} | {C.fmt(d['dt'])} | {C.fmt(d['dt1'])} | {C.fmt(d['median'])} | "
            f"{C.fmt(d['clean_worst'])} | {d['same']:.0%} | {d['failed']:.0%} "
            f"({d['failed_codes']}) | {d['impacts']:.1f} |"
        )
    return head + "\n".join(lines) + "\n"


def run(n=64, dtypes=("float64", "float32"), quick=False, shape="die"):
    states0 = initial_states(n)
    ts = jnp.linspace(0.0, T_END, N_SAVE)
    rows, items = [], []
    problem = f"B4 {shape}"

    # reference: Dopri8 at 1e-13 through the same compiled function as the Dopri8 rows
    dopri8_64 = solve_fn(make_scene(shape), ts, dfx.Dopri8())
    t0 = time.perf_counter()
    ref = jax.block_until_ready(dopri8_64(states0, jnp.asarray(REF_TOL)))
    ref_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = jax.block_until_ready(dopri8_64(states0, jnp.asarray(REF_TOL)))
    ref_best = time.perf_counter() - t0
    cr = codes(ref)
    ref_row = C.Row(
        problem,
        "reference: diffrax Dopri8, jaxrb.simulate of the batch",
        "float64",
        f"tol {REF_TOL:.0e}",
        n,
        0.0,
        ref_best / n * 1e6,
        ref_first - ref_best,
        float(jnp.mean(ref.num_steps)),
        f"reference non-successful: {(cr != 0).mean():.0%} ({code_summary(cr)})",
    )
    rows.append(ref_row)
    items.append((ref_row, detail(ref, ref)))

    for dname in dtypes:
        dt = jnp.float64 if dname == "float64" else jnp.float32
        scene = G.cast(make_scene(shape), dt)
        s0 = G.cast(states0, dt)
        tsd = ts.astype(dt)
        if dname == "float64":
            sweeps = [
                ("Dopri8", dfx.Dopri8(), [1e-6, 1e-8, 1e-10, 1e-12]),
                ("Tsit5", dfx.Tsit5(), [1e-6, 1e-8, 1e-10]),
            ]
        else:
            sweeps = [("Tsit5", dfx.Tsit5(), [1e-5, 1e-6])]
        for solver_name, solver, tols in sweeps:
            if quick:
                tols = tols[1:2] if len(tols) > 1 else tols
            fn = dopri8_64 if (dname == "float64" and solver_name == "Dopri8") else None
            if fn is None:
                fn = solve_fn(scene, tsd, solver)
            for tol in tols:
                method = f"diffrax {solver_name}, jaxrb.simulate of the batch"
                try:
                    first, best, tr = C.time_jax(fn, s0, jnp.asarray(tol, dt), repeats=1)
                except Exception as exc:  # report, do not hide: e.g. float32 event dtypes
                    msg = str(exc).strip().splitlines()
                    msg = next((m for m in msg if m.strip()), "")[:160].replace("|", "/")
                    rows.append(
                        C.Row(
                            problem,
                            method,
                            dname,
                            f"tol {tol:.0e}",
                            n,
                            math.nan,
                            math.nan,
                            math.nan,
                            note=f"FAILED: {type(exc).__name__}: {msg}",
                        )
                    )
                    break  # the same failure for every tolerance
                d = detail(tr, ref)
                row = C.Row(
                    problem,
                    method,
                    dname,
                    f"tol {tol:.0e}",
                    n,
                    d["error"],
                    best / n * 1e6,
                    first - best,
                    float(jnp.mean(tr.num_steps)),
                    f"median body {d['median']:.1e}; same impact count {d['same']:.0%}; "
                    f"non-successful {d['failed']:.0%}",
                )
                rows.append(row)
                items.append((row, d))
    rows += mujoco_rows(states0, quick, shape)
    return rows, items


def mujoco_rows(states0, quick, shape="die"):
    """Cost per body of MuJoCo's C engine on the same throws: a different (soft-contact) model.
    (None for the polyhedral dice, which MuJoCo would need as mesh assets.)"""
    if shape in POLYHEDRA:
        return []
    try:
        import mujoco
    except ImportError:
        return [
            C.Row(
                f"B4 {shape}",
                "MuJoCo C (not installed: pip install jaxrb[bench])",
                "float64",
                "-",
                0,
                math.nan,
                math.nan,
                math.nan,
            )
        ]
    n = states0.pos.shape[0]
    if shape == "die":
        geom = f"type='box' size='{HALF} {HALF} {HALF}' mass='{MASS}'"
    else:  # a cylinder's size: radius, half-height; its axis is body z as in jaxrb
        geom = f"type='cylinder' size='{COIN_RADIUS} {COIN_HALF}' mass='{COIN_MASS}'"
    rows = []
    for integrator, h in [("Euler", 0.002), ("RK4", 0.002), ("Euler", 0.0005)][: 1 if quick else 3]:
        xml = (
            f"<mujoco><option gravity='0 0 -9.81' integrator='{integrator}' timestep='{h}'/>"
            "<worldbody><geom type='plane' size='0 0 1' contype='0' conaffinity='1' "
            f"friction='{FRICTION} 0.005 0.0001'/>"
            + "".join(
                f"<body><freejoint/><geom {geom} "
                f"contype='1' conaffinity='0' friction='{FRICTION} 0.005 0.0001'/></body>"
                for _ in range(n)
            )
            + "</worldbody></mujoco>"
        )
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        n_steps = int(round(T_END / h))
        qpos0 = np.concatenate([np.asarray(states0.pos), np.asarray(states0.quat)], -1)
        qvel0 = np.concatenate([np.asarray(states0.vel), np.asarray(states0.omega)], -1)

        def go():
            mujoco.mj_resetData(model, data)
            data.qpos[:] = qpos0.ravel()  # quaternion scalar first, body -> world
            data.qvel[:] = qvel0.ravel()  # free joint: world linear, body (local) angular velocity
            for _ in range(n_steps):
                mujoco.mj_step(model, data)
            return data.qpos.reshape(n, 7).copy()

        sec, qpos = C.time_python(go)
        rest = float(np.mean(np.abs(np.asarray(data.qvel).reshape(n, 6)).max(-1) < 1e-2))
        rows.append(
            C.Row(
                f"B4 {shape}",
                f"MuJoCo C {integrator}, N bodies in one scene: DIFFERENT MODEL (soft contact)",
                "float64",
                f"h {h:g}",
                n,
                math.nan,
                sec / n * 1e6,
                math.nan,
                float(n_steps),
                f"mujoco {mujoco.__version__}, default solref/solimp, no restitution; "
                f"no error vs jaxrb; at rest at T: {rest:.0%}",
            )
        )
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description="B4 die and coin thrown onto the floor (impacts)")
    p.add_argument("--n", type=int, default=64, help="dice")
    p.add_argument("--n-coins", type=int, default=None, help="coins (default n / 4; 0: none)")
    p.add_argument(
        "--n-poly",
        type=int,
        default=None,
        help="d4 and d20 dice each, beside the cube (default n / 4; 0: none)",
    )
    p.add_argument("--dtype", choices=["float64", "float32", "both"], default="both")
    p.add_argument("--out", default=None)
    p.add_argument("--quick", action="store_true")
    a = p.parse_args(argv)
    # the CPU compiler settings of `jaxrb run`, without a cache (every compile a cold one)
    jaxrb.speed_up_compilation(cache=False)
    dtypes = ("float64", "float32") if a.dtype == "both" else (a.dtype,)
    n_coins = a.n_coins if a.n_coins is not None else max(a.n // 4, 1)
    n_poly = a.n_poly if a.n_poly is not None else max(a.n // 4, 1)
    dev = C.device_name()
    text, rows = "", []
    for shape, n in (("die", a.n), ("coin", n_coins), ("d4", n_poly), ("d20", n_poly)):
        if n <= 0:
            continue
        shape_rows, items = run(n, dtypes, a.quick, shape)
        rows += shape_rows
        table = C.markdown_table(shape_rows, dev)
        details = detail_table(items, dev)
        print(table)
        print(details)
        png = "b4.png" if shape == "die" else f"b4_{shape}.png"
        text += (
            f"## B4 {shape} thrown onto the floor (impacts), N = {n}\n\n"
            + table
            + f"\n### B4 {shape}: error parts and result codes\n\n"
            + details
            + f"\n![B4 {shape}]({png})\n\n"
        )
        if a.out:
            os.makedirs(a.out, exist_ok=True)
            # the worst body sits near pi (on another face) at every tolerance: plot the median
            C.plot_work_precision(
                [
                    dataclasses.replace(r, error=d["median"])
                    for r, d in items
                    if not r.method.startswith("reference")
                ],
                f"B4 {shape} with impacts, N={n}, {dev}",
                os.path.join(a.out, png),
                ylabel="median body's error (worst body: see b4.md)",
            )
    if a.out:
        with open(os.path.join(a.out, "b4.md"), "w") as f:
            f.write(text)
    return rows


if __name__ == "__main__":
    main()
