# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""B1: torque-free asymmetric body, I = (1, 2, 3), omega0 = (a, 0, c), a ~ U(0.5, 1.5),
c ~ U(1, 2), q0 = identity, T = 20, batch N.

Error = worst body's max(|omega(T) - exact| / |omega0|, geodesic angle of q(T) vs reference);
exact omega from `jaxrb.analytic.asymmetric_top` (Jacobi elliptic functions), reference attitude
from `jaxrb.simulate` with diffrax Dopri8 at rtol = atol = 1e-13 in float64 (cross-checked
against the exact flow `jaxrb.torque_free_flow` when present).

Methods: `jaxrb.simulate` with a batched state (the batch as one diffrax solve with
batch-wide step control, one device), with its reverse-mode gradient over all N bodies and a
forward-mode derivative; `simulate_batch` (the same solve, split over devices);
`jax.vmap(jaxrb.simulate)` (each body its own solve), also with default settings and with
Dopri8's stages written out (`jaxrb.unrolled_solver`); plain
diffrax on a hand-written 7-number right-hand side (quaternion + body omega), vmapped and as
one batched solve, with the same solvers and tolerances; a fixed-step jnp RK4; the exact
flow; scipy and MuJoCo.

Run: python -m benchmarks.b1_torque_free --n 1000 --dtype both --out bench_out
"""

import argparse
import math
import os

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402
from jaxrb._batched import batch_rms_norm, simulate_batch  # noqa: E402
from jaxrb.analytic import asymmetric_top  # noqa: E402

try:
    from . import _common as C
except ImportError:  # run as a script
    import _common as C  # type: ignore

T_END = 20.0
INERTIA = (1.0, 2.0, 3.0)


def initial_omegas(n, seed=0):
    k1, k2 = jax.random.split(jax.random.key(seed))
    a = jax.random.uniform(k1, (n,), minval=0.5, maxval=1.5, dtype=jnp.float64)
    c = jax.random.uniform(k2, (n,), minval=1.0, maxval=2.0, dtype=jnp.float64)
    return jnp.stack([a, jnp.zeros(n), c], -1)


def scene_for(dtype):
    return jaxrb.Scene(jaxrb.RigidBody(jnp.asarray(1.0, dtype), jnp.asarray(INERTIA, dtype)))


def reference_attitude(omega0, tol=1e-13):
    """q(T) from diffrax Dopri8 at rtol = atol = `tol` in float64 (the reference: 1e-13)."""
    return jax.jit(
        jax.vmap(
            lambda w: jaxrb.simulate(
                scene_for(jnp.float64),
                jaxrb.make_state(omega=w),
                jnp.array([0.0, T_END]),
                solver=dfx.Dopri8(),
                rtol=tol,
                atol=tol,
                max_steps=10**6,
                throw=False,
            ).states.quat[-1]
        )
    )(omega0)


def make_errors(omega0):
    """Error function for results (omega_T (N,3), quat_T (N,4)) in any dtype."""
    inertia = jnp.asarray(INERTIA)
    w_exact = jax.vmap(lambda w: asymmetric_top(T_END, inertia, w))(omega0)
    ref = reference_attitude(omega0)
    return error_against(w_exact, ref, omega0), w_exact, ref


def error_against(w_exact, ref, omega0):
    """The error function of results (omega_T (N,3), quat_T (N,4)), any dtype, against the
    final rates `w_exact` and unit attitudes `ref`: the worst body's max(relative omega
    error, geodesic angle)."""
    w0n = jnp.linalg.norm(omega0, axis=-1)

    def error(omega_T, quat_T):
        omega_T = jnp.asarray(omega_T, jnp.float64)
        quat_T = jnp.asarray(quat_T, jnp.float64)
        quat_T = quat_T / jnp.linalg.norm(quat_T, axis=-1, keepdims=True)
        e_w = jnp.linalg.norm(omega_T - w_exact, axis=-1) / w0n
        e_q = jaxrb.quat_geodesic_angle(quat_T, ref)
        return float(jnp.max(jnp.maximum(e_w, e_q)))

    return error


def rk4_fixed(scene, n_steps):
    """A fixed-step RK4 written directly in jnp, vmapped: the hand-written baseline."""
    h = T_END / n_steps

    def one(state):
        f = lambda y: jaxrb.vector_field(0.0, y, scene)  # noqa: E731
        ax = lambda y, k, c: jax.tree.map(lambda a, b: a + c * b, y, k)  # noqa: E731

        def step(_, y):
            k1 = f(y)
            k2 = f(ax(y, k1, 0.5 * h))
            k3 = f(ax(y, k2, 0.5 * h))
            k4 = f(ax(y, k3, h))
            return jax.tree.map(
                lambda y_, a, b, c, d: y_ + (h / 6) * (a + 2 * b + 2 * c + d), y, k1, k2, k3, k4
            )

        return jax.lax.fori_loop(0, n_steps, step, state)

    return jax.jit(jax.vmap(one))


def run(n=1000, dtypes=("float64", "float32"), n_python=10, quick=False, scaling=True, large=False):
    """The rows of B1 at batch size `n`. With `large` (N = 1e5 to 1e6, on a GPU) only the
    methods that treat the batch as arrays: the batched solve with its gradients, fixed-step
    RK4 and the exact flow; no vmap of adaptive solves, per-body loops or peers."""
    rows: list[C.Row] = []
    omega0 = initial_omegas(n)
    error, w_exact, ref = make_errors(omega0)
    ts64 = jnp.array([0.0, T_END])

    for dname in dtypes:
        dt = jnp.float64 if dname == "float64" else jnp.float32
        scene = scene_for(dt)
        states0 = jaxrb.make_state(omega=omega0.astype(dt))
        ts = ts64.astype(dt)
        # simulate_batch: the batch as one diffrax Dopri8 solve per device
        tols = [1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11] if dname == "float64" else [1e-4, 1e-5, 1e-6]
        if quick:
            tols = tols[1::2]
        rows += (
            []
            if large
            else C.lean_rows(
                "B1",
                scene,
                states0,
                ts,
                tols,
                dname,
                lambda tr: error(tr.states.omega[:, -1], tr.states.quat[:, -1]),
            )
        )
        # jaxrb.simulate with a batched state (one solve, one device), its gradients
        rows += batched_rows(scene, states0, ts, dname, error, quick, large)
        # vmap of diffrax Dopri8 / Tsit5 through jaxrb.simulate, and plain diffrax beside it
        vmap_tols = (
            [1e-7, 1e-8, 1e-9, 5e-10, 3e-10, 1e-10, 1e-11] if dname == "float64" else [1e-5, 1e-6]
        )
        if quick:
            vmap_tols = vmap_tols[1::2]
        for solver_name, solver in (
            ()
            if large
            else (
                ("Dopri8", dfx.Dopri8()),
                ("Tsit5", dfx.Tsit5()),
                ("Dopri8 written out", jaxrb.unrolled_solver(dfx.Dopri8())),
            )
        ):
            fn = jax.jit(
                jax.vmap(
                    lambda s, tol, solver=solver: jaxrb.simulate(
                        scene, s, ts, solver=solver, rtol=tol, atol=tol, throw=False
                    ),
                    in_axes=(0, None),
                )
            )
            for tol in vmap_tols:
                first, best, tr = C.time_jax(fn, states0, jnp.asarray(tol, dt))
                rows.append(
                    C.Row(
                        "B1",
                        f"diffrax {solver_name}, vmap(jaxrb.simulate)",
                        dname,
                        f"tol {tol:.0e}",
                        n,
                        error(tr.states.omega[:, -1], tr.states.quat[:, -1]),
                        best / n * 1e6,
                        first - best,
                        float(jnp.mean(tr.num_steps)),
                    )
                )
            rows += plain_rows(solver_name, solver, omega0.astype(dt), ts, vmap_tols, dname, error)
        if dname == "float64" and not large:  # the default rtol (1e-8) is for float64
            for label, fn in (
                (
                    "vmap(jaxrb.simulate), default settings (Tsit5, tol 1e-8)",
                    jax.jit(jax.vmap(lambda s: jaxrb.simulate(scene, s, ts))),
                ),
                (
                    "jaxrb.simulate, batched state, default settings (Dopri8, tol 1e-8)",
                    jax.jit(lambda s: jaxrb.simulate(scene, s, ts)),
                ),
            ):
                first, best, tr = C.time_jax(fn, states0)
                rows.append(
                    C.Row(
                        "B1",
                        label,
                        dname,
                        "default",
                        n,
                        error(tr.states.omega[:, -1], tr.states.quat[:, -1]),
                        best / n * 1e6,
                        first - best,
                        float(jnp.mean(tr.num_steps)),
                    )
                )
        # fixed-step jnp RK4
        for n_steps in [250, 500, 1000, 2000] if not quick else [500, 2000]:
            fn = rk4_fixed(scene, n_steps)
            first, best, out = C.time_jax(fn, states0)
            rows.append(
                C.Row(
                    "B1",
                    "jnp RK4 fixed step, vmap",
                    dname,
                    f"h {T_END / n_steps:.3g}",
                    n,
                    error(out.omega, out.quat),
                    best / n * 1e6,
                    first - best,
                    float(n_steps),
                )
            )
        # exact flow (if available)
        if hasattr(jaxrb, "torque_free_flow") or _has_exact_flow():
            from jaxrb._exact_flow import torque_free_flow

            fn = jax.jit(lambda s: torque_free_flow(jnp.asarray(INERTIA, dt), s, T_END))
            first, best, out = C.time_jax(fn, states0)
            # the 1e-13 reference attitude is itself off by ~1e-12 at T = 20, the size of
            # this row's error: compare with a finer reference too
            fine = reference_attitude(omega0, 1e-15)
            q_out = jnp.asarray(out.quat, jnp.float64)
            q_out = q_out / jnp.linalg.norm(q_out, axis=-1, keepdims=True)
            e_fine = float(jnp.max(jaxrb.quat_geodesic_angle(q_out, fine)))
            rows.append(
                C.Row(
                    "B1",
                    "jaxrb exact flow (torque_free_flow)",
                    dname,
                    "-",
                    n,
                    error(out.omega, out.quat),
                    best / n * 1e6,
                    first - best,
                    math.nan,
                    f"no time stepping; attitude vs a Dopri8 tol-1e-15 reference: {e_fine:.1e}",
                )
            )

    if large:
        return rows, []
    # scipy peers (float64, a subset of bodies, per-body Python loop)
    rows += scipy_rows(omega0[:n_python], w_exact[:n_python], ref[:n_python], quick)
    rows += mujoco_rows(omega0, error, quick)
    scale_pts = scaling_points(quick) if scaling else []
    return rows, scale_pts


LARGE_CHECKPOINTS = 100  # reverse-mode checkpoints of the batched solve with `large`
GRAD_TOL = 5e-10  # the batched Dopri8's cheapest tolerance with error <= 1e-8 here


def _observable(weights, traj):
    """A weighted sum of every body's final attitude and angular velocity."""
    return jnp.sum(weights[:, :4] * traj.states.quat[:, -1]) + jnp.sum(
        weights[:, 4:] * traj.states.omega[:, -1]
    )


