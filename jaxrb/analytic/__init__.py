"""Exact solutions used as oracles: torque-free tops, the fixed-axis pendulum, the bouncing ball.

Everything here is written in jax.numpy, so it is jittable and differentiable.
"""

from ._ball import (
    ball_apex_heights as ball_apex_heights,
    ball_height as ball_height,
    ball_impact_times as ball_impact_times,
    ball_rest_time as ball_rest_time,
)
from ._elliptic import (
    carlson_rf as carlson_rf,
    ellip_amplitude as ellip_amplitude,
    ellip_inc_f as ellip_inc_f,
    ellip_inc_f_m1 as ellip_inc_f_m1,
    ellipj as ellipj,
    ellipj_m1 as ellipj_m1,
    ellipk as ellipk,
    ellipk_m1 as ellipk_m1,
)
from ._pendulum import (
    SAMPLE_PENDULUM as SAMPLE_PENDULUM,
    PendulumParams as PendulumParams,
    pendulum_angular_acceleration as pendulum_angular_acceleration,
    pendulum_angular_velocity_squared as pendulum_angular_velocity_squared,
    pendulum_bearing_force as pendulum_bearing_force,
    pendulum_period as pendulum_period,
    pendulum_theta as pendulum_theta,
    pendulum_theta_dot as pendulum_theta_dot,
)
from ._tops import (
    AsymmetricTopParams as AsymmetricTopParams,
    SymmetricTopSolution as SymmetricTopSolution,
    asymmetric_top as asymmetric_top,
    asymmetric_top_params as asymmetric_top_params,
    flip_half_period as flip_half_period,
    spherical_top as spherical_top,
    symmetric_top as symmetric_top,
)
