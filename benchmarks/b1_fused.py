"""B1 on a GPU: a batch's Runge-Kutta step as one kernel against the stages written out.

The torque-free asymmetric top of B1 (J = (1, 2, 3) kg m^2, T = 20 s, omega0 = (a, 0, c)
with a ~ U(0.5, 1.5), c ~ U(1, 2) rad/s), N bodies as one `jaxrb.simulate` of a batched
state, one device. Rows side by side in one run:

- "fused": `simulate` as a user calls it (`solver=diffrax.Dopri8()` or `Tsit5()`): on a
  GPU each step of the shared body's free rotation is one kernel
  (`jaxrb/_fused_rotation_step.py`);
- "written out": the same method through `jaxrb.unrolled_solver(...)`, one XLA kernel per
  stage (what `simulate` used before).

Error: the largest over the bodies of max(|omega_T - omega_exact| / |omega0|, the geodesic
angle to the exact attitude), against the exact flow `jaxrb.torque_free_flow` (float64,
error about 1e-12 at T = 20). us/body: the best of 3 steady calls / N; compile: the first
call less the best. Also: the reverse-mode gradient of a weighted sum of the final states
with respect to every omega0 (100 checkpoints), both ways, and its agreement between them.

    python -m benchmarks.b1_fused --n 1000000 --out bench_out      # on a GPU
    python -m benchmarks.b1_fused --plot bench_out/b1_fused.json   # its picture, anywhere
    python -m benchmarks.b1_fused --per-member --n 1000000 --out bench_out   # an inertia sweep
    python -m benchmarks.b1_fused --extras --n 1000000 --out bench_out       # the rest

With `--per-member`, an inertia sweep instead: each member its own principal moments about
(1, 2, 3) (`member_inertias`), `jaxrb.simulate_batch(..., batched_scene=True)` against the
stages written out, the error against each member's exact flow, and the reverse gradient
with respect to every member's J (`b1_fused_per_member.json` and `.png`). With `--extras`,
what B1's rows leave out (`extras_rows`): a full inertia tensor, saves between the ends and
forward-mode derivatives (`b1_fused_extras.json`).

On a CPU the fused step is not used by `simulate` (its kernel is Triton's); this script then
says so and stops.
"""

import argparse
import json
import os

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C
    from .b1_torque_free import INERTIA, T_END, error_against, initial_omegas, scene_for
except ImportError:  # run as a script
    import _common as C  # type: ignore
    from b1_torque_free import (  # type: ignore
        INERTIA,
        T_END,
        error_against,
        initial_omegas,
        scene_for,
    )

ROWS = (  # (dtype, solver name, tolerances)
    ("float64", "Dopri8", (1e-8, 1e-9, 5e-10, 1e-11)),
    ("float64", "Tsit5", (1e-8, 1e-10)),
    ("float32", "Dopri8", (1e-6,)),
    ("float32", "Tsit5", (1e-5,)),
)
GRAD_TOL = 5e-10
CHECKPOINTS = 100
PER_MEMBER_ROWS = (  # `--per-member`: an inertia sweep, one J per member
    ("float64", "Dopri8", (1e-8, 1e-9, 1e-10)),
    ("float32", "Dopri8", (1e-6,)),
)


def _solvers(name):
    base = getattr(dfx, name)()
    return {"fused": base, "written out": jaxrb.unrolled_solver(base)}


def exact(omega0):
    """(omega_T (N, 3), unit quat_T (N, 4)) of the exact flow, float64."""
    states0 = jaxrb.make_state(omega=omega0)
    out = jax.jit(lambda s: jaxrb.torque_free_flow(jnp.asarray(INERTIA), s, T_END))(states0)
    quat = out.quat / jnp.linalg.norm(out.quat, axis=-1, keepdims=True)
    return out.omega, quat


def solve_rows(n):
    omega0 = initial_omegas(n)
    error = at_end(error_against(*exact(omega0), omega0))
    rows = []
    for dname, solver_name, tols in ROWS:
        dtype = jnp.dtype(dname)
        scene = scene_for(dtype)
        states0 = jaxrb.make_state(omega=omega0.astype(dtype))
        ts = jnp.array([0.0, T_END], dtype)
        for way, solver in _solvers(solver_name).items():
            fn = jax.jit(
                lambda s, tol, solver=solver, scene=scene, ts=ts: jaxrb.simulate(
                    scene, s, ts, solver=solver, rtol=tol, atol=tol, max_steps=10**5, throw=False
                )
            )
            for i, tol in enumerate(tols):
                timed = C.time_jax(fn, states0, jnp.asarray(tol, dtype))
                rows.append(_row(timed, n, f"{way}, {solver_name}", dname, tol, error, i == 0))
    return rows


