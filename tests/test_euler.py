"""Euler angles: round trips, scipy agreement, gimbal lock, gradients, errors, batching.

Speed note: the 12 sequences are 12 different programs, so compiling one jitted function per
sequence (or one for all 12) costs far more than running them eagerly, where XLA's per-op
cache is shared between sequences. The tests therefore run eagerly on fixed-shape batches
(N attitudes per sequence) and check jit == eager separately. Gradients are checked the
same way: directional derivatives (jvp per input direction, vjp per output component, central
differences) of the batched function, so every call has the same shapes.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

import jaxrb
from jaxrb import (
    EULER_SEQUENCES,
    euler_singularity_distance,
    euler_to_matrix,
    euler_to_quat,
    is_euler_singular,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_euler,
    quat_to_matrix,
)

PROPER = tuple(s for s in EULER_SEQUENCES if s[0] == s[2])
TAIT_BRYAN = tuple(s for s in EULER_SEQUENCES if s[0] != s[2])
N = 24  # attitudes per sequence per call (one fixed shape keeps the eager op cache warm)
SETTINGS = settings(max_examples=8, deadline=None)
angle_batches = hnp.arrays(np.float64, (N, 3), elements=st.floats(-math.pi, math.pi))


def _upper(seq):
    return "".join("XYZ"[int(c) - 1] for c in seq)


def _singular_values(seq):
    return (0.0, math.pi) if seq[0] == seq[2] else (math.pi / 2, -math.pi / 2)


def _run(angles, seq):
    """angles (N, 3) -> everything the property tests compare, as numpy arrays."""
    R = euler_to_matrix(angles, seq)
    a2 = matrix_to_euler(R, seq)
    q = euler_to_quat(angles, seq)
    a_q = quat_to_euler(q, seq)
    out = dict(
        R=R,
        angles=a2,
        R2=euler_to_matrix(a2, seq),
        q=q,
        q_of_R=matrix_to_quat(R),
        angles_q=a_q,
        R_q=euler_to_matrix(a_q, seq),
        dist=euler_singularity_distance(R, seq),
        singular=is_euler_singular(R, seq),
    )
    return {k: np.asarray(v) for k, v in out.items()}


def _check_ranges(a, seq):
    a = np.asarray(a)
    assert np.all(a[..., 0] > -math.pi) and np.all(a[..., 0] <= math.pi)
    assert np.all(a[..., 2] > -math.pi) and np.all(a[..., 2] <= math.pi)
    if seq[0] == seq[2]:
        assert np.all(a[..., 1] >= 0) and np.all(a[..., 1] <= math.pi)
    else:
        assert np.all(np.abs(a[..., 1]) <= math.pi / 2)


def _same_up_to_sign(p, q, atol):
    s = np.sign(np.sum(p * q, axis=-1, keepdims=True))
    np.testing.assert_allclose(p, s * q, atol=atol, rtol=0)


def _expected_distance(angles, seq):
    """Distance of phi2 (any value in [-pi, pi]) from gimbal lock, folded into phi2's range."""
    b = np.abs(angles[..., 1])
    if seq[0] == seq[2]:
        return np.minimum(b, math.pi - b)
    return np.abs(math.pi / 2 - b)


# --------------------------------------------------------------------------- round trips


@pytest.mark.filterwarnings("ignore:Gimbal lock detected:UserWarning")  # scipy, near lock
@SETTINGS
@given(angles=angle_batches)
def test_round_trip_random(angles):
    for seq in EULER_SEQUENCES:
        out = _run(angles, seq)
        R = out["R"]
        np.testing.assert_allclose(out["R2"], R, atol=1e-12, rtol=0)
        np.testing.assert_allclose(out["R_q"], R, atol=1e-12, rtol=0)
        # intrinsic (uppercase) scipy rotations are the same matrices
        scipy_R = Rotation.from_euler(_upper(seq), angles).as_matrix()
        np.testing.assert_allclose(R, scipy_R, atol=1e-14, rtol=0)
        _same_up_to_sign(out["q"], out["q_of_R"], atol=1e-14)
        _check_ranges(out["angles"], seq)
        _check_ranges(out["angles_q"], seq)
        # singularity query
        expected = _expected_distance(angles, seq)
        np.testing.assert_allclose(out["dist"], expected, atol=1e-12)
        np.testing.assert_array_equal(out["singular"], out["dist"] <= 1e-9)
        # scipy's as_euler has our ranges; angles agree where well conditioned (away from
        # gimbal lock and the +-pi wrap). Its angles give our matrix except within ~1e-7 of
        # gimbal lock, where scipy snaps phi3 to zero and so misses R by O(distance): there
        # the reference, not jaxrb, is inexact (ours is checked above to 1e-12 everywhere).
        theirs = Rotation.from_matrix(R).as_euler(_upper(seq))
        clear = out["dist"] > 1e-6
        np.testing.assert_allclose(
            euler_to_matrix(theirs, seq)[clear], R[clear], atol=1e-12, rtol=0
        )
        wrap = np.abs(np.abs(out["angles"][:, [0, 2]]) - math.pi).min(axis=1)
        good = (out["dist"] > 0.1) & (wrap > 1e-9)
        np.testing.assert_allclose(out["angles"][good], theirs[good], atol=1e-12, rtol=0)


