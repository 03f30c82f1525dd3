# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""B2: heavy symmetric top on a fixed point (Pivot at the tip, gravity), batch N of initial
tilts and spins; T = 2 s; error = worst body's max(geodesic angle of q(t), |omega - ref| /
|omega0|) over the save times, reference diffrax Dopri8 at tolerance 1e-13 (float64).

Run: python -m benchmarks.b2_heavy_top --n 1000 --dtype both --out bench_out
"""

import argparse
import os

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import _common as C, _generic as G
except ImportError:
    import _common as C  # type: ignore
    import _generic as G  # type: ignore

T_END = 2.0


def make_scene():
    body = jaxrb.RigidBody(jnp.asarray(1.0), jnp.array([0.02, 0.02, 0.01]))  # kg m^2 about C
    return jaxrb.Scene(body, forces=(jaxrb.Gravity(),), joint=jaxrb.Pivot((0.0, 0.0, -0.1)))


def initial_states(n, seed=0):
    k1, k2, k3 = jax.random.split(jax.random.key(seed), 3)
    tilt = jax.random.uniform(k1, (n,), minval=0.1, maxval=0.6, dtype=jnp.float64)
    spin = jax.random.uniform(k2, (n,), minval=30.0, maxval=60.0, dtype=jnp.float64)
    wx = jax.random.uniform(k3, (n,), minval=-1.0, maxval=1.0, dtype=jnp.float64)
    q = jaxrb.axis_angle_to_quat(jnp.array([1.0, 0.0, 0.0]), tilt)
    return jaxrb.make_state(quat=q, omega=jnp.stack([wx, jnp.zeros(n), spin], -1))


def run(n=1000, dtypes=("float64", "float32"), quick=False):
    states0 = initial_states(n)
    ts = jnp.linspace(0.0, T_END, 5)
    ref = G.reference(make_scene(), states0, ts)
    w0n = jnp.linalg.norm(states0.omega, axis=-1)

    def error(states, subset=None):
        r = ref if subset is None else jax.tree.map(lambda x: x[:subset], ref)
        w = w0n if subset is None else w0n[:subset]
        q = jnp.asarray(states.quat, jnp.float64)
        e_q = jnp.max(jaxrb.quat_geodesic_angle(q, r.quat), axis=-1)
        e_w = (
            jnp.max(
                jnp.linalg.norm(jnp.asarray(states.omega, jnp.float64) - r.omega, axis=-1), axis=-1
            )
            / w
        )
        return float(jnp.max(jnp.maximum(e_q, e_w)))

    return G.sweep(
        "B2",
        make_scene,
        states0,
        ts,
        error,
        dtypes=dtypes,
        quick=quick,
        splitting_dts=(1e-3, 2.5e-4),
    )


def main(argv=None):
    p = argparse.ArgumentParser(description="B2 heavy top")
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--dtype", choices=["float64", "float32", "both"], default="both")
    p.add_argument("--out", default=None)
    p.add_argument("--quick", action="store_true")
    a = p.parse_args(argv)
    dtypes = ("float64", "float32") if a.dtype == "both" else (a.dtype,)
    rows = run(a.n, dtypes, a.quick)
    dev = C.device_name()
    table = C.markdown_table(rows, dev)
    print(table)
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        with open(os.path.join(a.out, "b2.md"), "w") as f:
            f.write("## B2 heavy symmetric top on a pivot\n\n" + table)
        C.plot_work_precision(rows, f"B2 heavy top, N={a.n}, {dev}", os.path.join(a.out, "b2.png"))
    return rows


if __name__ == "__main__":
    main()
