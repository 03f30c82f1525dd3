# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""Work-precision sweep shared by B2 and B3: the same scene and initial states through every
method, errors against a float64 diffrax Dopri8 reference at rtol = atol = 1e-13."""

import math

import diffrax as dfx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

import jaxrb
from jaxrb._splitting import simulate_splitting

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore


def cast(tree, dtype):
    return jax.tree.map(
        lambda x: (
            x.astype(dtype) if hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jnp.floating) else x
        ),
        tree,
    )


def reference(scene, states0, ts):
    return jax.jit(
        jax.vmap(
            lambda s: (
                jaxrb.simulate(
                    scene,
                    s,
                    ts,
                    solver=dfx.Dopri8(),
                    rtol=1e-13,
                    atol=1e-13,
                    max_steps=1_000_000,
                    throw=False,
                ).states
            )
        )
    )(states0)


def sweep(problem, make_scene, states0, ts, error, *, dtypes, quick, splitting_dts=(), n_python=5):
    """Rows for: lean DOP853, vmap(simulate) Dopri8 and Tsit5, the splitting (if dts given),
    scipy solve_ivp DOP853/RK45 on a jitted jaxrb right-hand side (a few bodies)."""
    rows = []
    n = states0.omega.shape[0]
    for dname in dtypes:
        dt = jnp.float64 if dname == "float64" else jnp.float32
        scene = cast(make_scene(), dt)
        s0 = cast(states0, dt)
        tsd = ts.astype(dt)
        tols = [1e-6, 1e-8, 1e-10, 1e-12] if dname == "float64" else [1e-4, 1e-5, 1e-6]
        if quick:
            tols = tols[::2]
        rows += C.lean_rows(problem, scene, s0, tsd, tols, dname, lambda tr: error(tr.states))
        for solver_name, solver in (("Dopri8", dfx.Dopri8()), ("Tsit5", dfx.Tsit5())):
            fn = jax.jit(
                jax.vmap(
                    lambda s, tol, solver=solver: jaxrb.simulate(
                        scene,
                        s,
                        tsd,
                        solver=solver,
                        rtol=tol,
                        atol=tol,
                        max_steps=1_000_000,
                        throw=False,
                    ),
                    in_axes=(0, None),
                )
            )
            for tol in tols[1:] if not quick else tols[:1]:
                first, best, tr = C.time_jax(fn, s0, jnp.asarray(tol, dt), repeats=1)
                rows.append(
                    C.Row(
                        problem,
                        f"diffrax {solver_name}, vmap(jaxrb.simulate)",
                        dname,
                        f"tol {tol:.0e}",
                        n,
                        error(tr.states),
                        best / n * 1e6,
                        first - best,
                        float(jnp.mean(tr.num_steps)),
                    )
                )
        for h in splitting_dts if not quick else splitting_dts[:1]:
            fn = jax.jit(jax.vmap(lambda s, h=h: simulate_splitting(scene, s, tsd, dt=h)))
            first, best, tr = C.time_jax(fn, s0, repeats=1)
            rows.append(
                C.Row(
                    problem,
                    "jaxrb Lie-group splitting (order 2)",
                    dname,
                    f"h {h:g}",
                    n,
                    error(tr.states),
                    best / n * 1e6,
                    first - best,
                    float(tr.num_steps[0]),
                )
            )
    rows += scipy_rows(problem, make_scene(), states0, ts, error, n_python, quick)
    return rows


def scipy_rows(problem, scene, states0, ts, error, n_python, quick):
    from scipy.integrate import solve_ivp

    from jaxrb._simulate import _coordinates

    coords = _coordinates(scene)
    rows = []
    sub = jax.tree.map(lambda x: x[:n_python], states0)
    for method, tols in (("DOP853", [1e-8, 1e-10]), ("RK45", [1e-8])):
        for tol in tols if not quick else tols[:1]:

            def one(i):
                s0 = jax.tree.map(lambda x: x[i], sub)
                y0 = coords.reduce(s0)
                flat0, unravel = jax.flatten_util.ravel_pytree(y0)
                f = jax.jit(
                    lambda t, y: jax.flatten_util.ravel_pytree(
                        coords.coordinate_rates(
                            unravel(y), jaxrb.vector_field(t, coords.expand(unravel(y), s0), scene)
                        )
                    )[0]
                )
                f(0.0, flat0)
                rhs = lambda t, y: np.asarray(f(t, y))  # noqa: E731
                import time

                t0 = time.perf_counter()
                sol = solve_ivp(
                    rhs,
                    (float(ts[0]), float(ts[-1])),
                    np.asarray(flat0),
                    method=method,
                    rtol=tol,
                    atol=tol,
                    t_eval=np.asarray(ts),
                )
                sec = time.perf_counter() - t0
                ys = jax.vmap(lambda y: coords.expand(unravel(y), s0))(jnp.asarray(sol.y.T))
                return sec, ys, sol.t.size

            outs = [one(i) for i in range(n_python)]
            sec = sum(o[0] for o in outs)
            states = jax.tree.map(lambda *xs: jnp.stack(xs), *[o[1] for o in outs])
            rows.append(
                C.Row(
                    problem,
                    f"scipy solve_ivp {method} (jitted jaxrb rhs, loop)",
                    "float64",
                    f"tol {tol:.0e}",
                    n_python,
                    error(states, subset=n_python),
                    sec / n_python * 1e6,
                    math.nan,
                    math.nan,
                )
            )
    return rows
