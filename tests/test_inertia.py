"""jaxrb.inertia: primitives against exact quadrature, parallel axes, rotation, principal axes,
validity checks."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jaxrb.inertia as inertia


def _tensor_of_points(points, weights):
    """sum w (|p|^2 1 - p p^T) over points (n, 3) with weights (n,): the defining integral."""
    pp = np.einsum("n,ni,nj->ij", weights, points, points)
    return np.trace(pp) * np.eye(3) - pp


def _gauss(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * x + 0.5 * (b + a), 0.5 * (b - a) * w


def _grid(*axes):
    """Tensor-product nodes (N, d) and weights (N,) from 1D (nodes, weights) pairs."""
    nodes = np.stack(np.meshgrid(*[a[0] for a in axes], indexing="ij"), -1).reshape(-1, len(axes))
    weights = np.ones(())
    for a in axes:
        weights = np.multiply.outer(weights, a[1])
    return nodes, weights.reshape(-1)


# The integrands below are polynomials (times trigonometric polynomials in the azimuth), so
# Gauss-Legendre with 4 nodes per axis and an 8-point periodic trapezoid rule are exact: the
# quadrature differs from the formulas only by rounding (1e-15 relative).
EXACT = 1e-13


def test_cuboid_quadrature():
    m, a, b, c = 2.7, 0.3, 0.5, 1.1
    nodes, w = _grid(_gauss(4, -a / 2, a / 2), _gauss(4, -b / 2, b / 2), _gauss(4, -c / 2, c / 2))
    J = _tensor_of_points(nodes, w * m / (a * b * c))
    np.testing.assert_allclose(inertia.cuboid(m, a, b, c), J, rtol=EXACT, atol=EXACT)
    # docs/theory.md, section 3.2: m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2), width a along x,
    # height b along y.
    np.testing.assert_allclose(
        np.diag(inertia.cuboid(m, a, b, c)),
        m / 12 * np.array([b**2 + c**2, a**2 + c**2, a**2 + b**2]),
    )
    np.testing.assert_allclose(inertia.cube(m, a), m * a * a / 6 * np.eye(3), rtol=EXACT)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_cylinder_quadrature(axis):
    m, R, h = 0.8, 0.4, 0.07  # a coin-like short cylinder
    rho, w_rho = _gauss(4, 0.0, R)
    phi = 2 * np.pi * np.arange(8) / 8
    z, w_z = _gauss(4, -h / 2, h / 2)
    nodes, w = _grid((rho, w_rho * rho), (phi, np.full(8, 2 * np.pi / 8)), (z, w_z))
    cyl = np.stack(
        [nodes[:, 0] * np.cos(nodes[:, 1]), nodes[:, 0] * np.sin(nodes[:, 1]), nodes[:, 2]], -1
    )
    points = np.roll(cyl, axis - 2, axis=1)  # the symmetry axis (column 2) -> body axis `axis`
    J = _tensor_of_points(points, w * m / (np.pi * R * R * h))
    np.testing.assert_allclose(inertia.cylinder(m, R, h, axis=axis), J, rtol=EXACT, atol=EXACT)
    assert float(inertia.cylinder(m, R, h, axis=axis)[axis, axis]) == pytest.approx(m * R * R / 2)


def test_sphere_quadrature():
    m, R = 1.9, 0.3
    rho, w_rho = _gauss(4, 0.0, R)
    u, w_u = _gauss(6, -1.0, 1.0)  # u = cos(polar angle)
    phi = 2 * np.pi * np.arange(8) / 8
    nodes, w = _grid((rho, w_rho * rho**2), (u, w_u), (phi, np.full(8, 2 * np.pi / 8)))
    s = np.sqrt(1 - nodes[:, 1] ** 2)
    unit = np.stack([s * np.cos(nodes[:, 2]), s * np.sin(nodes[:, 2]), nodes[:, 1]], -1)
    J = _tensor_of_points(nodes[:, :1] * unit, w * m / (4 / 3 * np.pi * R**3))
    np.testing.assert_allclose(inertia.sphere(m, R), J, rtol=EXACT, atol=EXACT)
    # Thin shell: the same angular quadrature at radius R with surface density.
    nodes, w = _grid((u, w_u), (phi, np.full(8, 2 * np.pi / 8)))
    s = np.sqrt(1 - nodes[:, 0] ** 2)
    unit = np.stack([s * np.cos(nodes[:, 1]), s * np.sin(nodes[:, 1]), nodes[:, 0]], -1)
    J = _tensor_of_points(R * unit, w * m / (4 * np.pi))
    np.testing.assert_allclose(inertia.sphere(m, R, hollow=True), J, rtol=EXACT, atol=EXACT)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rod_quadrature(axis):
    m, L = 0.6, 1.7
    x, w = _gauss(3, -L / 2, L / 2)
    points = np.zeros((3, 3))
    points[:, axis] = x
    J = _tensor_of_points(points, w * m / L)
    np.testing.assert_allclose(inertia.rod(m, L, axis=axis), J, rtol=EXACT, atol=EXACT)
    assert not bool(inertia.is_valid_inertia(inertia.rod(m, L, axis=axis)))


def test_bad_axis():
    with pytest.raises(ValueError, match="axis must be 0, 1 or 2"):
        inertia.cylinder(1.0, 1.0, 1.0, axis=3)
    with pytest.raises(ValueError, match="axis must be 0, 1 or 2"):
        inertia.rod(1.0, 1.0, axis="z")


def _point_cloud(seed, n=7):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)) * np.array([0.3, 0.7, 1.1]), rng.uniform(0.5, 2.0, n)


@pytest.mark.parametrize("seed", range(4))
def test_from_products_and_parallel_axis_on_point_masses(seed):
    p, m = _point_cloud(seed)
    M = m.sum()
    c = (m[:, None] * p).sum(0) / M
    d = p - c
    J_C = _tensor_of_points(d, m)
    # products of inertia J_ij = sum m x_i x_j enter with a minus sign
    prod = np.einsum("n,ni,nj->ij", m, d, d)
    diag = np.trace(prod) - np.diag(prod)
    J = inertia.from_products(*diag, prod[0, 1], prod[0, 2], prod[1, 2])
    np.testing.assert_allclose(J, J_C, rtol=1e-13, atol=1e-13)
    assert float(J[0, 1]) == pytest.approx(-prod[0, 1])
    # parallel axes about a point O: the sign of the offset does not matter
    o = np.array([0.3, -1.2, 0.5])
    J_O = _tensor_of_points(p - o, m)
    np.testing.assert_allclose(inertia.parallel_axis(J_C, M, c - o), J_O, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(inertia.parallel_axis(J_C, M, o - c), J_O, rtol=1e-12, atol=1e-12)
    assert bool(inertia.is_valid_inertia(J_C)) and bool(inertia.is_valid_inertia(J_O))


@pytest.mark.parametrize("seed", range(4))
def test_rotate_matches_rotated_body(seed):
    """rotate(J, R) is the tensor of the body whose points are R p (R: old axes -> new axes)."""
    p, m = _point_cloud(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    np.testing.assert_allclose(
        inertia.rotate(_tensor_of_points(p, m), R),
        _tensor_of_points(p @ R.T, m),
        rtol=1e-12,
        atol=1e-12,
    )


_principal = jax.jit(inertia.principal)


def test_principal_round_trip():
    rng = np.random.default_rng(1)
    Rs = Rotation.random(16, random_state=2).as_matrix()
    moments = np.sort(rng.uniform(1.0, 2.0, (16, 3)), axis=-1)
    order = np.argsort(rng.uniform(size=(16, 3)), axis=-1)  # unsorted diagonal on input
    D = jnp.asarray(np.take_along_axis(moments, order, -1)[..., None] * np.eye(3))
    J = inertia.rotate(D, jnp.asarray(Rs))
    moments_out, axes = _principal(J)
    assert moments_out.shape == (16, 3) and axes.shape == (16, 3, 3)
    np.testing.assert_allclose(moments_out, moments, rtol=1e-13)
    np.testing.assert_allclose(np.linalg.det(axes), 1.0, rtol=1e-13)
    np.testing.assert_allclose(
        axes @ (moments_out[..., None] * np.eye(3)) @ np.swapaxes(axes, -1, -2), J, atol=1e-13
    )
    np.testing.assert_allclose(
        np.swapaxes(axes, -1, -2) @ axes, np.broadcast_to(np.eye(3), (16, 3, 3)), atol=1e-13
    )
    # the principal axes are the rotated body axes (columns of R), up to sign
    expected = np.take_along_axis(Rs, np.argsort(order, -1)[:, None, :], -1)
    np.testing.assert_allclose(
        np.abs(np.sum(expected * np.asarray(axes), axis=-2)), 1.0, rtol=1e-12
    )
    I_eager, axes_eager = inertia.principal(J)
    np.testing.assert_allclose(I_eager, moments_out, rtol=1e-14)
    np.testing.assert_allclose(axes_eager, axes, atol=1e-14)


def test_principal_gradient_finite_differences():
    R = jnp.asarray(Rotation.random(random_state=5).as_matrix())
    J0 = inertia.rotate(jnp.diag(jnp.array([1.0, 1.6, 2.3])), R)

    @jax.jit
    def f(J):
        mom, axes = inertia.principal(J)
        return jnp.sum(mom * jnp.array([1.0, -2.0, 0.5])) + jnp.sum(axes[:, 0] * axes[:, 1] ** 2)

    dJ = jnp.asarray(np.random.default_rng(3).normal(size=(3, 3)))
    dJ = 0.5 * (dJ + dJ.T)
    eps = 1e-6
    fd = (f(J0 + eps * dJ) - f(J0 - eps * dJ)) / (2 * eps)
    assert float(jnp.sum(jax.jit(jax.grad(f))(J0) * dJ)) == pytest.approx(
        float(fd), rel=1e-8, abs=1e-9
    )
    _, jvp = jax.jit(lambda J, dJ: jax.jvp(f, (J,), (dJ,)))(J0, dJ)
    assert float(jvp) == pytest.approx(float(fd), rel=1e-8, abs=1e-9)
    # degenerate (spherical) tensor: the moments still have finite gradients
    g = jax.grad(lambda J: jnp.sum(inertia.principal(J)[0] ** 2))(jnp.eye(3))
    np.testing.assert_allclose(g, 2 * np.eye(3), atol=1e-12)


def test_primitive_gradients():
    from jax.test_util import check_grads

    def f(m, a, b, c, J, d):
        return (
            inertia.cuboid(m, a, b, c)
            + inertia.cylinder(m, a, b, axis=1)
            + inertia.parallel_axis(J, m, d)
            + inertia.sphere(m, c)
        )

    args = (1.2, 0.3, 0.4, 0.5, jnp.diag(jnp.array([1.0, 2.0, 2.5])), jnp.array([0.1, -0.2, 0.3]))
    check_grads(jax.jit(f), args, order=1, modes=("fwd", "rev"))


def test_batching_and_jit():
    m = jnp.array([1.0, 2.0, 3.0])
    dims = jnp.array([[0.1], [0.2]])  # (2, 1) broadcasts with (3,)
    J = inertia.cuboid(m, dims, 0.3, 0.4)
    assert J.shape == (2, 3, 3, 3)
    np.testing.assert_allclose(J[1, 2], inertia.cuboid(3.0, 0.2, 0.3, 0.4))
    np.testing.assert_allclose(jax.jit(inertia.cuboid)(m, dims, 0.3, 0.4), J, rtol=1e-15)
    assert inertia.cylinder(m, 0.1, 0.2).shape == (3, 3, 3)
    assert inertia.sphere(m, jnp.array([0.1, 0.2, 0.3])).shape == (3, 3, 3)
    d = jnp.zeros((4, 1, 3)).at[..., 0].set(jnp.arange(4.0)[:, None])
    assert inertia.parallel_axis(J[0], m, d).shape == (4, 3, 3, 3)
    R = jnp.asarray(Rotation.random(5, random_state=0).as_matrix())
    assert inertia.rotate(inertia.sphere(1.0, 1.0), R).shape == (5, 3, 3)
    flags = jax.jit(inertia.inertia_violations)(J)
    assert all(f.shape == (2, 3) and f.dtype == jnp.bool_ for f in flags)
    assert bool(jnp.all(jax.jit(inertia.is_valid_inertia)(J)))
    assert bool(jnp.all(jax.vmap(inertia.is_valid_inertia)(J.reshape(6, 3, 3))))
    # float32 parameters stay float32; Python scalars do not upcast them
    assert inertia.cube(jnp.float32(1.0), 0.5).dtype == jnp.float32


def _bad_tensors():
    return {
        "not_symmetric": jnp.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        "not_positive_definite": jnp.diag(jnp.array([0.0, 1.0, 1.0])),  # a thin rod
        "triangle_inequality_violated": jnp.diag(jnp.array([1.0, 1.0, 3.0])),
        "non_finite": jnp.diag(jnp.array([1.0, jnp.nan, 1.0])),
    }


def test_violation_flags():
    for field, J in _bad_tensors().items():
        flags = inertia.inertia_violations(J)._asdict()
        assert flags.pop(field), field
        assert not any(bool(v) for v in flags.values()), field
        assert not bool(inertia.is_valid_inertia(J))
    # a flat plate sits exactly on the triangle inequality (I1 + I2 = I3): valid
    plate = inertia.rotate(
        inertia.cuboid(1.0, 0.3, 0.7, 0.0), jnp.asarray(Rotation.random(random_state=1).as_matrix())
    )
    assert bool(inertia.is_valid_inertia(plate))
    batch = jnp.stack([jnp.eye(3), _bad_tensors()["triangle_inequality_violated"]])
    np.testing.assert_array_equal(inertia.is_valid_inertia(batch), [True, False])
    np.testing.assert_array_equal(jax.jit(inertia.is_valid_inertia)(batch), [True, False])


@pytest.mark.parametrize(
    "field, match",
    [
        ("not_symmetric", r"J_C is not symmetric: max \|J - J\^T\| = 0\.2"),
        (
            "not_positive_definite",
            r"J_C is not positive definite: smallest principal moment I1 = 0 ",
        ),
        (
            "triangle_inequality_violated",
            r"J_C violates the triangle inequality: I1 \+ I2 = 2 < I3 = 3",
        ),
        ("non_finite", r"J_C contains non-finite values"),
    ],
)
def test_check_inertia_messages(field, match):
    with pytest.raises(ValueError, match=match):
        inertia.check_inertia(_bad_tensors()[field], name="J_C")


def test_check_inertia_shape_batch_and_success():
    with pytest.raises(
        ValueError, match=r"inertia must have shape \(\.\.\., 3, 3\), got shape \(3,\)"
    ):
        inertia.check_inertia(jnp.ones(3))
    with pytest.raises(ValueError, match=r"J must have shape \(\.\.\., 3, 3\), got shape \(3, 2\)"):
        inertia.principal(jnp.ones((3, 2)))
    batch = jnp.stack([jnp.eye(3), jnp.eye(3), _bad_tensors()["triangle_inequality_violated"]])
    with pytest.raises(ValueError, match=r"triangle inequality at batch index \(2,\)"):
        inertia.check_inertia(batch)
    good = inertia.cuboid(1.0, 0.1, 0.2, 0.3)
    assert inertia.check_inertia(good) is not None
    np.testing.assert_array_equal(inertia.check_inertia(good), good)
    # traced input: shape checked, values left to inertia_violations
    out = jax.jit(inertia.check_inertia)(_bad_tensors()["triangle_inequality_violated"])
    assert out.shape == (3, 3)
