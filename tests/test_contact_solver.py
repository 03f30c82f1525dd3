"""The sliding solver of the mode selection (`SlidingSolver`: a mode's solution for any
sliding directions by a 2 x 2 Woodbury update) against the direct 6 x 6 solve."""

import jax
import jax.numpy as jnp
import numpy as np
from programs import persistent

import jaxrb
from jaxrb.contact._features import contact_model
from jaxrb.contact._modes import CandidateTable, flight_mode, geometry, sliding_solver, solve_mode

TOL = jaxrb.contact.ContactOptions().resolved(jnp.float64)


def _scene(shape, mu=0.4):
    body = jaxrb.RigidBody(0.004, shape=shape)
    forces = (jaxrb.Gravity(), jaxrb.QuadraticDrag(0.01))
    return jaxrb.Scene(body, forces=forces, floor=jaxrb.Floor(0.5, mu))


SHAPES = (
    jaxrb.Box((0.008, 0.006, 0.004)),
    jaxrb.Cylinder(0.012, 0.001),
    jaxrb.dice.d12(0.01).shape,
)


@persistent(static_argnames="which")
def _compare(which, key_data):
    """Every candidate mode of `SHAPES[which]` at one moving state, with random unit sliding
    directions drawn from the key (its raw data): (the solver's, the direct solve's)
    multipliers and accelerations, and the multipliers without friction."""
    shape = SHAPES[which]
    key = jax.random.wrap_key_data(key_data)
    scene = _scene(shape)
    model = contact_model(shape)
    table = CandidateTable(model)
    k1, k2, k3 = jax.random.split(key, 3)
    quat = jaxrb.quat_normalize(jax.random.normal(k1, (4,)))
    state = jaxrb.make_state(
        pos=(0.0, 0.0, 0.01), quat=quat, vel=jax.random.normal(k2, (3,)), omega=(3.0, -2.0, 5.0)
    )
    state = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), state)
    hats = jax.random.normal(k3, (len(table), 3, 3))
    hats = hats / jnp.linalg.norm(hats, axis=-1, keepdims=True)
    old = flight_mode(jnp.float64)

    def one(i, h):
        mode = table.mode(i, old)
        geom = geometry(state, scene, model, mode.seed, mode.side)
        h = (h[0], h[1], h[2])
        fast = sliding_solver(0.0, state, mode, scene, model, TOL, geom)(h)
        direct = solve_mode(0.0, state, mode, scene, model, TOL, hats=h, geom=geom)
        zero = jnp.zeros(3, jnp.float64)
        plain = solve_mode(0.0, state, mode, scene, model, TOL, hats=(zero,) * 3, geom=geom)
        return [(s.lam, s.acc, s.alpha, s.rows.C) for s in (fast, direct)], plain.lam

    return jax.vmap(one)(jnp.arange(len(table)), hats)


def test_sliding_solver_equals_the_direct_solve():
    """For every candidate mode of a box, a coin and a d12 (stick and slide, points, pairs,
    faces), the Woodbury update gives the direct solve's contact forces and accelerations
    to roundoff (1e-9 of their scale)."""
    key = jax.random.key(3)
    for which in range(len(SHAPES)):
        key, sub = jax.random.split(key)
        (fast, direct), plain = _compare(which, jax.random.key_data(sub))
        for a, b in zip(fast, direct, strict=True):
            a, b = np.asarray(a), np.asarray(b)
            scale = np.max(np.abs(b)) + 1e-300
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * scale)
        # the directions matter: some candidates' forces differ from those without friction
        change = np.max(np.abs(np.asarray(direct[0]) - np.asarray(plain)))
        assert change > 1e-2 * np.max(np.abs(np.asarray(plain)))