def batched_rows(scene, states0, ts, dname, error, quick, large=False):
    """`jaxrb.simulate` on the batched state (one diffrax solve, batch-wide step control) over
    tolerances with Dopri8 and Tsit5; in float64 also the reverse-mode gradient of a weighted
    sum of all final states w.r.t. all N initial omegas (`jax.grad`, diffrax's default
    RecursiveCheckpointAdjoint), a forward-mode directional derivative (`jax.jvp`,
    `diffrax.ForwardMode()`) and, for comparison, the reverse gradient through
    `vmap(jaxrb.simulate)`, all at `GRAD_TOL` with Dopri8."""
    n = states0.omega.shape[0]
    dt = ts.dtype
    rows = []
    if dname == "float64":
        sweeps = (
            ("Dopri8", dfx.Dopri8(), [1e-7, 1e-8, 1e-9, 5e-10, 3e-10, 1e-10, 1e-11]),
            ("Tsit5", dfx.Tsit5(), [1e-6, 1e-7, 1e-8, 1e-9, 1e-10]),
        )
    else:
        sweeps = (
            ("Dopri8", dfx.Dopri8(), [1e-5, 1e-6]),
            ("Tsit5", dfx.Tsit5(), [1e-4, 1e-5, 1e-6]),
        )
    for name, solver, tols in sweeps:
        fn = jax.jit(
            lambda s, tol, solver=solver: jaxrb.simulate(
                scene, s, ts, solver=solver, rtol=tol, atol=tol, throw=False
            )
        )
        for tol in tols[1::2] if quick else tols:
            first, best, tr = C.time_jax(fn, states0, jnp.asarray(tol, dt))
            rows.append(
                C.Row(
                    "B1",
                    f"jaxrb.simulate, batched state (one solve), {name}",
                    dname,
                    f"tol {tol:.0e}",
                    n,
                    error(tr.states.omega[:, -1], tr.states.quat[:, -1]),
                    best / n * 1e6,
                    first - best,
                    float(tr.num_steps[0]),
                )
            )
    if dname != "float64":
        return rows
    weights = jax.random.normal(jax.random.key(0), (n, 7), dt)
    tol = jnp.asarray(GRAD_TOL, dt)

    def run(omega, adjoint=None):
        return jaxrb.simulate(
            scene,
            jaxrb.make_state(omega=omega),
            ts,
            solver=dfx.Dopri8(),
            rtol=tol,
            atol=tol,
            adjoint=adjoint,
            throw=False,
        )

    def run_vmap(omega):
        return jax.vmap(
            lambda w: jaxrb.simulate(
                scene,
                jaxrb.make_state(omega=w),
                ts,
                solver=dfx.Dopri8(),
                rtol=tol,
                atol=tol,
                throw=False,
            )
        )(omega)

    tr = jax.jit(run)(states0.omega)
    err = error(tr.states.omega[:, -1], tr.states.quat[:, -1])
    tangent = jax.random.normal(jax.random.key(1), states0.omega.shape, dt)
    for label, fn, args in (
        (
            "jaxrb.simulate, batched, Dopri8: reverse gradient wrt all N omega0 (jax.grad)"
            + (f", {LARGE_CHECKPOINTS} checkpoints" if large else ""),
            # diffrax's default checkpoints for max_steps 1e5 hold ~1300 copies of the
            # batch: 73 GiB at N = 1e6; a fixed number of checkpoints fits
            jax.jit(
                jax.grad(
                    lambda w: _observable(
                        weights,
                        run(
                            w, dfx.RecursiveCheckpointAdjoint(LARGE_CHECKPOINTS) if large else None
                        ),
                    )
                )
            ),
            (states0.omega,),
        ),
        (
            "jaxrb.simulate, batched, Dopri8: forward derivative (jax.jvp, ForwardMode)",
            jax.jit(
                lambda w, v: jax.jvp(
                    lambda x: _observable(weights, run(x, dfx.ForwardMode())), (w,), (v,)
                )
            ),
            (states0.omega, tangent),
        ),
        (
            "vmap(jaxrb.simulate), Dopri8: reverse gradient wrt all N omega0 (jax.grad)",
            jax.jit(jax.grad(lambda w: _observable(weights, run_vmap(w)))),
            (states0.omega,),
        ),
    ):
        if (quick or large) and "vmap" in label:
            continue
        try:
            first, best, _ = C.time_jax(fn, *args)
        except jax.errors.JaxRuntimeError as e:  # out of device memory at large N
            print(f"{label}: {str(e)[:200]}")
            continue
        rows.append(
            C.Row(
                "B1",
                label,
                dname,
                f"tol {GRAD_TOL:.0e}",
                n,
                err,
                best / n * 1e6,
                first - best,
                float(tr.num_steps[0]) if "batched" in label else math.nan,
                "error: the forward solution's",
            )
        )
    return rows