def test_matches_scipy_as_euler_deterministic():
    """A fixed batch so the angle comparison with scipy always covers many attitudes."""
    rng = np.random.default_rng(0)
    for seq in EULER_SEQUENCES:
        angles = rng.uniform(-math.pi, math.pi, (N, 3))
        angles[:, 1] = rng.uniform(0.2, 1.3, N) * (1 if seq[0] == seq[2] else rng.choice([-1, 1]))
        R = Rotation.from_euler(_upper(seq), angles).as_matrix()
        ours = np.asarray(matrix_to_euler(R, seq))
        np.testing.assert_allclose(ours, Rotation.from_matrix(R).as_euler(_upper(seq)), atol=1e-12)
        np.testing.assert_allclose(ours, angles, atol=1e-12)


@SETTINGS
@given(angles=angle_batches, which=hnp.arrays(np.int64, (N,), elements=st.integers(0, 1)))
def test_exactly_singular(angles, which):
    for seq in EULER_SEQUENCES:
        a = np.array(angles)
        a[:, 1] = np.array(_singular_values(seq))[which]
        out = _run(a, seq)
        got = out["angles"]
        assert np.all(np.isfinite(got))
        # documented convention: phi3 = 0, phi1 carries the determined phi1 +- phi3
        np.testing.assert_array_equal(got[:, 2], 0.0)
        np.testing.assert_array_equal(out["angles_q"][:, 2], 0.0)
        np.testing.assert_allclose(out["R2"], out["R"], atol=1e-12, rtol=0)
        np.testing.assert_allclose(out["R_q"], out["R"], atol=1e-12, rtol=0)
        np.testing.assert_allclose(got[:, 1], a[:, 1], atol=1e-14)
        assert np.all(out["singular"])
        assert np.all(out["dist"] < 1e-14)
        _check_ranges(got, seq)


@pytest.mark.parametrize("d", [1e-7, 1e-10])
def test_near_singular_round_trip(d):
    rng = np.random.default_rng(7)
    for seq in EULER_SEQUENCES:
        for mid in _singular_values(seq):
            inward = 1.0 if mid in (0.0, -math.pi / 2) else -1.0
            # inside phi2's range (0 + d, pi - d, pi/2 - d, -pi/2 + d), then just beyond it
            for side in (1.0, -1.0):
                angles = rng.uniform(-math.pi, math.pi, (N, 3))
                angles[:, 1] = mid + side * inward * d
                out = _run(angles, seq)
                np.testing.assert_allclose(out["R2"], out["R"], atol=1e-12, rtol=0)
                np.testing.assert_allclose(out["R_q"], out["R"], atol=1e-12, rtol=0)
                np.testing.assert_allclose(out["dist"], d, rtol=1e-5)
                np.testing.assert_array_equal(out["singular"], d <= 1e-9)
                # regular branch: phi3 is not snapped to zero this far from the singularity
                assert np.all(out["angles"][:, 2] != 0.0)
                _check_ranges(out["angles"], seq)


def _rows(rows, dtype=np.float64):
    """A fixed (N, 3) batch repeating the given rows."""
    return jnp.asarray(np.resize(np.asarray(rows, dtype), (N, 3)))