def at_end(error):
    """An error function of whole trajectories' (omega (N, S, 3), quat (N, S, 4)) from one
    of their final values (`error_against`)."""
    return lambda omega, quat: error(omega[:, -1], quat[:, -1])


def _row(timed, n, method, dname, tol, error, compiled):
    """A solve's row from `C.time_jax`'s (first, best, trajectory), `error` of the
    trajectory's (omega, quat); its compile time where `compiled` (the first call of its
    program)."""
    first, best, traj = timed
    row = dict(
        method=method,
        dtype=dname,
        tol=tol,
        error=error(traj.states.omega, traj.states.quat),
        us_per_body=best / n * 1e6,
        compile_s=first - best if compiled else None,
        steps=int(traj.num_steps[0]),
    )
    print(json.dumps(row), flush=True)
    return row


def derivative_rows(derivative_with, x, n, what):
    """Rows of `derivative_with(solver)` (a function of `x`, n bodies: a gradient, a
    directional derivative) for Dopri8 fused and written out, and the two results'
    agreement (the largest entry's relative difference)."""
    rows, results = [], {}
    for way, solver in _solvers("Dopri8").items():
        first, best, results[way] = C.time_jax(jax.jit(derivative_with(solver)), x)
        row = dict(
            method=f"{way}, Dopri8: {what}",
            dtype="float64",
            tol=GRAD_TOL,
            us_per_body=best / n * 1e6,
            compile_s=first - best,
        )
        print(json.dumps(row), flush=True)
        rows.append(row)
    a, b = results["fused"], results["written out"]
    agree = float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))
    print(json.dumps(dict(relative_difference=agree)), flush=True)
    rows.append(dict(method=f"{what}: fused against written out", relative_difference=agree))
    return rows


def reverse_gradient_rows(loss_with, x, n, what):
    """`derivative_rows` of the reverse gradient of `loss_with(solver)` w.r.t. `what`."""
    label = f"reverse gradient w.r.t. {what} ({CHECKPOINTS} checkpoints)"
    return derivative_rows(lambda solver: jax.grad(loss_with(solver)), x, n, label)


def gradient_rows(n):
    omega0 = initial_omegas(n)
    scene = scene_for(jnp.float64)
    ts = jnp.array([0.0, T_END])
    weights = jax.random.normal(jax.random.key(0), (n, 7))
    adjoint = dfx.RecursiveCheckpointAdjoint(CHECKPOINTS)

    def loss_with(solver):
        def loss(w):
            traj = jaxrb.simulate(
                scene,
                jaxrb.make_state(omega=w),
                ts,
                solver=solver,
                rtol=GRAD_TOL,
                atol=GRAD_TOL,
                adjoint=adjoint,
                throw=False,
            )
            final = jnp.concatenate([traj.states.quat[:, -1], traj.states.omega[:, -1]], -1)
            return jnp.sum(weights * final)

        return loss

    return reverse_gradient_rows(loss_with, omega0, n, "all omega0")


def member_inertias(n, seed=1):
    """(N, 3) principal moments (kg m^2), each member's own, about B1's (1, 2, 3): J1 in
    [1, 1.1], J2 in [2, 2.2], J3 in [2.7, 3] (so J1 + J2 >= J3)."""
    u = jax.random.uniform(jax.random.key(seed), (n, 3), dtype=jnp.float64)
    return jnp.asarray(INERTIA) * (1 + jnp.array([0.1, 0.1, -0.1]) * u)


def _member_scene(inertia, dtype):
    n = inertia.shape[0]
    return jaxrb.Scene(jaxrb.RigidBody(jnp.ones(n, dtype), inertia.astype(dtype), principal=True))


