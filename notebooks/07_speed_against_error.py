# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 07 — Speed against error: a small work-precision study of B1
#
# **The timings in this notebook are illustrative only**: a small batch, few repeats, on whatever
# machine runs the notebook (often a shared CPU). The real numbers, with compile time separated,
# larger batches, float32, more methods and peers (MuJoCo), come from `benchmarks/`
# (`python -m benchmarks.b1_torque_free --n 1000 --dtype both --out bench_out`).
#
# Problem B1 (benchmarks/README.md): a torque-free asymmetric body, I = (1, 2, 3), omega0 = (a, 0, c) with
# a ~ U(0.5, 1.5), c ~ U(1, 2), q0 = identity, T = 20 s. Error = worst body's
# max(|omega(T) - omega_exact(T)| / |omega0|, geodesic angle of q(T) vs a reference), with the exact
# elliptic-function omega (`jaxrb.analytic.asymmetric_top`) and a tolerance-1e-13 float64 reference
# attitude. Cost = steady-state wall time per body (compilation excluded: one warm-up call first).
#
# Methods, each at a few tolerances:
# - `jax.vmap(jaxrb.simulate)` (diffrax Tsit5 with a PID controller, per-body steps);
# - the lean batched DOP853 `jaxrb._batched.simulate_batch` (one batch-wide step-size loop);
# - scipy `solve_ivp(method="DOP853")` with a NumPy right-hand side, body by body.

# %%
import jax

jax.config.update("jax_enable_x64", True)
import time

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import scipy.integrate

import jaxrb
from jaxrb.analytic import asymmetric_top

try:
    from jaxrb._batched import simulate_batch
except ImportError:  # the fast batched path is optional
    simulate_batch = None

dev = jax.devices()[0]
print(f"device: {dev.platform}:{getattr(dev, 'device_kind', '?')}, jax {jax.__version__}, float64")

N, T_END = 64, 20.0
INERTIA = jnp.array([1.0, 2.0, 3.0])
k1, k2 = jax.random.split(jax.random.key(0))
omega0 = jnp.stack(
    [
        jax.random.uniform(k1, (N,), minval=0.5, maxval=1.5),
        jnp.zeros(N),
        jax.random.uniform(k2, (N,), minval=1.0, maxval=2.0),
    ],
    -1,
)
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, INERTIA))
states0 = jaxrb.State(
    jnp.zeros((N, 3)), jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (N, 1)), jnp.zeros((N, 3)), omega0
)
ts = jnp.array([0.0, T_END])


def best_time(fn, *args, repeat=3):
    jax.block_until_ready(fn(*args))  # warm-up (compiles on the first tolerance only)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return best


# %% [markdown]
# ## Reference and error measure
# omega(T) is exact (Jacobi elliptic functions). The reference attitude is the batched DOP853 at
# rtol = atol = 1e-13; its omega agrees with the exact one to ~1e-12, which bounds how far it can be
# trusted.

# %%
w_exact = jax.vmap(lambda w: asymmetric_top(T_END, INERTIA, w))(omega0)


@jax.jit
def run_vmap(tol):
    sim = lambda s: jaxrb.simulate(scene, s, ts, rtol=tol, atol=tol, max_steps=200_000)  # noqa: E731
    tr = jax.vmap(sim)(states0)
    return tr.states.omega[:, -1], tr.states.quat[:, -1]


if simulate_batch is not None:

    @jax.jit
    def run_batch(tol):
        tr = simulate_batch(scene, states0, ts, rtol=tol, atol=tol, throw=False)
        return tr.states.omega[:, -1], tr.states.quat[:, -1]

    w_ref, q_ref = run_batch(jnp.asarray(1e-13))
else:
    w_ref, q_ref = run_vmap(jnp.asarray(1e-13))
ref_err = float(jnp.max(jnp.linalg.norm(w_ref - w_exact, axis=-1)))
print(f"reference omega vs exact: {ref_err:.1e} rad/s")
assert ref_err < 1e-10
w0n = jnp.linalg.norm(omega0, axis=-1)


def b1_error(w_T, q_T):
    w_T, q_T = jnp.asarray(w_T), jnp.asarray(q_T)
    e_w = jnp.linalg.norm(w_T - w_exact, axis=-1) / w0n
    e_q = jaxrb.quat_geodesic_angle(q_T / jnp.linalg.norm(q_T, axis=-1, keepdims=True), q_ref)
    return float(jnp.max(jnp.maximum(e_w, e_q)))


