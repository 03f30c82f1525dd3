# ruff: noqa: E501  (table strings)
"""Roulette, after Small & Tse (2012, Chaos 22, 033150): where does the ball leave the wall,
and can it be predicted from the ball's first revolutions? (the contact engine, float64).

The scene is the shipped example `roulette` (`jaxrb run roulette`): a 21 mm, 5.5 g ball
launched along the outer wall of a roulette wheel's stator (`jaxrb.Wheel`: a track inclined at
d = 0.3 rad, a smooth wall of radius 0.41 m), rolling on the track pressed against the wall,
slowed by air drag (-k |v| v) and rolling resistance (mu_r). It leaves the wall when its speed
has fallen to v*^2 = (5/7) g rho tan d (rho = R - r, the centre's radius), then runs down
the track. With A = (5/7) mu_r g / cos d, B = (5/7) (k / m - (2/5) mu_r sin d / rho) the
speed on the wall is v' = -(A + B v^2) (docs/contact.md, section 11), so it leaves after

    t* = (atan(q v0) - atan(q v*)) / sqrt(A B),  q = sqrt(B / A),

having turned by phi* = ln((A + B v0^2) / (A + B v*^2)) / (2 rho B) about the axis.

That holds while the track's friction (mu = 0.4) keeps the ball rolling, for launch speeds up
to v_roll = 1.95 m/s; a faster ball slides first, gains spin about the track's normal, and
leaves the wall sooner (docs/contact.md, section 11).

1. *Launch-speed sweep* (`--speeds` launch speeds in [1.2, 4] m/s): the time and the angle at
   which the ball leaves the wall, from `jaxrb.simulate` (the lift-off event, and the ball's
   unwrapped azimuth at that time), against the closed forms where they hold (up to v_roll).
2. *Identification and prediction*: the ball's azimuth tracked (synthetic: the true run plus
   Gaussian noise of `--noise` rad) at 25 times over its first `--track` s on the wall; drag
   k and rolling resistance mu_r fitted to them by Levenberg-Marquardt through the simulation's
   forward-mode derivatives (`jaxrb.fit.least_squares_fit`), with their standard errors; then
   `--draws` parameter sets drawn from the fit's covariance are run to the lift-off, which
   gives the predicted leaving time and azimuth (mod 2 pi: where on the wheel) with their
   spread, against the truth.

Writes `roulette.md`, `roulette.png` and `roulette.npz` to `--out`; existing files are kept
unless `--force`.

Run: python -m benchmarks.roulette --speeds 29 --draws 32 --out bench_out
"""

import argparse
import functools
import time
from typing import NamedTuple

import jax

jax.config.update("jax_enable_x64", True)

import diffrax as dfx  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxrb  # noqa: E402
from jaxrb._scene_examples import example_path  # noqa: E402
from jaxrb._scene_file import load_scene  # noqa: E402
from jaxrb.fit import least_squares_fit  # noqa: E402

try:
    from . import _common as C
except ImportError:
    import _common as C  # type: ignore

G = 9.81
SAVES = 481  # saves per run (every 20th is a tracked time: 24 intervals)
TRACKED = 20
RTOL = ATOL = 1e-8
PAIR, POINT = 2, 1


class Example(NamedTuple):
    """The shipped `roulette` scene and the numbers the study uses: the track's inclination
    d (rad), the ball's radius (m), mass (kg) and centre's radius rho (m) in the corner, the
    true drag coefficient k (kg/m), rolling resistance and launch speed (m/s)."""

    spec: object
    wheel: object
    ball: object
    d: float
    r_ball: float
    rho: float
    mass: float
    k: float
    mu_r: float
    v0: float