def plain_rhs(inertia):
    """The torque-free body's 7-number right-hand side written by hand: (q_dot, omega_dot)
    with q_dot = 1/2 q (x) (0, omega), Euler's equations in principal axes; any leading axes."""

    def rhs(t, y, args):
        q, w = y
        dw = -jnp.cross(w, inertia * w) / inertia
        q0, q1, q2, q3 = jnp.moveaxis(q, -1, 0)
        w1, w2, w3 = jnp.moveaxis(w, -1, 0)
        dq = 0.5 * jnp.stack(
            [
                -q1 * w1 - q2 * w2 - q3 * w3,
                q0 * w1 + q2 * w3 - q3 * w2,
                q0 * w2 - q1 * w3 + q3 * w1,
                q0 * w3 + q1 * w2 - q2 * w1,
            ],
            -1,
        )
        return dq, dw

    return rhs


def members_first_rms_norm(tree):
    """The worst body's RMS norm for leaves with the body axis first, (N, ...): the plain
    batched solve's norm (jaxrb's own solve keeps the body axis last)."""
    return batch_rms_norm(tree, member_axis=0)


def plain_solve(solver, omega, ts, tol, norm=None):
    """Plain diffrax on `plain_rhs` from the identity attitude with body omega `omega` ((3,),
    or (N, 3) as one solve, then give `norm`, e.g. the worst body's RMS), saving at ts[-1]
    only: (omega_T, quat_T, accepted steps)."""
    rhs = plain_rhs(jnp.asarray(INERTIA, omega.dtype))
    quat = jnp.zeros(omega.shape[:-1] + (4,), omega.dtype).at[..., 0].set(1.0)
    kwargs = {} if norm is None else {"norm": norm}
    sol = dfx.diffeqsolve(
        dfx.ODETerm(rhs),
        solver,
        ts[0],
        ts[-1],
        None,
        (quat, omega),
        saveat=dfx.SaveAt(t1=True),
        stepsize_controller=dfx.PIDController(rtol=tol, atol=tol, **kwargs),
        max_steps=100_000,
        throw=False,
    )
    return sol.ys[1][-1], sol.ys[0][-1], sol.stats["num_accepted_steps"]


