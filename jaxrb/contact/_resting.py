"""Which points rest at an event (docs/contact.md, section 5, steps 1, 4 and 5): those that
touch with no normal velocity, every point of a face that has come down flat, and those
whose slip is gone."""

import jax
import jax.numpy as jnp

from .._quaternion import _safe_norm
from ._modes import active_points, face_point_masks

# a face rests as a whole when its points all touch and this many of them rest
RESTING_OF_A_FACE = 3


def touching_points(geom, model, mode, tol) -> jax.Array:
    """Mask (P,) of the points within `tol.contact` (m) of the surface (a cap's highest rim
    points: within `tol.flat`), and those `mode` holds on it."""
    flat = jnp.asarray(model.flat_points)
    return (geom.gap <= jnp.where(flat, tol.flat, tol.contact)) | active_points(model, mode)


def resting_points(touching, geom, model, tol) -> tuple[jax.Array, jax.Array]:
    """Masks (P,) of the points that rest and of those whose slip is gone, for the points
    `touching` (P,) at the state of `geom`.

    A point rests when it touches and its normal velocity is below `tol.slip_stop` (m/s);
    so does every point of a face whose points all touch and three of which rest. A rigid
    face's normal velocities are an affine function of the point: three of its vertices at
    rest hold the others to a few times `slip_stop`, but one further from them can exceed it
    (a d12's pentagon coming down about a vertex: its far vertices separating at 1.8e-5 m/s
    while three rest), and without the rule the face's modes would not be candidates. The
    projection that follows the choice removes that motion. A slip is gone below
    `tol.slip_stop` (m/s)."""
    resting = touching & (jnp.abs(geom.gap_rate) <= tol.slip_stop)
    faces = jnp.asarray(face_point_masks(model))
    flat_down = jnp.all(~faces | touching, axis=1) & (
        jnp.sum(faces & resting, axis=1) >= RESTING_OF_A_FACE
    )
    resting = resting | jnp.any(faces & flat_down[:, None], axis=0)
    zero_slip = _safe_norm(geom.slip) <= tol.slip_stop
    return resting, zero_slip