@functools.cache
def example() -> Example:
    """The shipped `roulette` scene (`Example`), built when first asked for, not at import:
    building it runs JAX, which would start its backend before `main` can choose the CPU
    compiler settings."""
    spec = load_scene(example_path("roulette"))
    (drag,) = [f for f in spec.scene.forces if isinstance(f, jaxrb.QuadraticDrag)]
    wheel, ball = spec.scene.floor, spec.scene.body
    r_ball = float(ball.shape.radius)
    return Example(
        spec=spec,
        wheel=wheel,
        ball=ball,
        d=float(wheel.inclination),
        r_ball=r_ball,
        rho=float(wheel.wall_radius) - r_ball,
        mass=float(ball.mass),
        k=float(drag.coefficient),
        mu_r=float(wheel.rolling_resistance),
        v0=float(spec.state0.vel[1]),
    )


def scene_with(drag, rolling):
    """The example scene with drag coefficient `drag` (kg/m) and rolling resistance `rolling`."""
    ex = example()
    wheel = eqx.tree_at(lambda w: w.rolling_resistance, ex.wheel, jnp.asarray(rolling))
    forces = (jaxrb.Gravity(), jaxrb.QuadraticDrag(drag))
    return jaxrb.Scene(ex.ball, forces, floor=wheel)


def launch(v0):
    """In the corner at azimuth 0, rolling along +y at `v0` (m/s), no spin about the normal."""
    ex = example()
    d = ex.d
    height = (ex.r_ball + ex.rho * np.sin(d)) / np.cos(d)
    slope = jnp.array([np.cos(d), 0.0, np.sin(d)])
    return jaxrb.make_state(
        pos=jnp.array([ex.rho, 0.0, height]),
        vel=jnp.stack([0.0 * v0, v0, 0.0 * v0]),
        omega=-(v0 / ex.r_ball) * slope,
    )


def closed_form(v0, drag=None, rolling=None):
    """(t*, phi*, v*): when (s), at which unwrapped azimuth (rad) and speed (m/s) the ball
    launched at `v0` leaves the wall (module docstring)."""
    ex = example()
    drag = ex.k if drag is None else drag
    rolling = ex.mu_r if rolling is None else rolling
    A = 5 / 7 * rolling * G / np.cos(ex.d)
    B = 5 / 7 * (drag / ex.mass - 0.4 * rolling * np.sin(ex.d) / ex.rho)
    q, rate = np.sqrt(B / A), np.sqrt(A * B)
    v_leave = np.sqrt(5 / 7 * G * ex.rho * np.tan(ex.d))
    t = (np.arctan(q * v0) - np.arctan(q * v_leave)) / rate
    phi = np.log((A + B * v0**2) / (A + B * v_leave**2)) / (2 * ex.rho * B)
    return t, phi, v_leave


def rolling_limit(friction=None):
    """v_roll (m/s): the fastest launch the track's friction keeps rolling (docs/contact.md,
    section 11; the small friction along the track neglected)."""
    ex = example()
    mu = float(ex.wheel.friction) if friction is None else friction
    return np.sqrt(ex.rho * mu * G / (0.4 * np.cos(ex.d) * (np.cos(ex.d) + mu * np.sin(ex.d))))


def unwrapped_azimuth(pos):
    """The azimuth atan2(y, x) of the saved positions (..., S, 3), unwrapped along the saves."""
    phi = jnp.arctan2(pos[..., 1], pos[..., 0])
    step = jnp.diff(phi, axis=-1)
    step = (step + jnp.pi) % (2 * jnp.pi) - jnp.pi
    return jnp.concatenate([phi[..., :1], phi[..., :1] + jnp.cumsum(step, axis=-1)], axis=-1)


MIN_BATCH = 3  # smaller batches are padded to this size: one compiled program serves them


def runs(v0, drag, rolling, t_end):
    """Balls launched at `v0` (N,) with drag `drag` (N,) and rolling resistance `rolling`
    (N,), saved at SAVES times in [0, t_end] (N,), as one vmapped call of `jaxrb.sweep`:
    (lift-off time (N,), unwrapped azimuth at the saves (N, SAVES), result codes (N,)). The
    lift-off time is the first event that ends the two-point contact (inf if none before
    t_end). A batch of fewer than MIN_BATCH is padded (the sweep repeats the last row), and
    the inputs become plain float64 arrays (no weak types, e.g. from `jnp.full(n, 0.1)`),
    so that the sweep, the tracked data and the predictions share one compiled program."""
    rows = [np.asarray(x, np.float64) for x in (v0, drag, rolling, t_end)]
    out = jaxrb.sweep(_one, rows, chunk_size=max(len(rows[0]), MIN_BATCH), progress=False)
    return tuple(out)


