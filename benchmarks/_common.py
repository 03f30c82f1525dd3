# ruff: noqa: B023, E501  (closures are called inside their loop iteration; table strings)
"""Shared helpers for the benchmarks: timing, device name, tables, plots.

Every benchmark reports speed against error on the same work in one run: a row per
(method, dtype, tolerance or step) with the worst body's error, the steady-state wall time per
body, body-steps per second where steps are known, and the compile time separately.
"""

import dataclasses
import math
import os
import statistics
import time

import jax


@dataclasses.dataclass
class Row:
    problem: str
    method: str
    dtype: str
    setting: str  # tolerance or step size
    n: int  # batch size timed
    error: float  # worst body's error (problem-specific definition)
    us_per_body: float  # steady-state wall time per body (microseconds)
    compile_s: float  # first call minus steady call (s); nan for non-JAX peers
    steps: float = math.nan  # steps per body (accepted), if known
    note: str = ""

    @property
    def body_steps_per_s(self) -> float:
        if math.isnan(self.steps) or self.us_per_body <= 0:
            return math.nan
        return self.steps / (self.us_per_body * 1e-6)


def output_paths(parser, out, names, force):
    """The paths of the result files `names` in the folder `out` (made if missing); the
    parser's usage error if one exists already and `force` is not set."""
    paths = [os.path.join(out, name) for name in names]
    existing = [q for q in paths if os.path.exists(q)]
    if existing and not force:
        parser.error(f"{existing[0]} exists (pass --force to overwrite)")
    os.makedirs(out, exist_ok=True)
    return paths


def device_name() -> str:
    d = jax.devices()[0]
    k = len(jax.devices())
    more = f" ({k} devices; rows not marked otherwise use the first)" if k > 1 else ""
    return f"{d.platform}:{getattr(d, 'device_kind', '?')}{more}"


def lean_variants(scene, n_bodies):
    """(label, devices) for `simulate_batch` (the batch as one diffrax Dopri8 solve per
    device): all devices, and one device when there are more; the label marks the one
    `simulate_batch` picks by default for this scene."""
    from jaxrb._batched import _default_devices

    devs = jax.devices()
    if len(devs) == 1:
        return [("jaxrb simulate_batch, Dopri8", devs)]
    default = len(_default_devices(scene, n_bodies))
    return [
        (
            f"jaxrb simulate_batch, Dopri8, {k} device{'s' if k > 1 else ''}"
            + (" (default)" if k == default else ""),
            devs[:k],
        )
        for k in (len(devs), 1)
    ]


def lean_rows(problem, scene, states0, ts, tols, dname, error_of):
    """Rows of `simulate_batch` (diffrax Dopri8, the batch as one solve per device) over the
    tolerances `tols`, one sweep per `lean_variants` (the tolerance is a traced argument: one
    compilation per sweep). `error_of(trajectory)` gives the row's error."""
    import diffrax as dfx
    import jax.numpy as jnp

    from jaxrb._batched import simulate_batch

    n = states0.omega.shape[0]
    rows = []
    for label, devs in lean_variants(scene, n):
        lean = jax.jit(
            lambda s, tol: simulate_batch(
                scene, s, ts, rtol=tol, atol=tol, solver=dfx.Dopri8(), throw=False, devices=devs
            )
        )
        for tol in tols:
            first, best, tr = time_jax(lean, states0, jnp.asarray(tol, ts.dtype))
            rows.append(
                Row(
                    problem,
                    label,
                    dname,
                    f"tol {tol:.0e}",
                    n,
                    error_of(tr),
                    best / n * 1e6,
                    first - best,
                    float(tr.num_steps[0]),
                )
            )
    return rows


def time_jax(fn, *args, repeats=3):
    """(first-call seconds, best steady seconds, result) of fn(*args), blocking on the result."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    best = min(times)
    return first, best, out


def time_python(fn, repeats=1):
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def fmt(x, spec=".2e"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, spec)


def markdown_table(rows: list[Row], device: str) -> str:
    head = (
        f"device: `{device}`\n\n"
        "| problem | method | dtype | setting | N | error | us/body | body-steps/s | steps | compile s | note |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = [
        f"| {r.problem} | {r.method} | {r.dtype} | {r.setting} | {r.n} | {fmt(r.error)} | "
        f"{fmt(r.us_per_body, '.3g')} | {fmt(r.body_steps_per_s, '.2e')} | {fmt(r.steps, '.0f')} | "
        f"{fmt(r.compile_s, '.1f')} | {r.note} |"
        for r in rows
    ]
    return head + "\n".join(lines) + "\n"


def plot_work_precision(
    rows: list[Row],
    title: str,
    path: str,
    ylabel: str = "worst body's error",
    legend_outside: bool = False,
) -> None:
    """Error vs wall time per body, one line per (method, dtype); saved as PNG. With
    `legend_outside` the legend stands right of the axes (many methods)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 5) if legend_outside else (7, 5))
    ax.set_prop_cycle(color=plt.cm.tab20.colors)
    groups: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        if r.error > 0 and math.isfinite(r.error) and r.us_per_body > 0:
            groups.setdefault((r.method, r.dtype), []).append(r)
    for (method, dtype), rs in groups.items():
        rs = sorted(rs, key=lambda r: r.us_per_body)
        ax.loglog(
            [r.us_per_body for r in rs],
            [r.error for r in rs],
            marker="o" if dtype == "float64" else "x",
            linestyle="-" if dtype == "float64" else "--",
            label=f"{method} ({dtype})",
        )
    ax.set_xlabel("wall time per body (us)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    if legend_outside:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    else:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_scaling(points: list[tuple[str, int, float]], title: str, path: str) -> None:
    """us/body vs batch size N, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    methods = sorted({p[0] for p in points})
    for m in methods:
        ps = sorted((n, t) for mm, n, t in points if mm == m)
        ax.loglog([p[0] for p in ps], [p[1] for p in ps], marker="o", label=m)
    ax.set_xlabel("batch size N")
    ax.set_ylabel("wall time per body (us)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
