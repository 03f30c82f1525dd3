"""One command for the whole benchmark report: tables (markdown) and PNGs in --out.

    python -m benchmarks.run_all --out bench_out [--n 1000] [--dtype both] [--quick]

Writes b1.md/b1.png/b1_scaling.png, b2.md/b2.png, b3.md/b3.png, b4.md/b4.png, long_run.md /
long_run_energy.png and REPORT.md (all tables, device named). Optional peer: MuJoCo
(`pip install jaxrb[bench]`); rows say when it is missing. B4 (impacts, tens of ms per body
on a CPU) has its own batch size `--n-impacts` (default 64; 16 with --quick).
"""

import argparse
import os

import jax

jax.config.update("jax_enable_x64", True)

try:
    from . import (
        _common as C,
        b1_torque_free,
        b2_heavy_top,
        b3_coin_drag,
        b4_die_impacts,
        long_run,
    )
except ImportError:
    import _common as C  # type: ignore
    import b1_torque_free  # type: ignore
    import b2_heavy_top  # type: ignore
    import b3_coin_drag  # type: ignore
    import b4_die_impacts  # type: ignore
    import long_run  # type: ignore


def main(argv=None):
    p = argparse.ArgumentParser(description="jaxrb benchmark report")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--dtype", choices=["float64", "float32", "both"], default="both")
    p.add_argument("--quick", action="store_true")
    p.add_argument(
        "--n-impacts", type=int, default=None, help="B4 batch size (default 64; 16 with --quick)"
    )
    p.add_argument("--periods", type=int, default=10_000, help="long-run rotation periods")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    common = ["--n", str(a.n), "--dtype", a.dtype, "--out", a.out] + (
        ["--quick"] if a.quick else []
    )
    b1_torque_free.main(common)
    b2_heavy_top.main(common)
    b3_coin_drag.main(common)
    n4 = a.n_impacts if a.n_impacts is not None else (16 if a.quick else 64)
    b4_die_impacts.main(
        ["--n", str(n4), "--dtype", a.dtype, "--out", a.out] + (["--quick"] if a.quick else [])
    )
    long_run.main(
        ["--periods", str(a.periods if not a.quick else 100), "--out", a.out]
        + (["--top-seconds", "20"] if a.quick else [])
    )
    b4_sizes = f"B4: {n4} dice, {max(n4 // 4, 1)} coins"
    parts = [f"# jaxrb benchmark report\n\ndevice: `{C.device_name()}`, N = {a.n} ({b4_sizes})\n"]
    for name in ("b1.md", "b2.md", "b3.md", "b4.md", "long_run.md"):
        path = os.path.join(a.out, name)
        if os.path.exists(path):
            parts.append(open(path).read())
    with open(os.path.join(a.out, "REPORT.md"), "w") as f:
        f.write("\n".join(parts))
    print(f"report written to {os.path.join(a.out, 'REPORT.md')}")


if __name__ == "__main__":
    main()