def _one(row):
    v0, drag, rolling, t_end = row
    traj = jaxrb.simulate(
        scene_with(drag, rolling),
        launch(v0),
        jnp.linspace(0.0, t_end, SAVES),
        rtol=RTOL,
        atol=ATOL,
        max_impacts=8,
        throw=False,
    )
    log = traj.contact
    left = (log.event_kind[:-1] == PAIR) & (log.event_kind[1:] != PAIR)
    t_leave = jnp.where(jnp.any(left), log.event_time[1:][jnp.argmax(left)], jnp.inf)
    return t_leave, unwrapped_azimuth(traj.states.pos), traj.result._value


def leaving(v0, drag, rolling):
    """(t*, phi*) from the simulation: one pass to the lift-off event, one to that time.
    The first runs to a little past the closed form's t* (a ball that slides first leaves
    sooner)."""
    t_end = 1.1 * closed_form(np.asarray(v0), np.asarray(drag), np.asarray(rolling))[0] + 0.5
    t_leave, _, code1 = runs(v0, drag, rolling, jnp.asarray(t_end))
    t_leave = np.asarray(t_leave)
    ok = np.isfinite(t_leave) & (np.asarray(code1) == 0)
    _, phi, code2 = runs(v0, drag, rolling, jnp.asarray(np.where(ok, t_leave, 1.0)))
    ok &= np.asarray(code2) == 0
    return np.where(ok, t_leave, np.nan), np.where(ok, np.asarray(phi)[:, -1], np.nan)


class TrackedAzimuth(eqx.Module):
    """Residuals (rad) of the simulated azimuth at the tracked times against the data, as a
    function of z = (log k, log mu_r)."""

    ts: jnp.ndarray
    data: jnp.ndarray
    v0: jnp.ndarray

    def __call__(self, z, args):
        drag, rolling = jnp.exp(z[0]), jnp.exp(z[1])
        traj = jaxrb.simulate(
            scene_with(drag, rolling),
            launch(self.v0),
            self.ts,
            rtol=RTOL,
            atol=ATOL,
            max_impacts=8,
            adjoint=dfx.ForwardMode(),
            throw=False,
        )
        return unwrapped_azimuth(traj.states.pos) - self.data


def tracked_data(track, noise, seed):
    """The true run's azimuth at 25 times over [0, track] s (every TRACKED-th save of
    `runs`), plus N(0, noise^2) (rad): (times, data, truth)."""
    ex = example()
    one = lambda x: jnp.asarray([x])  # noqa: E731
    _, phi, _ = runs(one(ex.v0), one(ex.k), one(ex.mu_r), one(track))
    ts = np.linspace(0.0, track, SAVES)[::TRACKED]
    truth = np.asarray(phi)[0, ::TRACKED]
    rng = np.random.default_rng(seed)
    return ts, truth + noise * rng.standard_normal(ts.size), truth


def identify(track=6.0, noise=0.005, seed=0, start=(2.0, 0.5)):
    """Fit k and mu_r to tracked azimuths; `start`: the initial guess as multiples of the
    true values. Returns (FitResult, ts, data, truth)."""
    ex = example()
    ts, data, truth = tracked_data(track, noise, seed)
    residuals = TrackedAzimuth(jnp.asarray(ts), jnp.asarray(data), jnp.asarray(ex.v0))
    z0 = jnp.log(jnp.array([start[0] * ex.k, start[1] * ex.mu_r]))
    fit = least_squares_fit(
        residuals,
        z0,
        lambda z: (jnp.exp(z[0]), jnp.exp(z[1])),
        ("drag", "rolling_resistance"),
        ("log drag", "log rolling_resistance"),
        rtol=1e-10,
        atol=1e-10,
    )
    return fit, ts, data, truth


