# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""B3: coin (thin cylinder) thrown with spin under gravity and air drag: quadratic drag force
F = -k |v| v and an aerodynamic damping moment M = -(c1 + c2 |w|) w; T = 1.5 s. Error = worst
body's max(|pos - ref| / 1 m, geodesic angle of q, |omega - ref| / |omega0|) over the save
times; reference diffrax Dopri8 at tolerance 1e-13 (float64).

Run: python -m benchmarks.b3_coin_drag --n 1000 --dtype both --out bench_out
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

T_END = 1.5


def make_scene():
    shape = jaxrb.Cylinder(jnp.asarray(0.012), jnp.asarray(0.001))  # a 24 mm coin, 2 mm thick
    body = jaxrb.RigidBody(jnp.asarray(0.0075), shape=shape)
    forces = (
        jaxrb.Gravity(),
        jaxrb.QuadraticDrag.from_air(1.225, 1.1, 3.14159 * 0.012**2),
        jaxrb.DampingMoment(jnp.asarray(1e-8), jnp.asarray(2e-9)),
    )
    return jaxrb.Scene(body, forces=forces)


def initial_states(n, seed=0):
    k1, k2, k3 = jax.random.split(jax.random.key(seed), 3)
    v = jax.random.uniform(k1, (n, 3), minval=-1.0, maxval=1.0, dtype=jnp.float64) + jnp.array(
        [0.0, 0.0, 4.0]
    )
    w = jax.random.uniform(k2, (n, 3), minval=-1.0, maxval=1.0, dtype=jnp.float64) * jnp.array(
        [60.0, 60.0, 5.0]
    )
    tilt = jax.random.uniform(k3, (n,), minval=0.0, maxval=1.0, dtype=jnp.float64)
    q = jaxrb.axis_angle_to_quat(jnp.array([0.0, 1.0, 0.0]), tilt)
    return jaxrb.make_state(pos=jnp.zeros((n, 3)), quat=q, vel=v, omega=w)


def run(n=1000, dtypes=("float64", "float32"), quick=False):
    states0 = initial_states(n)
    ts = jnp.linspace(0.0, T_END, 4)
    ref = G.reference(make_scene(), states0, ts)
    w0n = jnp.linalg.norm(states0.omega, axis=-1)

    def error(states, subset=None):
        r = ref if subset is None else jax.tree.map(lambda x: x[:subset], ref)
        w = w0n if subset is None else w0n[:subset]
        f64 = lambda x: jnp.asarray(x, jnp.float64)  # noqa: E731
        e_q = jnp.max(jaxrb.quat_geodesic_angle(f64(states.quat), r.quat), axis=-1)
        e_w = jnp.max(jnp.linalg.norm(f64(states.omega) - r.omega, axis=-1), axis=-1) / w
        e_x = jnp.max(jnp.linalg.norm(f64(states.pos) - r.pos, axis=-1), axis=-1)
        return float(jnp.max(jnp.maximum(jnp.maximum(e_q, e_w), e_x)))

    return G.sweep("B3", make_scene, states0, ts, error, dtypes=dtypes, quick=quick)


def main(argv=None):
    p = argparse.ArgumentParser(description="B3 coin with drag")
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
        with open(os.path.join(a.out, "b3.md"), "w") as f:
            f.write("## B3 coin with gravity and air drag\n\n" + table)
        C.plot_work_precision(
            rows, f"B3 coin + drag, N={a.n}, {dev}", os.path.join(a.out, "b3.png")
        )
    return rows


if __name__ == "__main__":
    main()
