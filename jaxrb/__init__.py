"""jaxrb: JAX-accelerated, differentiable rigid-body dynamics.

Conventions: SI units, world z up; quaternions scalar first (e0, e1, e2, e3) mapping body to
world; `omega` is the body-frame angular velocity; Euler sequences "abc" are rotations about
body-embedded (moving) axes, R = R_a(phi1) R_b(phi2) R_c(phi3).
"""

import importlib.metadata

from . import dice as dice, inertia as inertia
from ._batched import simulate_batch as simulate_batch
from ._body import RigidBody as RigidBody
from ._compilation import (
    default_cache_dir as default_cache_dir,
    speed_up_compilation as speed_up_compilation,
)
from ._dynamics import (
    accelerations as accelerations,
    joint_reaction as joint_reaction,
    total_wrench as total_wrench,
    vector_field as vector_field,
)
from ._euler import (
    SEQUENCES as EULER_SEQUENCES,  # noqa: F401 (public name, the 12 sequence strings)
    euler_singularity_distance as euler_singularity_distance,
    euler_to_matrix as euler_to_matrix,
    euler_to_quat as euler_to_quat,
    is_euler_singular as is_euler_singular,
    matrix_to_euler as matrix_to_euler,
    quat_to_euler as quat_to_euler,
)
from ._exact_flow import torque_free_flow as torque_free_flow
from ._floor import Floor as Floor
from ._forces import (
    AbstractForce as AbstractForce,
    DampingMoment as DampingMoment,
    Gravity as Gravity,
    LinearDrag as LinearDrag,
    QuadraticDrag as QuadraticDrag,
    Wrench as Wrench,
)
from ._invariants import angular_momentum as angular_momentum, energy as energy
from ._joints import AbstractJoint as AbstractJoint, Hinge as Hinge, Pivot as Pivot
from ._persistent import persistent_jit as persistent_jit
from ._polyhedron import ConvexPolyhedron as ConvexPolyhedron
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
from ._rates import (
    angular_acceleration_from_quat as angular_acceleration_from_quat,
    angular_velocity_matrix as angular_velocity_matrix,
    omega_body_from_quat_rate as omega_body_from_quat_rate,
    omega_from_angular_velocity_matrix as omega_from_angular_velocity_matrix,
    omega_world_from_quat_rate as omega_world_from_quat_rate,
    quat_E as quat_E,
    quat_G as quat_G,
    quat_rate as quat_rate,
    quat_rate_world as quat_rate_world,
)
from ._results import RESULTS as RESULTS
from ._scene import Scene as Scene
from ._shapes import (
    AbstractShape as AbstractShape,
    Box as Box,
    Cylinder as Cylinder,
    Sphere as Sphere,
)
from ._simulate import Trajectory as Trajectory, simulate as simulate
from ._splitting import simulate_splitting as simulate_splitting
from ._state import State as State, make_state as make_state
from ._surfaces import Bowl as Bowl, Cone as Cone, Wheel as Wheel
from ._sweep import grid as grid, random_draws as random_draws, sweep as sweep
from ._unrolled_stages import unrolled_solver as unrolled_solver
from .contact._lanes import simulate_throws as simulate_throws

# [contact]

try:
    __version__ = importlib.metadata.version("jaxrb")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+unknown"
