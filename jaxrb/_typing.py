"""Array shape aliases used in annotations (jaxtyping)."""

from jaxtyping import Array, ArrayLike, Float

Scalar = Float[Array, ""]
ScalarLike = float | Float[ArrayLike, ""]
Vec3 = Float[Array, "*batch 3"]
Quat = Float[Array, "*batch 4"]
Mat3 = Float[Array, "*batch 3 3"]

__all__ = ["Array", "ArrayLike", "Float", "Scalar", "ScalarLike", "Vec3", "Quat", "Mat3"]
