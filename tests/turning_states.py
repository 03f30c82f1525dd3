"""States of a d12 lying flat on a face and turning about the vertical: the tests of a face
that slides on three of its vertices (`Mode.support`), and of such a face at high friction
coming down pivoting about a vertex; the attitude that turns a shape's first face down,
which the mode choice's tests start from too; and a narrow box standing on its end,
turning about a corner (a face that tips onto an edge, and the Painlevé paradox)."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxrb
from benchmarks.contact_throws import shape_of
from jaxrb.contact import contact_model


def first_face_down(model):
    """The attitude (unit quaternion) that turns the first face of `model`'s shape down (its
    outward normal to -z), and the shape's corners so turned (P, 3), from the mass centre
    (m)."""
    normal = np.asarray(model.normals[0])
    axis = np.cross(normal, [0.0, 0.0, -1.0])
    angle = np.arccos(np.clip(-normal[2], -1.0, 1.0))
    axis = axis / np.linalg.norm(axis) if np.linalg.norm(axis) > 1e-12 else np.array([1.0, 0, 0])
    base = jaxrb.axis_angle_to_quat(jnp.asarray(axis), angle)
    return base, np.asarray(model.corners) @ np.asarray(jaxrb.quat_to_matrix(base)).T


def flat_turning_states(model, key, n):
    """`n` states of the d12 of `model` lying flat on its first face and turning about the
    vertical at 1-6 rad/s (either way), about a random point within the face's
    circumcircle: its vertices slide at different speeds in different directions."""
    face = list(model.face_points[0])
    base, world = first_face_down(model)
    height = -np.min(world[:, 2])
    centre = world[face].mean(axis=0) * np.array([1.0, 1.0, 0.0])
    circumradius = np.max(np.linalg.norm(world[face] - world[face].mean(axis=0), axis=1))
    k = jax.random.split(key, 4)
    yaw = jax.random.uniform(k[0], (n,), maxval=2 * np.pi)
    angle = jax.random.uniform(k[1], (n,), maxval=2 * np.pi)
    distance = circumradius * jnp.sqrt(jax.random.uniform(k[2], (n,)))
    turn_way = jnp.where(jnp.arange(n) % 2 == 0, 1.0, -1.0)
    spin = jax.random.uniform(k[3], (n,), minval=1.0, maxval=6.0) * turn_way
    up = jnp.array([0.0, 0.0, 1.0])

    def place(yaw, angle, distance, spin):
        turn = jaxrb.axis_angle_to_quat(up, yaw)
        q = jaxrb.quat_multiply(turn, base)
        offset = distance * jnp.array([jnp.cos(angle), jnp.sin(angle), 0.0])
        pivot = jaxrb.quat_to_matrix(turn) @ (centre + offset)  # from the mass centre
        w = spin * up
        omega = jaxrb.quat_to_matrix(q).T @ w
        return jaxrb.State(jnp.array([0.0, 0.0, height]), q, jnp.cross(w, -pivot), omega)

    return jax.vmap(place)(yaw, angle, distance, spin)


# a box of 24 x 8 x 8 mm (5 g), the bars of the throws benchmark, here standing on an end
# face, turning about one of its corners
NARROW_MASS, _narrow_box = shape_of("bar")[:2]
NARROW_BOX = _narrow_box()


def narrow_box_on_end(spin):
    """The state of `NARROW_BOX` standing on its first face (an end), turning about the
    vertical through that face's first corner at `spin` (rad/s), and that corner's index."""
    model = contact_model(NARROW_BOX)
    base, world = first_face_down(model)
    corner = int(model.face_points[0][0])
    w = np.array([0.0, 0.0, spin])
    state = jaxrb.State(
        jnp.array([0.0, 0.0, -np.min(world[:, 2])]),
        base,
        jnp.asarray(np.cross(w, -world[corner])),
        jaxrb.quat_to_matrix(base).T @ jnp.asarray(w),
    )
    return state, corner


def narrow_box_scene(friction):
    """`NARROW_BOX` (5 g) under gravity on a level floor of restitution 0.5 and `friction`."""
    body = jaxrb.RigidBody(NARROW_MASS, shape=NARROW_BOX)
    return jaxrb.Scene(body, (jaxrb.Gravity(),), floor=jaxrb.Floor(0.5, friction))