def plain_rows(solver_name, solver, omega0, ts, tols, dname, error):
    """Plain diffrax on `plain_rhs`, saving at t1 only: vmapped (each body its own solve) and
    as one solve of the whole batch with the worst body's RMS norm in the PIDController."""
    n = omega0.shape[0]
    dt = omega0.dtype

    def solve(omega, tol, norm):
        return plain_solve(solver, omega, ts, tol, norm)

    rows = []
    for label, fn in (
        (
            f"plain diffrax {solver_name}, hand-written rhs, vmap",
            jax.jit(jax.vmap(lambda w, tol: solve(w, tol, None), in_axes=(0, None))),
        ),
        (
            f"plain diffrax {solver_name}, hand-written rhs, one solve (batch norm)",
            jax.jit(lambda w, tol: solve(w, tol, members_first_rms_norm)),
        ),
    ):
        for tol in tols:
            first, best, (w, q, steps) = C.time_jax(fn, omega0, jnp.asarray(tol, dt))
            rows.append(
                C.Row(
                    "B1",
                    label,
                    dname,
                    f"tol {tol:.0e}",
                    n,
                    error(w, q),
                    best / n * 1e6,
                    first - best,
                    float(jnp.mean(steps)),
                )
            )
    return rows


def _has_exact_flow():
    try:
        import jaxrb._exact_flow  # noqa: F401

        return True
    except ImportError:
        return False


