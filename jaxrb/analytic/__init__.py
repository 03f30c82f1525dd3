"""Exact solutions used as oracles: torque-free tops, the fixed-axis pendulum, the bouncing ball.

Everything here is written in jax.numpy, so it is jittable and differentiable.
"""

# [elliptic]
# [tops]
# [pendulum]
# [ball]
