"""Which points rest at an event (docs/contact.md, section 5, steps 1, 4 and 5): those that
touch with no normal velocity, every point of a face that has come down flat, and those
whose slip is gone."""

import jax
import jax.numpy as jnp

from .._quaternion import _safe_norm
from ._modes import active_points, face_point_masks

# a face may rest as a whole when this many of its points rest
RESTING_OF_A_FACE = 3


def touching_points(geom, model, mode, tol) -> jax.Array:
    """Mask (P,) of the points within `tol.contact` (m) of the surface (a cap's highest rim
    points: within `tol.flat`), and those `mode` holds on it."""
    flat = jnp.asarray(model.flat_points)
    return (geom.gap <= jnp.where(flat, tol.flat, tol.contact)) | active_points(model, mode)


def resting_points(touching, geom, model, tol) -> tuple[jax.Array, jax.Array]:
    """Masks (P,) of the points that rest and of those whose slip is gone, for the points
    `touching` (P,) at the state of `geom`.

    A point rests when it touches and its normal velocity is below `tol.slip_stop` (m/s).
    A face rests as a whole when three of its points rest and its other points are within
    the model's `face_reach` times the tolerances (`tol.contact`, m; `tol.slip_stop`, m/s): a rigid
    face's gaps and normal velocities are affine functions of the point on it, so three
    points within the tolerances of rest leave the others within that multiple of them, and
    a test point by point cannot tell such a face from one at rest (a d12's pentagon coming
    down about a vertex: its far vertices separating at 1.8e-5 m/s while three rest). The
    projection that follows the choice removes that motion. A slip is gone below
    `tol.slip_stop` (m/s)."""
    resting = touching & (jnp.abs(geom.gap_rate) <= tol.slip_stop)
    faces = jnp.asarray(face_point_masks(model))
    reach = model.face_reach()[:, None]
    near = (geom.gap <= reach * tol.contact) & (jnp.abs(geom.gap_rate) <= reach * tol.slip_stop)
    flat_down = jnp.all(~faces | near, axis=1) & (
        jnp.sum(faces & resting, axis=1) >= RESTING_OF_A_FACE
    )
    resting = resting | jnp.any(faces & flat_down[:, None], axis=0)
    zero_slip = _safe_norm(geom.slip) <= tol.slip_stop
    return resting, zero_slip
