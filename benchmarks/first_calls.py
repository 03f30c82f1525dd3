# ruff: noqa: E501  (table strings)
"""First calls from a cold start, against a plain diffrax solve of the same equations.

    python -m benchmarks.first_calls --out bench_out [--rounds 3]

What a user waits for the first time a program runs in a fresh process (no persistent
caches; XLA's CPU settings as `jaxrb.speed_up_compilation` sets them, for both sides):

- a free body (I = diag(1, 2, 3) kg m^2, omega0 (1, 0.5, 0.8) rad/s, 11 saves over 20 s,
  Tsit5 at rtol = atol = 1e-8): `jaxrb.simulate`'s first call against `diffrax.diffeqsolve`
  of B1's hand-written 7-number right-hand side (`b1_torque_free.plain_rhs`: quaternion and
  body-frame omega), both jitted
  with the initial omega and the save times as arguments;
- the first reverse-mode gradient of the final omega_x with respect to omega0, both ways
  (diffrax's default `RecursiveCheckpointAdjoint`);
- the default die scene of `jaxrb run` (contact engine, float64): `jaxrb.simulate`'s first
  call.

Each call runs in its own Python process, the two sides alternating, `--rounds` times; the
table gives trace, lowering and XLA's compile apart (s), their sum, and the optimised
program's size (lines of HLO text). Writes `first_calls.md`.
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore

REPOSITORY = Path(__file__).resolve().parents[1]

# One process per measurement: the program below, with CASE set to one of CASES.
PROGRAM = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import diffrax as dfx
import jax.numpy as jnp
import optimistix as optx
import jaxrb
jaxrb.speed_up_compilation(cache=False)
CASE = sys.argv[1]
from benchmarks.b1_torque_free import plain_rhs
I = jnp.array([1.0, 2.0, 3.0])
ts = jnp.linspace(0.0, 20.0, 11)
w0 = jnp.array([1.0, 0.5, 0.8])
scene = jaxrb.Scene(jaxrb.RigidBody(1.0, jnp.diag(I)))

def plain(w, ts):
    y0 = (jnp.array([1.0, 0.0, 0.0, 0.0]), w)
    sol = dfx.diffeqsolve(
        dfx.ODETerm(plain_rhs(I)), dfx.Tsit5(), ts[0], ts[-1], None, y0,
        saveat=dfx.SaveAt(ts=ts), stepsize_controller=dfx.PIDController(rtol=1e-8, atol=1e-8),
        max_steps=100_000,
    )
    return sol.ys[1][-1]

def ours(w, ts):
    return jaxrb.simulate(scene, jaxrb.make_state(omega=w), ts).states.omega[-1]

def replace(module, name, value):  # a part of the contact program left out (attribution)
    assert hasattr(module, name), (module, name)
    setattr(module, name, value)

if CASE in ("die_no_choice", "die_no_event", "die_no_rows"):
    from jaxrb.contact import _driver, _modes, _select, _transition
    if CASE == "die_no_choice":  # the mode after an event: the one before it
        replace(_transition, "select_mode", lambda t, state, geom, old, *rest, **kw: _select.Choice(
            mode=old, consistent=jnp.array(True), painleve=jnp.array(False),
            ambiguous=jnp.array(False)))
    else:  # an event changes nothing (no impact law, no mode choice, no projection)
        def no_event(t, y, mode, trigger, scene, model, tol, live=True):
            zero, no = jnp.zeros((), y.pos.dtype), jnp.array(False)
            return _transition.EventOutcome(
                state=y, mode=mode, impact=no, impulse=jnp.zeros(3, zero.dtype),
                point=jnp.zeros(3, zero.dtype), speed=zero, energy_lost=zero, merged=no,
                rest_time=zero + jnp.inf, guarded=no, inconsistent=no, painleve=no,
                ambiguous=no, energy_rise=zero, penetration=zero)
        replace(_driver, "at_event", no_event)
    if CASE == "die_no_rows":  # and a mode's solve has no contact rows
        replace(_modes, "mode_rows", lambda state, *rest, **kw: _modes.no_rows(state.pos.dtype))

if CASE == "die_plain":  # the least an event-driven die could be: one flight to the floor
    from jaxrb._scene_file import default_scene_path, load_scene
    spec = load_scene(default_scene_path())
    corners = jnp.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)]) * 0.008

    def die_rates(t, y, args):
        state = jaxrb.State(*y)
        acc, omega_dot = jaxrb.accelerations(t, state, spec.scene)
        return (state.vel, jaxrb.quat_rate(state.quat, state.omega), acc, omega_dot)

    def lowest(t, y, args, **kwargs):  # the lowest corner's height (m)
        return jnp.min(y[0][2] + corners @ jaxrb.quat_to_matrix(y[1])[2])

    def flight(s):
        sol = dfx.diffeqsolve(
            dfx.ODETerm(die_rates), dfx.Tsit5(), spec.ts[0], spec.ts[-1], None,
            (s.pos, s.quat, s.vel, s.omega), saveat=dfx.SaveAt(ts=spec.ts),
            stepsize_controller=dfx.PIDController(rtol=1e-6, atol=1e-6),
            event=dfx.Event(lowest, root_finder=optx.Newton(1e-10, 1e-10)), max_steps=100_000,
        )
        return sol.ys, sol.event_mask

    fn, args = flight, (spec.state0,)
elif CASE.startswith("die"):
    from jaxrb._scene_file import default_scene_path, load_scene, make_solver
    spec = load_scene(default_scene_path())
    kwargs = dict(spec.options, solver=make_solver(spec.options["solver"]), throw=False)
    fn, args = (lambda s: jaxrb.simulate(spec.scene, s, spec.ts, **kwargs)), (spec.state0,)
else:
    fn = {"free": ours, "free_plain": plain, "grad": ours, "grad_plain": plain}[CASE]
    if CASE.startswith("grad"):
        fn = jax.grad(lambda w, ts, f=fn: f(w, ts)[0])
    args = (w0, ts)
t0 = time.perf_counter()
traced = jax.jit(fn).trace(*args)
t1 = time.perf_counter()
lowered = traced.lower()
t2 = time.perf_counter()
compiled = lowered.compile()
t3 = time.perf_counter()
jax.block_until_ready(compiled(*args))
t4 = time.perf_counter()
print(json.dumps(dict(trace=t1 - t0, lower=t2 - t1, compile=t3 - t2, run=t4 - t3,
                      lines=compiled.as_text().count("\n"))))
"""