def per_member_rows(n, grad_n):
    """An inertia sweep: `simulate_batch(..., batched_scene=True)`, each member with its own
    J (on a GPU each step one kernel with every member's J and J^-1 beside its state), against
    the stages written out; its error against each member's exact flow; and the reverse
    gradient of a weighted sum of the final omegas with respect to every member's J."""
    omega0, inertia = initial_omegas(n), member_inertias(n)
    flow = jax.jit(
        jax.vmap(lambda J, w: jaxrb.torque_free_flow(J, jaxrb.make_state(omega=w), T_END))
    )(inertia, omega0)
    unit = flow.quat / jnp.linalg.norm(flow.quat, axis=-1, keepdims=True)
    error = at_end(error_against(flow.omega, unit, omega0))
    rows = []
    for dname, solver_name, tols in PER_MEMBER_ROWS:
        dtype = jnp.dtype(dname)
        scene = _member_scene(inertia, dtype)
        states0 = jaxrb.make_state(omega=omega0.astype(dtype))
        ts = jnp.array([0.0, T_END], dtype)
        for way, solver in _solvers(solver_name).items():
            for i, tol in enumerate(tols):

                def run(scene, states0, solver=solver, ts=ts, tol=tol):
                    return jaxrb.simulate_batch(
                        scene, states0, ts, solver=solver, rtol=tol, atol=tol,
                        max_steps=10**5, batched_scene=True, throw=False,
                    )  # fmt: skip

                method = f"{way}, {solver_name}, one J per member"
                timed = C.time_jax(run, scene, states0)
                rows.append(_row(timed, n, method, dname, tol, error, i == 0))
    if not grad_n:
        return rows
    omega0, inertia = initial_omegas(grad_n), member_inertias(grad_n)
    states0, ts = jaxrb.make_state(omega=omega0), jnp.array([0.0, T_END])
    weights = jax.random.normal(jax.random.key(2), (grad_n, 3))
    adjoint = dfx.RecursiveCheckpointAdjoint(CHECKPOINTS)

    def loss_with(solver):
        def loss(inertia):
            traj = jaxrb.simulate_batch(
                _member_scene(inertia, jnp.float64), states0, ts, solver=solver,
                rtol=GRAD_TOL, atol=GRAD_TOL, adjoint=adjoint, batched_scene=True,
                throw=False,
            )  # fmt: skip
            return jnp.sum(weights * traj.states.omega[:, -1])

        return loss

    return rows + reverse_gradient_rows(loss_with, inertia, grad_n, "every member's J")


TURN = jaxrb.axis_angle_to_quat(jnp.array([1.0, 2.0, 3.0]), 0.7)  # principal -> body axes
SAVES = 11


def extras_rows(n):
    """What the fused step does beyond B1's rows, fused against written out (Dopri8 at
    `GRAD_TOL`, float64): B1's body turned by the fixed rotation `TURN` (an inertia tensor
    with products of inertia; the exact flow is B1's in the principal axes, turned back),
    `SAVES` saves over the run (the dense output between steps; error the worst over the
    saves), and forward-mode derivatives (`diffrax.ForwardMode`: the final state's
    directional derivative along a random tangent of every omega0) with their agreement."""
    omega0 = initial_omegas(n)
    Q = jaxrb.quat_to_matrix(TURN)  # body axes of a principal axis: columns
    body = jaxrb.RigidBody(1.0, Q @ jnp.diag(jnp.asarray(INERTIA)) @ Q.T)
    turned = jaxrb.quat_conjugate(TURN)  # world <- body = (world <- principal) (principal <- body)
    ts = jnp.linspace(0.0, T_END, SAVES)
    flow = jax.jit(lambda s: jaxrb.torque_free_flow(jnp.asarray(INERTIA), s, ts))(
        jaxrb.make_state(omega=omega0)
    )
    unit = flow.quat / jnp.linalg.norm(flow.quat, axis=-1, keepdims=True)
    full_error = at_end(
        error_against(
            flow.omega[:, -1] @ Q.T, jaxrb.quat_multiply(unit[:, -1], turned), omega0 @ Q.T
        )
    )
    save_errors = [error_against(flow.omega[:, k], unit[:, k], omega0) for k in range(SAVES)]

    def saves_error(omega, quat):
        return max(e(omega[:, k], quat[:, k]) for k, e in enumerate(save_errors))

    cases = (  # (label, scene, initial states, save times, error of (omega, quat))
        ("inertia with products", jaxrb.Scene(body), jaxrb.make_state(
            quat=jnp.broadcast_to(turned, (n, 4)), omega=omega0 @ Q.T), ts[jnp.array([0, -1])],
            full_error),
        (f"{SAVES} saves", scene_for(jnp.float64), jaxrb.make_state(omega=omega0), ts,
            saves_error),
    )  # fmt: skip
    rows = []
    for label, scene, states0, times, error in cases:
        for way, solver in _solvers("Dopri8").items():

            def run(states0, solver=solver, scene=scene, times=times):
                return jaxrb.simulate(
                    scene, states0, times, solver=solver, rtol=GRAD_TOL, atol=GRAD_TOL,
                    max_steps=10**5, throw=False,
                )  # fmt: skip

            timed = C.time_jax(jax.jit(run), states0)
            rows.append(_row(timed, n, f"{way}, Dopri8, {label}", "float64", GRAD_TOL, error, True))
    tangent = jax.random.normal(jax.random.key(3), (n, 3))
    scene, ends = scene_for(jnp.float64), ts[jnp.array([0, -1])]

    def directional_with(solver):
        def final(w):
            traj = jaxrb.simulate(
                scene, jaxrb.make_state(omega=w), ends, solver=solver, rtol=GRAD_TOL,
                atol=GRAD_TOL, adjoint=dfx.ForwardMode(), throw=False,
            )  # fmt: skip
            return jnp.concatenate([traj.states.quat[:, -1], traj.states.omega[:, -1]], -1)

        return lambda w: jax.jvp(final, (w,), (tangent,))[1]

    label = "forward-mode derivative along a tangent of all omega0"
    return rows + derivative_rows(directional_with, omega0, n, label)


