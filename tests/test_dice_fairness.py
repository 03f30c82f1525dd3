"""A loaded d6 against a fair one, thrown at random by `jaxrb.sweep` (float64).

The loaded die's mass centre sits half-way from its centre towards the face numbered 2 (the
shape's offset, the centroid relative to the mass centre, points the other way), so it should
come to rest on that face and show the opposite number, 5, more often than 1/6; the fair die
should show every number about equally. Both are judged by 99 % Wilson score intervals (and
the fair one also by a chi-square test). 60 throws per die, drawn as in the studies of
`benchmarks/` (the attitude uniform over all rotations, so that no number starts on top more
often than another); the benchmark `benchmarks/dice_outcomes.py` throws thousands.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

import jaxrb

EDGE, MASS, N = 0.016, 0.0045, 60
Z99 = 2.5758293035489


def wilson(count, n, z=Z99):
    """The Wilson score interval of a proportion count / n."""
    p = count / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def throws(n, seed):
    """Random throws: heights U(0.05, 0.3) m, the attitude uniform over all rotations (a
    normalised 4-vector of standard normals), spin U(-40, 40) rad/s per body axis, horizontal
    speed U(-0.5, 0.5) m/s, restitution and friction U(0.2, 0.8)."""
    k = jax.random.split(jax.random.key(seed), 7)

    def u(key, lo, hi, shape=(n,)):
        return jax.random.uniform(key, shape, minval=lo, maxval=hi, dtype=jnp.float64)

    quat = jax.random.normal(k[0], (n, 4), dtype=jnp.float64)
    quat = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    pos = jnp.stack([jnp.zeros(n), jnp.zeros(n), u(k[2], 0.05, 0.3)], -1)
    vel = jnp.concatenate([u(k[3], -0.5, 0.5, (n, 2)), jnp.zeros((n, 1))], -1)
    state = jaxrb.make_state(pos=pos, quat=quat, vel=vel, omega=u(k[4], -40.0, 40.0, (n, 3)))
    return state, u(k[5], 0.2, 0.8), u(k[6], 0.2, 0.8)


def test_loaded_d6_shows_the_face_opposite_its_heavy_side_more_often():
    die = jaxrb.dice.d6(EDGE)
    normals = np.asarray(die.shape.face_normals())
    heavy = int(np.argmin(normals[:, 2]))  # the face whose outward normal is -z
    opposite = int(np.argmax(normals[:, 2]))
    assert die.numbers[heavy] + die.numbers[opposite] == 7
    ts = jnp.array([0.0, 3.0])

    def throw(row):
        shape = eqx.tree_at(lambda s: s.offset, die.shape, row["offset"])
        scene = jaxrb.Scene(
            jaxrb.RigidBody(MASS, shape=shape),
            (jaxrb.Gravity(),),
            floor=jaxrb.Floor(row["restitution"], row["friction"]),
        )
        traj = jaxrb.simulate(scene, row["state"], ts, max_impacts=200, throw=False)
        q = traj.states.quat[-1]
        return dict(
            code=traj.result._value,
            outcome=die.outcome(q),
            alignment=die.face_alignment(q),
            speed=jnp.linalg.norm(traj.states.vel[-1]) + jnp.linalg.norm(traj.states.omega[-1]),
        )

    state, restitution, friction = throws(N, seed=1)
    both = jax.tree.map(lambda x: jnp.concatenate([x, x]), (state, restitution, friction))
    load = jnp.zeros((2 * N, 3)).at[N:, 2].set(0.5 * EDGE / 2)  # centroid above the mass centre
    rows = dict(state=both[0], restitution=both[1], friction=both[2], offset=load)
    out = jaxrb.sweep(throw, rows, chunk_size=1, progress=False)
    assert np.all(out["code"] == jaxrb.RESULTS.successful._value)
    assert np.all(out["alignment"] > 1 - 1e-12)  # at rest squarely on a face
    assert np.all(out["speed"] < 1e-9)
    fair = np.bincount(out["outcome"][:N], minlength=7)[1:]
    loaded = np.bincount(out["outcome"][N:], minlength=7)[1:]
    # the loaded die: its heavy side down more often than 1 in 6
    lo, _ = wilson(loaded[die.numbers[opposite] - 1], N)
    assert lo > 1 / 6, loaded
    # the fair die: every number's interval holds 1/6, and the counts pass a chi-square test
    for count in fair:
        lo, hi = wilson(count, N)
        assert lo < 1 / 6 < hi, fair
    assert stats.chisquare(fair).pvalue > 0.01, fair