def scipy_rows(omega0, w_exact, ref, quick):
    from scipy.integrate import solve_ivp

    J = np.asarray(INERTIA)

    def rhs(t, y):
        q, w = y[:4], y[4:7]
        dw = -np.cross(w, J * w) / J
        q0, q1, q2, q3 = q
        w1, w2, w3 = w
        dq = 0.5 * np.array(
            [
                -q1 * w1 - q2 * w2 - q3 * w3,
                q0 * w1 + q2 * w3 - q3 * w2,
                q0 * w2 - q1 * w3 + q3 * w1,
                q0 * w3 + q1 * w2 - q2 * w1,
            ]
        )
        return np.concatenate([dq, dw, y[10:13], np.zeros(3)])  # translation: pos, vel

    rows = []
    n = omega0.shape[0]
    w0 = np.asarray(omega0)
    for method, tols in (("DOP853", [1e-7, 1e-9, 1e-11]), ("RK45", [1e-7, 1e-9])):
        for tol in tols if not quick else tols[:1]:

            def loop():
                outs, steps = [], 0
                for i in range(n):
                    y0 = np.concatenate([[1.0, 0, 0, 0], w0[i], np.zeros(6)])
                    sol = solve_ivp(rhs, (0, T_END), y0, method=method, rtol=tol, atol=tol)
                    outs.append(sol.y[:, -1])
                    steps += sol.t.size - 1
                return np.array(outs), steps / n

            sec, (out, steps) = C.time_python(loop)
            q = out[:, :4] / np.linalg.norm(out[:, :4], axis=-1, keepdims=True)
            e_w = np.linalg.norm(out[:, 4:7] - np.asarray(w_exact), axis=-1) / np.linalg.norm(
                w0, axis=-1
            )
            e_q = np.asarray(jaxrb.quat_geodesic_angle(jnp.asarray(q), ref))
            rows.append(
                C.Row(
                    "B1",
                    f"scipy solve_ivp {method} (loop)",
                    "float64",
                    f"tol {tol:.0e}",
                    n,
                    float(np.max(np.maximum(e_w, e_q))),
                    sec / n * 1e6,
                    math.nan,
                    steps,
                )
            )
    return rows