CASES = [
    (
        "free",
        "free_plain",
        "free body: first `simulate` / plain diffrax",
        "first call <= 1.5x plain diffrax's",
    ),
    ("grad", "grad_plain", "free body: first reverse gradient / plain diffrax", "<= 5 s"),
    ("die", None, "default die scene: first `simulate`", "<= 4 s"),
]

# `--parts`: where the die's first call goes. The same call with parts of the contact
# program left out (what those programs compute is wrong; only their size counts), and a
# plain diffrax solve of the die's flight to its first touch of the floor (an event), the
# least an event-driven die could compile to
PARTS = [
    ("die_no_choice", None, "  die, the mode after an event the one before (no mode choice)", ""),
    ("die_no_event", None, "  die, an event changes nothing (no impact law, no mode choice)", ""),
    ("die_no_rows", None, "  die, as above and no contact rows (flight, conditions, roots)", ""),
    ("die_plain", None, "  plain diffrax: the die's flight to the floor, one event", ""),
]


def measure(case: str) -> dict:
    """One cold first call in a fresh process (no caches): its stages (s) and size."""
    out = subprocess.run(
        [sys.executable, "-c", PROGRAM, case],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPOSITORY,  # where `benchmarks` imports from
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="bench_out")
    p.add_argument("--rounds", type=int, default=3, help="processes per case (alternating)")
    p.add_argument("--force", action="store_true", help="overwrite earlier results")
    p.add_argument("--parts", action="store_true", help="also the die with parts left out")
    a = p.parse_args(argv)
    cases = CASES + (PARTS if a.parts else [])
    if a.rounds < 1:
        p.error("--rounds must be >= 1")
    (path,) = C.output_paths(p, a.out, ["first_calls.md"], a.force)
    results = {}
    for r in range(a.rounds):
        for ours, peer, _, _ in cases:
            for case in filter(None, (ours, peer) if r % 2 == 0 else (peer, ours)):
                m = measure(case)
                results.setdefault(case, []).append(m)
                total = m["trace"] + m["lower"] + m["compile"]
                print(f"round {r + 1}: {case}: {total:.2f} s ({m['lines']} HLO lines)", flush=True)

    def cell(case, key):
        values = [m[key] for m in results[case]]
        if key == "lines":
            return str(values[0])
        return ", ".join(f"{v:.2f}" for v in values)

    def totals(case):
        return [m["trace"] + m["lower"] + m["compile"] for m in results[case]]

    lines = [
        f"# First calls from a cold start ({C.device_name()}; {a.rounds} processes per case, alternating)\n",
        "| call | trace (s) | lower (s) | XLA compile (s) | total (s) | HLO lines | target | median ratio to plain diffrax |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for ours, peer, label, target in cases:
        for case, name in ((ours, label), (peer, "  plain diffrax, the same")):
            if case is None:
                continue
            ratio = ""
            if case == ours and peer is not None:
                ratio = f"{statistics.median(totals(ours)) / statistics.median(totals(peer)):.2f}"
            lines.append(
                f"| {name} | {cell(case, 'trace')} | {cell(case, 'lower')} | "
                f"{cell(case, 'compile')} | {', '.join(f'{t:.2f}' for t in totals(case))} | "
                f"{cell(case, 'lines')} | {target if case == ours else ''} | {ratio} |"
            )
    text = "\n".join(lines) + "\n"
    with open(path, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
