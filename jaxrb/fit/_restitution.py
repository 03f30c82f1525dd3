"""Restitution fitting from bounce observations of a ball dropped onto a floor.

Closed forms (`jaxrb.analytic.ball_impact_times`, `ball_apex_heights`; a drop from rest at
t = 0): t_1 = sqrt(2 h0 / g), t_(k+1) - t_k = 2 e^k g t_1 / g, apex after bounce k is
e^(2k) h0. The restitution e is parameterised as sigmoid(z) (every iterate in (0, 1)), the
drop height h0 as exp(z).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..analytic import ball_apex_heights, ball_impact_times
from ._least_squares import FitResult, check_series, least_squares_fit, require_samples
from ._parameterisation import (
    positive_to_unconstrained,
    unconstrained_to_positive,
    unconstrained_to_unit,
    unit_to_unconstrained,
)


class _BounceResiduals(eqx.Module):
    times: jnp.ndarray | None
    heights: jnp.ndarray | None
    time_weight: jnp.ndarray
    height_weight: jnp.ndarray
    g: jnp.ndarray
    h0_known: jnp.ndarray | None

    def physical(self, z):
        e = unconstrained_to_unit(z[0])
        h0 = self.h0_known if self.h0_known is not None else unconstrained_to_positive(z[1])
        return e, h0

    def __call__(self, z, args):
        e, h0 = self.physical(z)
        parts = []
        if self.times is not None:
            model = ball_impact_times(h0, e, self.times.shape[0], g=self.g)
            parts.append((model - self.times) * self.time_weight)
        if self.heights is not None:
            model = ball_apex_heights(h0, e, self.heights.shape[0], g=self.g)
            parts.append((model - self.heights) * self.height_weight)
        return jnp.concatenate(parts)


def fit_restitution(
    *,
    impact_times=None,
    apex_heights=None,
    h0=None,
    restitution0: float = 0.5,
    h0_guess=None,
    g: float = 9.81,
    time_noise: float = 1.0,
    height_noise: float = 1.0,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    max_steps: int = 200,
) -> FitResult:
    """Fit Newton's restitution coefficient from the bounces of a dropped ball.

    **Arguments:**

    - `impact_times`: (n,) times (s) of the first n impacts after release from rest at t = 0.
    - `apex_heights`: (n,) apex heights (m) of the lowest point after bounces 1..n.
      At least one of the two is needed; both may be combined.
    - `h0`: the drop height (m) if known; otherwise it is fitted too (guess `h0_guess`,
      default from the first impact time or apex).
    - `restitution0`: initial guess in (0, 1).
    - `g`: gravity (m/s^2).
    - `time_noise`, `height_noise`: relative noise levels weighting the two kinds of residual.
    - `rtol`, `atol`, `max_steps`: Levenberg–Marquardt settings.

    **Returns:** a `FitResult` with values `restitution` and `h0`.
    """
    if impact_times is None and apex_heights is None:
        raise ValueError("fit_restitution needs `impact_times` and/or `apex_heights`")
    times = None if impact_times is None else check_series(impact_times, "impact_times", ())
    heights = None if apex_heights is None else check_series(apex_heights, "apex_heights", ())
    if times is not None and (np.any(times <= 0) or np.any(np.diff(times) <= 0)):
        raise ValueError("impact_times must be positive and strictly increasing")
    if heights is not None and np.any(heights <= 0):
        raise ValueError("apex_heights must be positive")
    if not 0 < restitution0 < 1:
        raise ValueError(f"restitution0 must be in (0, 1), got {restitution0}")
    if h0 is not None:
        h0 = float(h0)
        if not (np.isfinite(h0) and h0 > 0):
            raise ValueError(f"h0 must be finite and > 0, got {h0}")
    if h0 is None and h0_guess is None:
        h0_guess = 0.5 * g * times[0] ** 2 if times is not None else heights[0] / restitution0**2
    z0 = [unit_to_unconstrained(restitution0)]
    internal = ("logit restitution",)
    if h0 is None:
        z0.append(positive_to_unconstrained(float(h0_guess)))
        internal += ("log h0",)
    z0 = np.asarray(z0, dtype=float)
    n_res = (0 if times is None else times.size) + (0 if heights is None else heights.size)
    require_samples(n_res, z0.size, "the bounce observations")
    fn = _BounceResiduals(
        times=None if times is None else jnp.asarray(times),
        heights=None if heights is None else jnp.asarray(heights),
        time_weight=jnp.asarray(1.0 / time_noise),
        height_weight=jnp.asarray(1.0 / height_noise),
        g=jnp.asarray(float(g)),
        h0_known=None if h0 is None else jnp.asarray(h0),
    )
    return least_squares_fit(
        fn,
        z0,
        fn.physical,
        ("restitution", "h0"),
        internal,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
    )