def test_singularity_distance_values():
    for seq in EULER_SEQUENCES:
        if seq in PROPER:
            rows, expected = [[0.2, 0.5, -0.3], [0.2, math.pi - 0.25, -0.3]], [0.5, 0.25]
        else:
            rows = [[0.2, 0.5, -0.3], [0.2, -1.2, -0.3]]
            expected = [math.pi / 2 - 0.5, math.pi / 2 - 1.2]
        dist = euler_singularity_distance(euler_to_matrix(_rows(rows), seq), seq)
        np.testing.assert_allclose(dist, np.resize(expected, N), rtol=1e-13)
    # custom tolerance
    R = euler_to_matrix(_rows([[0.1, 1e-5, 0.2]]), "313")
    assert np.all(is_euler_singular(R, "313", tol=1e-4))
    assert not np.any(is_euler_singular(R, "313"))


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_identity_and_ranges(seq):
    eye = jnp.broadcast_to(jnp.eye(3), (N, 3, 3))
    np.testing.assert_array_equal(matrix_to_euler(eye, seq), np.zeros((N, 3)))
    one = jnp.asarray(np.resize([1.0, 0.0, 0.0, 0.0], (N, 4)))
    np.testing.assert_array_equal(quat_to_euler(one, seq), np.zeros((N, 3)))
    # a half turn about the first axis is reported as phi1 = +pi, never -pi
    R = euler_to_matrix(_rows([[-math.pi, 0.0, 0.0], [math.pi, 0.0, 0.0]]), seq)
    got = np.asarray(matrix_to_euler(R, seq))
    np.testing.assert_allclose(euler_to_matrix(got, seq), R, atol=1e-15)
    np.testing.assert_allclose(got[:, 0], math.pi, atol=1e-15)
    _check_ranges(got, seq)
    # the quaternion's sign does not matter, nor does its norm
    q = euler_to_quat(_rows([[0.4, 0.9, -2.0]]), seq)
    a1 = quat_to_euler(q, seq)
    np.testing.assert_allclose(quat_to_euler(-3.0 * q, seq), a1, atol=1e-14)
    np.testing.assert_allclose(a1, _rows([[0.4, 0.9, -2.0]]), atol=1e-14)


@pytest.mark.parametrize("seq", ["121", "313", "321", "132"])
def test_elementary_definition(seq):
    """R = R_a(phi1) R_b(phi2) R_c(phi3), elementary matrices of docs/theory.md, section 2.1."""

    def elem(axis, t):
        c, s = math.cos(t), math.sin(t)
        return {
            "1": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "2": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "3": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
        }[axis]

    ang = (0.3, -1.1, 2.5)
    expected = elem(seq[0], ang[0]) @ elem(seq[1], ang[1]) @ elem(seq[2], ang[2])
    np.testing.assert_allclose(euler_to_matrix(jnp.array(ang), seq), expected, atol=1e-15)
    np.testing.assert_allclose(
        quat_to_matrix(euler_to_quat(jnp.array(ang), seq)), expected, atol=1e-15
    )


def test_float32():
    for seq in EULER_SEQUENCES:
        s0, s1 = _singular_values(seq)
        angles = _rows([[0.7, s0, -0.2], [0.7, s1, -0.2], [0.7, 0.3, -0.2]], np.float32)
        R = euler_to_matrix(angles, seq)
        got = matrix_to_euler(R, seq)
        assert got.dtype == jnp.float32
        np.testing.assert_array_equal(got[0::3, 2], 0.0)  # exactly singular in float32 too
        np.testing.assert_array_equal(got[1::3, 2], 0.0)
        np.testing.assert_allclose(euler_to_matrix(got, seq), R, atol=1e-6)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad", ["122", "xyz", "ZXZ", 123, "", "3131", None])
def test_unknown_sequence(bad):
    for fn, arg in [
        (euler_to_matrix, jnp.zeros(3)),
        (euler_to_quat, jnp.zeros(3)),
        (matrix_to_euler, jnp.eye(3)),
        (quat_to_euler, jnp.array([1.0, 0, 0, 0])),
        (is_euler_singular, jnp.eye(3)),
        (euler_singularity_distance, jnp.eye(3)),
    ]:
        with pytest.raises(ValueError, match="seq") as info:
            fn(arg, bad)
        for s in EULER_SEQUENCES:
            assert s in str(info.value)


def test_bad_shapes():
    with pytest.raises(ValueError, match="angles"):
        euler_to_matrix(jnp.zeros(2), "313")
    with pytest.raises(ValueError, match="angles"):
        euler_to_quat(jnp.zeros((3, 2)), "313")
    with pytest.raises(ValueError, match="R"):
        matrix_to_euler(jnp.zeros((3, 4)), "313")
    with pytest.raises(ValueError, match="R"):
        is_euler_singular(jnp.zeros(3), "313")
    with pytest.raises(ValueError, match="q"):
        quat_to_euler(jnp.zeros(3), "313")


# --------------------------------------------------------------------------- gradients


def _jacobians(f, x, eps):
    """Per-row Jacobians (fwd, rev, central differences) of a row-wise batched f at x (N, ...).

    Each has shape (N, M, D) with D the input and M the output components of one row.
    """
    n_in = int(np.prod(x.shape[1:]))
    y, pull = jax.vjp(f, x)
    n_out = int(np.prod(y.shape[1:]))

    def unit(k, shape):
        return jnp.zeros((N, int(np.prod(shape[1:]))), x.dtype).at[:, k].set(1.0).reshape(shape)

    fwd, fd = [], []
    for k in range(n_in):
        t = unit(k, x.shape)
        fwd.append(jax.jvp(f, (x,), (t,))[1].reshape(N, n_out))
        fd.append(((f(x + eps * t) - f(x - eps * t)) / (2 * eps)).reshape(N, n_out))
    rev = [pull(unit(m, y.shape))[0].reshape(N, n_in) for m in range(n_out)]
    return (
        np.stack(fwd, axis=-1),
        np.stack(rev, axis=-2),
        np.stack(fd, axis=-1),
    )