def predict(fit, draws, seed=1):
    """Leaving time and azimuth of `draws` parameter sets from the fit's covariance (N,) each."""
    ex = example()
    mean = np.array([float(fit.values["drag"]), float(fit.values["rolling_resistance"])])
    rng = np.random.default_rng(seed)
    params = rng.multivariate_normal(mean, fit.covariance, size=draws)
    params = np.abs(params)  # a draw below zero (far in the tail) is reflected
    v0 = jnp.full(draws, ex.v0)
    t, phi = leaving(v0, jnp.asarray(params[:, 0]), jnp.asarray(params[:, 1]))
    return params, t, phi


def sweep(speeds):
    """Leaving time and azimuth for each launch speed (N,), simulated and closed form (the
    closed form of a ball that rolls all along: valid up to `rolling_limit()`)."""
    ex = example()
    n = len(speeds)
    v0 = jnp.asarray(speeds)
    t, phi = leaving(v0, jnp.full(n, ex.k), jnp.full(n, ex.mu_r))
    t_cf, phi_cf, _ = closed_form(np.asarray(speeds))
    return t, phi, t_cf, phi_cf


def plot(speeds, t, phi, t_cf, phi_cf, fit_parts, path):
    fit, ts, data, truth, params, t_pred, phi_pred, t_true, phi_true = fit_parts
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    v_roll = rolling_limit()
    rolls = speeds <= v_roll
    ax = axes[0]
    ax.plot(speeds, t, "o", ms=4, label="jaxrb (lift-off event)")
    ax.plot(speeds[rolls], t_cf[rolls], "-", lw=1, label="closed form (rolling)")
    ax.plot(speeds[~rolls], t_cf[~rolls], ":", lw=1, color="C1", label="had it rolled")
    ax.axvline(v_roll, color="0.5", lw=0.8)
    ax.text(v_roll, ax.get_ylim()[1], " slides first", va="top", fontsize=8)
    ax.set_xlabel("launch speed (m/s)")
    ax.set_ylabel("time on the wall (s)")
    ax.set_title("When the ball leaves the wall")
    ax.legend()
    ax = axes[1]
    ax.plot(speeds, np.degrees(np.mod(phi, 2 * np.pi)), "o", ms=4, label="jaxrb")
    ax.plot(speeds[rolls], np.degrees(np.mod(phi_cf[rolls], 2 * np.pi)), "x", label="closed form")
    ax.axvline(v_roll, color="0.5", lw=0.8)
    ax.set_xlabel("launch speed (m/s)")
    ax.set_ylabel("azimuth where it leaves (deg, mod 360)")
    ax.set_title("Where on the wheel it leaves")
    ax.legend()
    ax = axes[2]
    ax.hist(np.degrees(phi_pred - phi_true), bins=20, color="C2", alpha=0.8)
    ax.axvline(0.0, color="k", lw=1)
    ax.set_xlabel("predicted - true azimuth at lift-off (deg)")
    ax.set_ylabel("draws from the fit's covariance")
    ax.set_title(f"Prediction from {ts[-1]:g} s of tracking")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(speeds, t, phi, t_cf, phi_cf, fit_parts, seconds, device):
    ex = example()
    fit, ts, data, truth, params, t_pred, phi_pred, t_true, phi_true = fit_parts
    k, mu = fit.values["drag"], fit.values["rolling_resistance"]
    sk, smu = fit.std["drag"], fit.std["rolling_resistance"]
    rolls = speeds <= rolling_limit()
    err_t = np.nanmax(np.abs(t - t_cf)[rolls] / t_cf[rolls])
    err_phi = np.nanmax(np.abs(phi - phi_cf)[rolls])
    sooner = (t_cf - t)[~rolls] if (~rolls).any() else np.zeros(1)
    lines = [
        f"Roulette study on {device}: {len(speeds)} launch speeds, {len(params)} prediction draws, {seconds:.0f} s in all (compilation included).",
        "",
        f"- Sweep: for the {int(rolls.sum())} launches below v_roll = {rolling_limit():.3f} m/s (the ball rolls all along) the lift-off time agrees with the closed form to {err_t:.1e} (relative, largest), the azimuth there to {err_phi:.1e} rad; the faster launches slide first and leave {np.nanmin(sooner):.2f} to {np.nanmax(sooner):.2f} s sooner than they would have rolling; {int(np.sum(np.isnan(t)))} runs did not leave the wall.",
        f"- Fit from {ts.size} azimuths over {ts[-1]:g} s (noise {np.std(data - truth):.2g} rad): k = {float(k):.4g} +- {float(sk):.2g} kg/m (true {ex.k:.4g}), mu_r = {float(mu):.4g} +- {float(smu):.2g} (true {ex.mu_r:.4g}); {fit.num_steps} steps, converged: {fit.converged}.",
        f"- Prediction (true launch speed {ex.v0:g} m/s): leaves at {np.nanmean(t_pred):.3f} +- {np.nanstd(t_pred):.3f} s (true {t_true:.3f} s), at azimuth {np.degrees(np.nanmean(phi_pred)):.1f} +- {np.degrees(np.nanstd(phi_pred)):.1f} deg (true {np.degrees(phi_true):.1f} deg, {phi_true / (2 * np.pi):.1f} turns).",
        "",
        "| launch speed (m/s) | t* jaxrb (s) | t* closed form (s) | phi* jaxrb (rad) | phi* closed form (rad) |",
        "|---|---|---|---|---|",
    ]
    for row in zip(speeds, t, t_cf, phi, phi_cf, strict=True):
        lines.append("| {:.3f} | {:.6f} | {:.6f} | {:.5f} | {:.5f} |".format(*row))
    return "\n".join(lines) + "\n"


