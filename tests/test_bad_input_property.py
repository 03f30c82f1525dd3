"""Property test of the bad-input policy: random scenes, states, save times and tolerances,
good and bad mixed, give a named error or a correct result, never a silent NaN.

Each example draws a batch of bodies, some with injected defects. Traced (one compiled,
vmapped `simulate(throw=False)` for every example): a body with no defect succeeds with
finite states and no energy gain; a body with defects carries the flag of one of them and
takes no solver steps. Concrete: building the same models and calling `simulate` raises a
ValueError naming the faulty parameter, or succeeds when there is none.
"""

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings, strategies as st
from programs import persistent

import jaxrb

R = jaxrb.RESULTS
BATCH = 16
N_SAVES = 4

# field -> (defect draws, result code, what a concrete error names)
DEFECTS = {
    "mass": ([math.nan, math.inf, -1.0, 0.0], R.invalid_mass, r"mass must be"),
    "inertia": (
        [(1.0, 1.0, 3.0), (-1.0, 2.0, 2.0), (math.nan, 1.0, 1.0)],
        R.invalid_inertia,
        r"inertia",
    ),
    "radius": ([math.nan, -0.1, 0.0, math.inf], R.invalid_shape, r"Sphere\.radius"),
    "g_z": ([math.nan, math.inf], R.invalid_force, r"Gravity\.g"),
    "drag": ([math.nan, -0.5], R.invalid_force, r"LinearDrag\.coefficient"),
    "omega": ([(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0)], R.nonfinite_state, r"state0\.omega"),
    "quat": ([(0.0, 0.0, 0.0, 0.0)], R.zero_quaternion, r"state0\.quat"),
    "ts": (["reversed", "nan"], None, r"ts "),
    "rtol": ([math.nan, -1e-8], R.invalid_tolerances, r"rtol"),
}
TS_CODES = {"reversed": R.decreasing_times, "nan": R.nonfinite_times}


def _body_values(draw):
    a = draw(st.floats(0.1, 10.0))
    b = draw(st.floats(0.1, 10.0))
    c = abs(a - b) + draw(st.floats(0.01, 0.99)) * 2 * min(a, b)  # the triangle inequality
    exponent = draw(st.floats(-150.0, 150.0))
    quat = [draw(st.floats(-1.0, 1.0)) for _ in range(4)]
    quat[0] = quat[0] if abs(quat[0]) > 0.1 else 0.5
    return dict(
        mass=draw(st.floats(0.01, 100.0)),
        inertia=(a, b, c),
        radius=draw(st.floats(1e-3, 1.0)),
        g_z=draw(st.floats(-20.0, 20.0)),
        drag=draw(st.floats(0.0, 1.0)),
        omega=tuple(draw(st.floats(-20.0, 20.0)) for _ in range(3)),
        quat=tuple(x * 10.0**exponent for x in quat),
        ts=draw(st.floats(0.05, 0.5)),
        rtol=draw(st.floats(1e-10, 1e-7)),
    )


@st.composite
def members(draw):
    """A batch: each body's values and the fields given a defect (none for about half)."""
    batch = []
    for _ in range(BATCH):
        values = _body_values(draw)
        bad = draw(st.sets(st.sampled_from(sorted(DEFECTS)), max_size=2))
        if draw(st.booleans()):
            bad = set()
        for field in bad:
            values[field] = draw(st.sampled_from(DEFECTS[field][0]))
        batch.append((values, frozenset(bad)))
    return batch


def _save_times(spec):
    if spec == "reversed":
        return jnp.linspace(0.3, 0.0, N_SAVES)
    if spec == "nan":
        return jnp.linspace(0.0, 0.3, N_SAVES).at[2].set(jnp.nan)
    return jnp.linspace(0.0, spec, N_SAVES)


def _scene(mass, inertia, radius, g_z, drag):
    return jaxrb.Scene(
        jaxrb.RigidBody(mass, inertia, shape=jaxrb.Sphere(radius)),
        forces=(
            jaxrb.Gravity(jnp.stack([jnp.zeros_like(g_z), jnp.zeros_like(g_z), g_z])),
            jaxrb.LinearDrag(drag),
        ),
    )