def _points(seq):
    """(N, 3): the identity, both singular attitudes exactly, then regular attitudes."""
    s0, s1 = _singular_values(seq)
    reg = 1.0 if seq[0] == seq[2] else -0.6
    rows = [[0.0, 0.0, 0.0], [0.4, s0, -0.7], [-2.0, s1, 0.9], [0.3, reg, 2.1]]
    return _rows(rows), np.resize([False, False, False, True], N)


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_forward_gradients(seq):
    """euler_to_matrix / euler_to_quat: fwd and rev equal central differences everywhere."""
    A, _ = _points(seq)
    for fn in (euler_to_matrix, euler_to_quat):
        fwd, rev, fd = _jacobians(lambda a, fn=fn: fn(a, seq), A, 1e-5)
        np.testing.assert_allclose(fwd, fd, atol=1e-9, rtol=0)
        np.testing.assert_allclose(rev, fd, atol=1e-9, rtol=0)


@pytest.mark.parametrize("seq", EULER_SEQUENCES)
def test_inverse_gradients(seq):
    A, regular = _points(seq)
    Rs = euler_to_matrix(A, seq)
    fwd, rev, fd = _jacobians(lambda R: matrix_to_euler(R, seq), Rs, 1e-6)
    # finite (no NaN) at the identity and exactly at gimbal lock, forward and reverse
    assert np.all(np.isfinite(fwd)) and np.all(np.isfinite(rev))
    _, rev_q, _ = _jacobians(lambda q: quat_to_euler(q, seq), euler_to_quat(A, seq), 1e-6)
    assert np.all(np.isfinite(rev_q))
    # correct at the regular attitudes: central differences in the ambient 3x3 space
    np.testing.assert_allclose(fwd[regular], fd[regular], atol=1e-8, rtol=0)
    np.testing.assert_allclose(rev[regular], fd[regular], atol=1e-8, rtol=0)
    # and the composition angles -> R -> angles is the identity map there
    J, _, _ = _jacobians(lambda a: matrix_to_euler(euler_to_matrix(a, seq), seq), A, 1e-6)
    np.testing.assert_allclose(J[regular], np.broadcast_to(np.eye(3), J[regular].shape), atol=1e-12)


# --------------------------------------------------------------------------- jit, batching


def test_batch_shapes():
    angles = jax.ShapeDtypeStruct((5, 7, 3), jnp.float64)
    for seq in ("313", "231"):
        R = jax.eval_shape(lambda a, seq=seq: euler_to_matrix(a, seq), angles)
        assert R.shape == (5, 7, 3, 3)
        assert jax.eval_shape(lambda a, seq=seq: euler_to_quat(a, seq), angles).shape == (5, 7, 4)
        for fn, shape in [
            (matrix_to_euler, (5, 7, 3)),
            (is_euler_singular, (5, 7)),
            (euler_singularity_distance, (5, 7)),
        ]:
            assert jax.eval_shape(lambda r, fn=fn, seq=seq: fn(r, seq), R).shape == shape
        q = jax.ShapeDtypeStruct((5, 7, 4), jnp.float64)
        assert jax.eval_shape(lambda q, seq=seq: quat_to_euler(q, seq), q).shape == (5, 7, 3)


def test_jit_and_vmap_equal_eager(getkey):
    angles = jax.random.uniform(getkey(), (N, 3), minval=-3.0, maxval=3.0)
    for seq in ("313", "231"):
        R = euler_to_matrix(angles, seq)
        q = euler_to_quat(angles, seq)
        a2 = matrix_to_euler(R, seq)

        @jax.jit
        def jitted(angles, seq=seq):
            R = euler_to_matrix(angles, seq)
            return R, euler_to_quat(angles, seq), matrix_to_euler(R, seq)

        Rj, qj, aj = jitted(angles)
        np.testing.assert_allclose(Rj, R, atol=1e-15, rtol=0)
        np.testing.assert_allclose(qj, q, atol=1e-15, rtol=0)
        np.testing.assert_allclose(aj, a2, atol=1e-14, rtol=0)
        vm = jax.vmap(lambda r, seq=seq: matrix_to_euler(r, seq))(R)
        np.testing.assert_allclose(vm, a2, atol=1e-15, rtol=0)


def test_public_names():
    assert jaxrb.EULER_SEQUENCES == (
        "121", "123", "131", "132", "212", "213", "231", "232", "312", "313", "321", "323",
    )  # fmt: skip
