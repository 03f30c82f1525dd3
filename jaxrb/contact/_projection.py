"""Keeping drift out: positions and velocities projected onto a mode's constraints at the
start of each segment (docs/contact.md, section 5, step 6).

Each projection is the smallest correction in the kinetic metric: delta u = M^-1 J^T nu with
J delta u = -residual on the mode's rows, so it moves the body as an impulse at the contacts
would. Positions take two Gauss-Newton steps (the residuals are at the integrator's error
level, so the second leaves them at roundoff).
"""

import jax
import jax.numpy as jnp

from .._linalg import solve as small_solve
from .._quaternion import _safe_norm, axis_angle_to_quat, quat_multiply, quat_normalize
from .._state import State
from ._modes import (
    FACE,
    PAIR,
    POINT,
    face_twist,
    geometry,
    inverse_mass_columns,
    mode_rows,
    on_support,
    tree_where,
)


def _correction(rows_J, mask, residual, body, R):
    """delta u (6,) = M^-1 J^T nu, with J delta u = -residual on the masked rows."""
    dtype = residual.dtype
    minv_Jt = inverse_mass_columns(body, R, rows_J)  # rows: M^-1 J_k
    W = rows_J @ minv_Jt.T
    both = mask[:, None] & mask[None, :]
    eye = jnp.eye(6, dtype=dtype)
    # a tiny regularisation keeps redundant rows (a pair's two rows along its line) solvable
    scale = jnp.max(jnp.where(mask, jnp.abs(jnp.diagonal(W)), 0.0))
    W = jnp.where(both, W, eye) + 1e-12 * scale * eye
    nu = small_solve(W, jnp.where(mask, -residual, 0.0))
    return jnp.where(mask, nu, 0.0) @ minv_Jt


def _zero_hats(dtype):
    z = jnp.zeros(3, dtype)
    return z, z, z


def project(state: State, mode, scene, model, slip_stop, iterations: int = 2) -> State:
    """The state projected onto `mode`'s constraints: `iterations` Gauss-Newton steps that
    bring the active gaps and a face's tilt to zero, then one step that brings to zero the
    normal velocities of the active contacts and the slips of those that stick or start to
    slide from rest (slip below `slip_stop`, m/s). One loop of `iterations` + 1 passes: the
    compiled program holds the geometry, the rows and the correction once."""
    dtype = state.pos.dtype

    def step(k, state):
        geom = geometry(state, scene, model, mode.seed, mode.side)
        rows = mode_rows(state, geom, mode, _zero_hats(dtype), 0.0, scene, model)
        velocities = k == iterations
        mask = jnp.where(
            velocities, rows.mask | _still_rows(state, geom, mode, model, slip_stop), rows.holonomic
        )
        delta = _correction(
            rows.J, mask, jnp.where(velocities, rows.vel, rows.pos), scene.body, geom.R
        )
        turn = delta[3:]
        angle = _safe_norm(turn)
        quat = quat_normalize(quat_multiply(axis_angle_to_quat(turn, angle), state.quat))
        moved = State(state.pos + delta[:3], quat, state.vel, state.omega)
        w = geom.w + delta[3:]
        pushed = State(state.pos, state.quat, state.vel + delta[:3], geom.R.T @ w)
        return tree_where(velocities, pushed, moved)

    return jax.lax.fori_loop(0, iterations + 1, step, state)


def _still_rows(state, geom, mode, model, slip_stop):
    """The tangential rows (6,) the velocity projection adds to the mode's: those of the
    points (or the face) whose slip is below `slip_stop` (m/s): sticking, or starting to
    slide from rest."""
    kind = mode.kind
    still_a = _safe_norm(geom.slip[mode.a]) <= slip_stop
    still_b = _safe_norm(geom.slip[mode.b]) <= slip_stop
    # (a support's vertices slide: its mode is chosen only when every one of them slips but
    # its vertex b, whose rows are the mode's own where it pivots)
    still_f = _safe_norm(face_twist(state, geom, model, mode.face)[0]) <= slip_stop
    still_f = still_f & ~on_support(mode)
    point_like = (kind == POINT) | (kind == PAIR)
    return jnp.where(
        kind == FACE,
        jnp.array([False, False, False, True, True, True]) & still_f,
        jnp.stack(
            [
                False,
                False,
                point_like & still_a,
                point_like & still_a,
                (kind == PAIR) & still_b,
                (kind == PAIR) & still_b,
            ]
        ),
    )