def plot(results_path):
    """Work against precision of a saved run (`b1_fused.json`, `b1_fused_per_member.json`):
    error against us per body, one line per method and dtype; written beside it, the same
    name ending in `.png`."""
    with open(results_path) as f:
        saved = json.load(f)
    rows = [
        C.Row(
            problem="B1",
            method=r["method"],
            dtype=r["dtype"],
            setting=str(r["tol"]),
            n=saved["n"],
            error=r["error"],
            us_per_body=r["us_per_body"],
            compile_s=r["compile_s"] or float("nan"),
            steps=r["steps"],
        )
        for r in saved["rows"]
        if "error" in r
    ]
    path = os.path.splitext(results_path)[0] + ".png"
    sweep = ", one J per member" if results_path.endswith("_per_member.json") else ""
    title = f"B1{sweep}, N = {saved['n']:.0e}, one solve: a step as one kernel ({saved['device']})"
    C.plot_work_precision(rows, title, path)
    print(f"wrote {os.path.abspath(path)}")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1_000_000)
    p.add_argument("--grad-n", type=int, default=100_000, help="bodies of the gradient rows")
    p.add_argument("--no-solve", action="store_true", help="the gradient rows only")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true")
    p.add_argument("--plot", metavar="JSON", help="only draw a saved run's picture")
    p.add_argument(
        "--per-member", action="store_true", help="an inertia sweep instead (one J per member)"
    )
    p.add_argument(
        "--extras",
        action="store_true",
        help="instead: a full inertia tensor, saves between the ends, forward mode",
    )
    a = p.parse_args()
    if a.plot:
        plot(a.plot)
        return
    if jax.default_backend() == "cpu":
        print("b1_fused: no GPU here; simulate does not use the fused step on a CPU")
        return
    name = "b1_fused_gradient.json" if a.no_solve else "b1_fused.json"
    name = "b1_fused_per_member.json" if a.per_member else name
    name = "b1_fused_extras.json" if a.extras else name
    picture = [] if a.no_solve or a.extras else [name.replace(".json", ".png")]
    path, *_ = C.output_paths(p, a.out, [name, *picture], a.force)
    device = C.device_name()
    print(f"device {device}, jax {jax.__version__}, N = {a.n}", flush=True)
    if a.extras:
        rows = extras_rows(a.n)
    elif a.per_member:
        rows = per_member_rows(a.n, a.grad_n)
    else:
        rows = [] if a.no_solve else solve_rows(a.n)
        rows += gradient_rows(a.grad_n) if a.grad_n else []
    with open(path, "w") as f:
        json.dump(dict(device=device, n=a.n, grad_n=a.grad_n, rows=rows), f, indent=1)
    print(f"wrote {os.path.abspath(path)}")
    if rows and not (a.no_solve or a.extras):
        plot(path)


if __name__ == "__main__":
    main()