def study(n_speeds, draws, track=6.0, noise=0.005):
    ex = example()
    speeds = np.linspace(1.2, 4.0, n_speeds)
    t, phi, t_cf, phi_cf = sweep(speeds)
    fit, ts, data, truth = identify(track, noise)
    params, t_pred, phi_pred = predict(fit, draws)
    (t_true,), (phi_true,) = leaving(
        jnp.asarray([ex.v0]), jnp.asarray([ex.k]), jnp.asarray([ex.mu_r])
    )
    fit_parts = (fit, ts, data, truth, params, t_pred, phi_pred, t_true, phi_true)
    return speeds, t, phi, t_cf, phi_cf, fit_parts


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--speeds", type=int, default=29, help="launch speeds in [1.2, 4] m/s")
    p.add_argument("--draws", type=int, default=32, help="parameter draws for the prediction")
    p.add_argument("--track", type=float, default=6.0, help="s of tracked azimuths")
    p.add_argument("--noise", type=float, default=0.005, help="rad, tracking noise")
    p.add_argument("--out", default="bench_out")
    p.add_argument("--force", action="store_true", help="replace existing result files")
    a = p.parse_args(argv)
    jaxrb.speed_up_compilation(cache=False)
    names = ("roulette.md", "roulette.png", "roulette.npz")
    md, png, npz = C.output_paths(p, a.out, names, a.force)
    start = time.perf_counter()
    speeds, t, phi, t_cf, phi_cf, fit_parts = study(a.speeds, a.draws, a.track, a.noise)
    seconds = time.perf_counter() - start
    text = report(speeds, t, phi, t_cf, phi_cf, fit_parts, seconds, C.device_name())
    print(text)
    with open(md, "w") as f:
        f.write(text)
    plot(speeds, t, phi, t_cf, phi_cf, fit_parts, png)
    fit, ts, data, truth, params, t_pred, phi_pred, t_true, phi_true = fit_parts
    np.savez(
        npz,
        speeds=speeds,
        t=t,
        phi=phi,
        t_cf=t_cf,
        phi_cf=phi_cf,
        ts=ts,
        data=data,
        truth=truth,
        params=params,
        t_pred=t_pred,
        phi_pred=phi_pred,
        t_true=t_true,
        phi_true=phi_true,
        fit_values=np.array([float(fit.values["drag"]), float(fit.values["rolling_resistance"])]),
        fit_covariance=fit.covariance,
    )


if __name__ == "__main__":
    main()