def _run(mass, inertia, radius, g_z, drag, omega, quat, ts, rtol):
    scene = _scene(mass, inertia, radius, g_z, drag)
    state = jaxrb.make_state(pos=(0.0, 0.0, 1.0), vel=(1.0, 0.0, 2.0), omega=omega, quat=quat)
    traj = jaxrb.simulate(scene, state, ts, rtol=rtol, atol=1e-9, throw=False)
    energy = jaxrb.energy(scene, traj.states)
    s = traj.states
    spin = jnp.sum(s.omega * scene.body.inertia * s.omega, axis=-1)
    kinetic = 0.5 * (mass * jnp.sum(s.vel**2, axis=-1) + spin)
    # the size of the terms that make up the energy: the solver's error scales with it
    scale = jnp.max(kinetic + jnp.abs(energy - kinetic))
    return traj.result, traj.num_steps, s, energy, scale


@persistent
def _run_batch(mass, inertia, radius, g_z, drag, omega, quat, ts, rtol):
    return jax.vmap(_run)(mass, inertia, radius, g_z, drag, omega, quat, ts, rtol)


def _arrays(batch):
    def column(field):
        return jnp.asarray([v[field] for v, _ in batch], dtype=float)

    out = {f: column(f) for f in DEFECTS if f != "ts"}
    out["ts"] = jnp.stack([_save_times(v["ts"]) for v, _ in batch])
    return out


# no shrinking: a batch of 16 bodies shrinks slowly, and the failing body is named anyway
QUICK = dict(
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
)


@settings(max_examples=150, **QUICK)
@given(members())
def test_traced_bad_input_is_flagged_and_good_input_is_computed(batch):
    result, steps, states, energy, scale = _run_batch(**_arrays(batch))
    for i, (values, bad) in enumerate(batch):
        code = int(result._value[i])
        if not bad:
            assert code == R.successful._value, (values, code)
            leaves = jax.tree.leaves(jax.tree.map(lambda x, i=i: x[i], states))
            assert all(bool(jnp.all(jnp.isfinite(x))) for x in leaves)
            assert jnp.allclose(jnp.linalg.norm(states.quat[i], axis=-1), 1.0, atol=1e-12)
            e = energy[i]
            # gravity and linear drag: the energy may only fall
            assert float(jnp.max(e) - e[0]) <= 1e-6 * float(scale[i]), values
        else:
            allowed = [TS_CODES[values["ts"]] if f == "ts" else DEFECTS[f][1] for f in bad]
            assert code in [c._value for c in allowed], (bad, code)
            assert int(steps[i]) == 0


@settings(max_examples=60, **QUICK)
@given(members())
def test_concrete_bad_input_raises_a_named_error(batch):
    for values, bad in batch[:4]:
        # the models raise where they are made; simulate raises for state, times, tolerances
        try:
            scene = _scene(
                *(jnp.asarray(values[k], float) for k in ("mass", "inertia", "radius", "g_z")),
                jnp.asarray(values["drag"], float),
            )
            state = jaxrb.make_state(omega=values["omega"], quat=values["quat"])
            ts = _save_times(values["ts"])
            if not bad:
                # only the checks: a zero-length step budget would make this a solver test
                jaxrb.simulate(scene, state, ts[:1], rtol=values["rtol"], atol=1e-9)
        except ValueError as e:
            assert bad, str(e)
            names = "|".join(DEFECTS[f][2] for f in bad)
            assert re.search(names, str(e)), (bad, str(e))
            continue
        if bad:
            with pytest.raises(ValueError) as info:
                jaxrb.simulate(scene, state, ts, rtol=values["rtol"], atol=1e-9)
            names = "|".join(DEFECTS[f][2] for f in bad)
            assert re.search(names, str(info.value)), (bad, str(info.value))


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(jaxrb.EULER_SEQUENCES),
    st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
        lambda q: max(abs(x) for x in q) > 1e-3
    ),
    # down to 1e-290: components that matter at 1e-12 (>= 1e-13 of the largest, which is
    # > 1e-3) stay normal float64 numbers; XLA on a CPU flushes subnormal ones (< 2.2e-308)
    # to zero, so (0, 0, 1, 1e-9) * 1e-299 reads as (0, 0, 1, 0)
    st.floats(-290.0, 300.0),
)
def test_euler_angles_of_any_quaternion_norm_round_trip(seq, quat, exponent):
    q = np.asarray(quat) * 10.0**exponent
    angles = jaxrb.quat_to_euler(jnp.asarray(q), seq)
    assert jnp.all(jnp.isfinite(angles))
    back = np.asarray(jaxrb.euler_to_quat(angles, seq))
    unit = np.asarray(quat) / np.linalg.norm(quat)
    assert min(np.abs(back - unit).max(), np.abs(back + unit).max()) < 1e-12
