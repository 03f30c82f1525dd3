"""jaxrb: JAX-accelerated, differentiable rigid-body dynamics.

Conventions: SI units, world z up; quaternions scalar first (e0, e1, e2, e3) mapping body to
world; `omega` is the body-frame angular velocity; Euler sequences "abc" are rotations about
body-embedded (moving) axes, R = R_a(phi1) R_b(phi2) R_c(phi3).
"""

import importlib.metadata

from . import inertia as inertia
from ._quaternion import (
    axis_angle_to_quat as axis_angle_to_quat,
    matrix_to_quat as matrix_to_quat,
    quat_conjugate as quat_conjugate,
    quat_geodesic_angle as quat_geodesic_angle,
    quat_identity as quat_identity,
    quat_multiply as quat_multiply,
    quat_normalize as quat_normalize,
    quat_rotate as quat_rotate,
    quat_to_axis_angle as quat_to_axis_angle,
    quat_to_matrix as quat_to_matrix,
    quat_to_rotvec as quat_to_rotvec,
    skew as skew,
)

# [euler]
# [rates]
# [model]
# [dynamics]
# [simulate]
# [contact]

try:
    __version__ = importlib.metadata.version("jaxrb")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+unknown"