def mujoco_runner(omega0, h):
    """A function running the N bodies as free joints in one MuJoCo scene with its C RK4 at
    step `h` to T, returning (omega_T (N, 3), quat_T (N, 4), steps); None without mujoco."""
    try:
        import mujoco
    except ImportError:
        return None
    n = omega0.shape[0]
    xml = (
        f"<mujoco><option gravity='0 0 0' integrator='RK4' timestep='{h}'/><worldbody>"
        + "".join(
            f"<body><freejoint/><inertial pos='0 0 0' mass='1' diaginertia='{INERTIA[0]} "
            f"{INERTIA[1]} {INERTIA[2]}'/></body>"
            for _ in range(n)
        )
        + "</worldbody></mujoco>"
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    n_steps = int(round(T_END / h))

    def go():
        mujoco.mj_resetData(model, data)
        qvel = np.zeros((n, 6))
        qvel[:, 3:] = np.asarray(omega0)  # free-joint angular velocity: body (local) frame
        data.qvel[:] = qvel.ravel()
        for _ in range(n_steps):
            mujoco.mj_step(model, data)
        qpos = data.qpos.reshape(n, 7)
        return data.qvel.reshape(n, 6)[:, 3:].copy(), qpos[:, 3:].copy(), n_steps

    return go


def mujoco_rows(omega0, error, quick):
    n = omega0.shape[0]
    rows = []
    for h in [0.02, 0.01, 0.005, 0.0025] if not quick else [0.01]:
        go = mujoco_runner(omega0, h)
        if go is None:
            return [
                C.Row(
                    "B1",
                    "MuJoCo C (not installed: pip install jaxrb[bench])",
                    "float64",
                    "-",
                    0,
                    math.nan,
                    math.nan,
                    math.nan,
                )
            ]
        sec, (omega_T, quat_T, n_steps) = C.time_python(go)
        import mujoco

        rows.append(
            C.Row(
                "B1",
                "MuJoCo C RK4, N bodies in one scene",
                "float64",
                f"h {h:g}",
                n,
                error(omega_T, quat_T),
                sec / n * 1e6,
                math.nan,
                float(n_steps),
                f"mujoco {mujoco.__version__}",
            )
        )
    return rows


def scaling_points(quick):
    """us/body vs N for simulate_batch (Dopri8, tol 1e-10) and vmapped Dopri8 (tol 1e-9),
    float64."""
    pts = []
    scene = scene_for(jnp.float64)
    ts = jnp.array([0.0, T_END])
    sizes = [1, 10, 100, 1000, 10000, 100000] if not quick else [100, 1000]
    for n in sizes:
        s = jaxrb.make_state(omega=initial_omegas(n, seed=1))
        for label, devs in C.lean_variants(scene, n):
            f_lean = jax.jit(
                lambda s: simulate_batch(
                    scene,
                    s,
                    ts,
                    rtol=1e-10,
                    atol=1e-10,
                    solver=dfx.Dopri8(),
                    throw=False,
                    devices=devs,
                )
            )
            _, best, _ = C.time_jax(f_lean, s, repeats=2)
            label = label.replace("Dopri8", "Dopri8 tol 1e-10").replace(" (default)", "")
            pts.append((label, n, best / n * 1e6))
        f_dfx = jax.jit(
            jax.vmap(
                lambda s: jaxrb.simulate(
                    scene, s, ts, solver=dfx.Dopri8(), rtol=1e-9, atol=1e-9, throw=False
                )
            )
        )
        if n > 10000:  # ~0.5 ms per body: a minute per call at N = 1e5
            continue
        _, best, _ = C.time_jax(f_dfx, s, repeats=2)
        pts.append(("diffrax Dopri8 vmap tol 1e-9", n, best / n * 1e6))
    return pts


BATCHED = "jaxrb.simulate, batched state (one solve), Dopri8"


def targets(rows, bound=1e-8):
    """The targets as ratios between rows of this run (float64, each on one device): the
    cheapest row of each method with error <= `bound` against the batched solve's, and the
    default `vmap(jaxrb.simulate)` against plain diffrax with the same solver and tolerance."""

    def cheapest(method):
        ok = [r for r in rows if r.method == method and r.dtype == "float64" and r.error <= bound]
        return min(ok, key=lambda r: r.us_per_body, default=None)

    batched = cheapest(BATCHED)
    if batched is None:
        return ""
    lines = [
        f"Cheapest rows with error <= {bound:g} (float64), against {BATCHED} "
        f"({batched.setting}, error {batched.error:.2e}, {batched.us_per_body:.3g} us/body):",
        "",
    ]
    for method in (
        "jaxrb.simulate, batched state (one solve), Tsit5",
        "plain diffrax Dopri8, hand-written rhs, vmap",
        "plain diffrax Tsit5, hand-written rhs, vmap",
        "diffrax Dopri8, vmap(jaxrb.simulate)",
        "diffrax Tsit5, vmap(jaxrb.simulate)",
        "diffrax Dopri8 written out, vmap(jaxrb.simulate)",
        "jnp RK4 fixed step, vmap",
        "MuJoCo C RK4, N bodies in one scene",
        "jaxrb exact flow (torque_free_flow)",
    ):
        r = cheapest(method)
        if r is not None:
            lines.append(
                f"- {method}: {r.setting}, error {r.error:.2e}, {r.us_per_body:.3g} us/body: "
                f"{r.us_per_body / batched.us_per_body:.1f}x the batched solve's time"
            )
    grad = [r for r in rows if r.method.startswith("jaxrb.simulate, batched, Dopri8: reverse")]
    mujoco = cheapest("MuJoCo C RK4, N bodies in one scene")
    if grad:
        g = grad[0].us_per_body
        line = (
            f"- the batched solve's reverse gradient over all N: {g:.3g} us/body, "
            f"{g / batched.us_per_body:.1f}x the cheapest forward solve's time"
        )
        if mujoco is not None:
            line += f"; MuJoCo's row takes {mujoco.us_per_body / g:.1f}x as long"
        lines.append(line)
    default = [r for r in rows if r.method.startswith("vmap(jaxrb.simulate), default")]
    plain = [
        r
        for r in rows
        if r.method == "plain diffrax Tsit5, hand-written rhs, vmap"
        and r.dtype == "float64"
        and r.setting == "tol 1e-08"
    ]
    if default and plain:
        d, q = default[0], plain[0]
        lines.append(
            f"- default path, vmap(jaxrb.simulate) (error {d.error:.2e}, {d.us_per_body:.1f} "
            f"us/body) against plain diffrax Tsit5 at tol 1e-8 (error {q.error:.2e}, "
            f"{q.us_per_body:.1f} us/body): {d.us_per_body / q.us_per_body:.2f}x"
        )
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--dtype", choices=["float64", "float32", "both"], default="both")
    p.add_argument("--out", default=None, help="directory for the markdown table and PNGs")
    p.add_argument("--quick", action="store_true", help="fewer settings (smoke run)")
    p.add_argument("--no-scaling", action="store_true")
    p.add_argument(
        "--large",
        action="store_true",
        help="only the array methods (batched solve and its gradients, RK4, exact flow): "
        "for N = 1e5 to 1e6 on a GPU",
    )
    a = p.parse_args(argv)
    dtypes = ("float64", "float32") if a.dtype == "both" else (a.dtype,)
    rows, pts = run(a.n, dtypes, quick=a.quick, scaling=not a.no_scaling, large=a.large)
    dev = C.device_name()
    table = C.markdown_table(rows, dev)
    summary = targets(rows)
    print(table)
    print(summary)
    for m, n, t in pts:
        print(f"scaling: {m:35s} N={n:6d} {t:9.2f} us/body")
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        with open(os.path.join(a.out, "b1.md"), "w") as f:
            f.write("## B1 torque-free asymmetric body\n\n" + table + "\n" + summary)
        C.plot_work_precision(
            rows, f"B1 torque-free, N={a.n}, {dev}", os.path.join(a.out, "b1.png")
        )
        if pts:
            C.plot_scaling(pts, f"B1 batch scaling, {dev}", os.path.join(a.out, "b1_scaling.png"))
    return rows, pts


if __name__ == "__main__":
    main()