# %% [markdown]
# ## The sweep

# %%
results = {}
tols = [1e-5, 1e-7, 1e-9, 1e-11]
results["vmap(jaxrb.simulate), Tsit5"] = [
    (best_time(run_vmap, jnp.asarray(tol)) / N, b1_error(*run_vmap(jnp.asarray(tol))), tol)
    for tol in tols
]
if simulate_batch is not None:
    results["simulate_batch (lean DOP853)"] = [
        (best_time(run_batch, jnp.asarray(tol)) / N, b1_error(*run_batch(jnp.asarray(tol))), tol)
        for tol in tols
    ]


I1, I2, I3 = np.asarray(INERTIA)


def rhs_np(t, y):
    q, w = y[:4], y[4:]
    w_dot = np.array(
        [(I2 - I3) * w[1] * w[2] / I1, (I3 - I1) * w[2] * w[0] / I2, (I1 - I2) * w[0] * w[1] / I3]
    )
    q_dot = 0.5 * np.array(
        [
            -q[1:] @ w,
            q[0] * w[0] + q[2] * w[2] - q[3] * w[1],
            q[0] * w[1] + q[3] * w[0] - q[1] * w[2],
            q[0] * w[2] + q[1] * w[1] - q[2] * w[0],
        ]
    )
    return np.concatenate([q_dot, w_dot])


n_py = 4  # scipy runs body by body in Python: a few bodies suffice for the time per body
rows = []
scipy.integrate.solve_ivp(
    rhs_np, (0.0, 1.0), np.r_[1.0, 0, 0, 0, 1.0, 0, 1.0], method="DOP853"
)  # warm-up
for tol in tols:
    t0 = time.perf_counter()
    ys = [
        scipy.integrate.solve_ivp(
            rhs_np,
            (0.0, T_END),
            np.r_[1.0, 0, 0, 0, np.asarray(omega0[i])],
            method="DOP853",
            rtol=tol,
            atol=tol,
        ).y[:, -1]
        for i in range(n_py)
    ]
    per_body = (time.perf_counter() - t0) / n_py
    ys = np.array(ys)
    e_w = np.linalg.norm(ys[:, 4:] - np.asarray(w_exact[:n_py]), axis=-1) / np.asarray(w0n[:n_py])
    e_q = np.asarray(
        jaxrb.quat_geodesic_angle(
            jnp.asarray(ys[:, :4] / np.linalg.norm(ys[:, :4], axis=-1, keepdims=True)), q_ref[:n_py]
        )
    )
    rows.append((per_body, float(np.max(np.maximum(e_w, e_q))), tol))
results[f"scipy DOP853 ({n_py} bodies, NumPy rhs)"] = rows

print(f"{'method':42} {'tol':>7} {'error':>9} {'time/body':>11}")
for name, rs in results.items():
    for t_body, err, tol in rs:
        print(f"{name:42} {tol:7.0e} {err:9.1e} {1e6 * t_body:9.1f} us")

# %%
fig, ax = plt.subplots(figsize=(8, 5))
for (name, rs), m in zip(results.items(), "os^", strict=False):
    t_body, err, tol = map(np.array, zip(*rs, strict=True))
    ax.loglog(t_body, err, m + "-", label=name)
    for x, y, tl in zip(t_body, err, tol, strict=True):
        ax.annotate(f"{tl:.0e}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
ax.set_xlabel("wall time per body (s)  [illustrative: see benchmarks/]")
ax.set_ylabel("B1 error (worst body)")
ax.set_title(f"B1 work-precision, N = {N}, T = {T_END:g} s, on {dev.platform}")
ax.grid(alpha=0.3, which="both")
ax.legend(fontsize="small", loc="upper center")
plt.show()

# Accuracy claims are checked against the exact oracle; timings are not asserted (machine-dependent).
for name, rs in results.items():
    errs = [err for _, err, _ in rs]
    assert errs[-1] < 1e-8, (name, errs)  # tight tolerance: accurate against the exact solution
    assert errs[0] > 10 * errs[-1], (name, errs)  # and the tolerance controls the error
