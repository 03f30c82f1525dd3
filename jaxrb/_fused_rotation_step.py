"""A batch of free rotations stepped by one GPU kernel per Runge-Kutta step.

`simulate` of a batched `State` integrates the batch as one diffrax solve (`_batched.py`).
With the stages written out (`_unrolled_stages.py`) XLA still runs a step as one kernel per
stage, each writing its increment to memory and reading those of the earlier stages: for
Dopri8 about 160 passes over the batch's arrays per step, and at N = 1e6 in float64 a step
is bound by memory bandwidth. Here a step of the torque-free rotation is one Pallas kernel
(Triton on an NVIDIA GPU): each GPU thread takes a member, keeps its 7 coordinates and all
stages' increments in registers, and writes only y1 and the error estimate (7 + 7 rows). The
step-size control, saving and adjoints stay diffrax's: the solver is diffrax's own method
(`Tsit5`, `Dopri5`, `Dopri8`) whose `step` calls the kernel.

Same method, same arithmetic: the kernel forms the stages with `unrolled_step`'s sums
(`combine_increments`, `weighted_sum`) and the rates with `rotation_rates_rows`, which
`ROTATION.member_last_rates` uses too (a FSAL method evaluates its first stage
in the kernel on every step instead of carrying it: it costs registers, not memory). The
steps taken are diffrax's; results agree to roundoff.

Derivatives: the kernel has no derivative of its own. The step is a `jax.custom_jvp` whose
tangent is the same step written in jax.numpy (`step_rows` on whole rows), so forward and
reverse mode (diffrax's adjoints) differentiate the identical arithmetic, at the cost of
running the step in XLA as well. The dense output's increments (saves between the end
points) come from the same jax.numpy stages; XLA drops them where nothing reads them.

Used for the torque-free rotation of a batch on a GPU: members sharing one body (the B1
problem; J and J^-1 are kernel scalars), or each with its own inertia (`batched_scene`, an
inertia sweep: J, J^-1 and a validity flag are rows beside the state's, `member_rows`; a
flagged member's rates are zero, as on the masked path); elsewhere the written-out stages
serve (`batch_solver`). B1 at N = 1e6 on an NVIDIA H200,
Dopri8 at tol 5e-10 in float64 (error 6.3e-9): 0.035 us per body against 0.24 with the
stages written out (benchmarks/README.md, "a step as one kernel").

Coordinates: quat (4, N) scalar first, body -> world; omega (3, N) body frame (rad/s);
inertia in body axes (kg m^2), the member axis last.
"""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from ._coordinates import rotation_rates_rows
from ._unrolled_stages import combine_increments, weighted_sum

BLOCK = 128
"""Members per kernel instance (one per GPU thread at `NUM_WARPS` = 4 warps of 32)."""
NUM_WARPS = 4


def scalar_vector(dt, body, dtype, per_member: bool = False) -> jax.Array:
    """The kernel's scalars as one vector: dt (s), then J and J^-1 (principal: 3 + 3 values;
    full: 9 + 9, row-major), zero-padded to a power of two (8 or 32) for Triton. With
    `per_member` (J and J^-1 in `member_rows`), dt alone, padded to 8; `body` is not read."""
    values = [jnp.reshape(dt, (1,)).astype(dtype)]
    if not per_member:
        if body.inertia_inverse is None:
            raise ValueError("the fused rotation step needs the body's cached J^-1")
        values += [body.inertia.astype(dtype).ravel(), body.inertia_inverse.astype(dtype).ravel()]
    values = jnp.concatenate(values)
    size = 8 if per_member or body.principal else 32
    return jnp.pad(values, (0, size - values.shape[0]))


def member_rows(inertia, inverse, valid) -> jax.Array:
    """The kernel's per-member rows, one column per member: J's and J^-1's entries (principal
    moments (N, 3): 3 + 3 rows; full tensors (N, 3, 3): 9 + 9, row-major) and last the
    member's validity (1 or 0), all in J's dtype."""
    n = inertia.shape[0]
    flag = valid.astype(inertia.dtype)[None]
    return jnp.concatenate(
        [inertia.reshape(n, -1).T, inverse.reshape(n, -1).astype(inertia.dtype).T, flag]
    )


def _entries(values, principal: bool):
    """J or J^-1 from its entries in order: the 3 moments, or nested [r][c] of 9."""
    if principal:
        return values[:3]
    return [[values[3 * r + c] for c in range(3)] for r in range(3)]


def _rates(scalars, principal: bool, rows, members=None):
    """`rotation_rates_rows` with J and J^-1 read from `scalar_vector`'s entries, or per
    member from `member_rows`' rows (a flagged member's rates zero)."""
    size = 3 if principal else 9
    values = scalars[1:] if members is None else members
    inertia = _entries(values[:size], principal)
    inverse = _entries(values[size : 2 * size], principal)
    rates = rotation_rates_rows(inertia, inverse, principal, rows)
    if members is None:
        return rates
    valid = members[2 * size]
    return tuple(jnp.where(valid != 0, r, jnp.zeros_like(r)) for r in rates)


def stage_increments(tableau, scalars, principal, rows, members=None):
    """Every stage's increment k_i = dt f(Y_i) (a list over the stages of 7 rows each) and
    y1's rows."""
    dt = scalars[0]

    def increment(y):
        return [dt * r for r in _rates(scalars, principal, y, members)]

    ks = [increment(rows)]
    y_stage = rows
    for i in range(1, len(tableau.c) + 1):
        y_stage = combine_increments(rows, tableau.a_lower[i - 1], ks)
        ks.append(increment(y_stage))
    y1 = y_stage if tableau.ssal else combine_increments(rows, tableau.b_sol, ks)
    return ks, y1


def step_rows(tableau, scalars, principal, rows, members=None):
    """One step: (y1 rows, error-estimate rows), as `unrolled_step` computes them."""
    ks, y1 = stage_increments(tableau, scalars, principal, rows, members)
    error = weighted_sum(tableau.b_error, ks)
    if error is None:
        error = [jnp.zeros_like(r) for r in rows]
    return tuple(y1), tuple(error)


def _kernel(tableau, principal, n_scalars, n_members):
    def kernel(scalars_ref, *refs):
        inputs, outputs = refs[: 7 + n_members], refs[7 + n_members :]
        scalars = [scalars_ref[i] for i in range(n_scalars)]
        rows = [ref[...] for ref in inputs]
        members = rows[7:] if n_members else None
        y1, error = step_rows(tableau, scalars, principal, rows[:7], members)
        for ref, value in zip(outputs, y1 + error, strict=True):
            ref[...] = value

    return kernel


def _pallas_step(tableau, principal, interpret, scalars, quat, omega, members=None):
    from jax.experimental import pallas as pl  # imported where used: not on every start

    n = quat.shape[-1]
    if n % BLOCK:  # Triton did not mask a partial last block: it ran past the arrays' ends
        raise ValueError(f"the fused step takes whole blocks of {BLOCK} members, got {n}")

    def row(r):  # row r of a (rows, N) array, a block of BLOCK members at a time
        return pl.BlockSpec((None, BLOCK), lambda i: (r, i))

    row_specs = [row(r) for r in range(4)] + [row(r) for r in range(3)]  # quat, then omega
    n_members = 0 if members is None else members.shape[0]
    row_specs += [row(r) for r in range(n_members)]  # per-member J, J^-1, validity
    compiler_params = None
    if not interpret:
        from jax.experimental.pallas import triton as pl_triton

        compiler_params = pl_triton.CompilerParams(num_warps=NUM_WARPS)
    outs = pl.pallas_call(
        _kernel(tableau, principal, scalars.shape[0], n_members),
        grid=(n // BLOCK,),
        in_specs=[pl.BlockSpec(scalars.shape, lambda i: (0,))] + row_specs,
        out_specs=[pl.BlockSpec((BLOCK,), lambda i: (i,))] * 14,
        out_shape=[jax.ShapeDtypeStruct((n,), quat.dtype)] * 14,
        interpret=interpret,
        compiler_params=compiler_params,
        name="fused_rotation_step",
    )(scalars, quat, quat, quat, quat, omega, omega, omega, *[members] * n_members)
    return _as_coordinates(outs[:7]), _as_coordinates(outs[7:])


def _as_coordinates(rows):
    return jnp.stack(rows[:4]), jnp.stack(rows[4:])


def _xla_step(tableau, principal, scalars, quat, omega, members=None):
    rows = list(quat) + list(omega)
    y1, error = step_rows(tableau, scalars, principal, rows, members)
    return _as_coordinates(y1), _as_coordinates(error)


fused_step = jax.custom_jvp(_pallas_step, nondiff_argnums=(0, 1, 2))
"""(tableau, principal, interpret, scalars, quat, omega, members=None) -> ((quat1, omega1),
(quat_err, omega_err)): one step by the kernel, differentiable through the same step in
jax.numpy. `members`: `member_rows` (each member's J, J^-1 and validity), or None for
J and J^-1 among the scalars."""


@fused_step.defjvp
def _fused_step_jvp(tableau, principal, interpret, primals, tangents):
    out = fused_step(tableau, principal, interpret, *primals)
    _, tangent = jax.jvp(lambda *p: _xla_step(tableau, principal, *p), primals, tangents)
    return out, tangent


class _FusedRotation:
    """The `step` of the fused solvers: diffrax's method, its step one kernel (see the module
    docstring). `body` carries J and the cached J^-1, or, with `members` (`member_rows`, a
    column per member), only whether J is principal; `interpret`: run the kernel in
    Pallas's interpreter (any backend; for tests)."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del terms, args, made_jump
        quat, omega = y0
        members, principal = self.members, self.body.principal
        scalars = scalar_vector(t1 - t0, self.body, omega.dtype, members is not None)
        tableau = self.tableau
        y1, y_error = fused_step(tableau, principal, self.interpret, scalars, quat, omega, members)
        rows = list(quat) + list(omega)
        ks, _ = stage_increments(tableau, scalars, principal, rows, members)
        k_stacked = (
            jnp.stack([jnp.stack(k[:4]) for k in ks]),
            jnp.stack([jnp.stack(k[4:]) for k in ks]),
        )  # read only by saves between the end points; otherwise dropped by XLA
        dense_info = dict(y0=y0, y1=y1, k=k_stacked)
        if tableau.fsal:  # the kernel evaluates the first stage itself: nothing is carried
            solver_state = (jnp.array(True), solver_state[1])
        return y1, y_error, dense_info, solver_state, dfx.RESULTS.successful


def _fused_class(base):
    class Fused(_FusedRotation, base):
        body: object = None
        members: jax.Array | None = None
        interpret: bool = eqx.field(static=True, default=False)

    Fused.__name__ = Fused.__qualname__ = f"FusedRotation{base.__name__}"
    return Fused


_FUSED = {cls: _fused_class(cls) for cls in (dfx.Tsit5, dfx.Dopri5, dfx.Dopri8)}


def on_gpu() -> bool:
    """Whether JAX's default backend is a GPU, where the kernel (Triton's) runs."""
    return jax.default_backend() == "gpu"


def fused_rotation_solver(solver, body, interpret: bool = False, members=None):
    """The fused twin of a `diffrax.Tsit5`, `Dopri5` or `Dopri8` (its exact class) for the
    torque-free rotation of `body` (J^-1 cached: `RigidBody.with_inertia_inverse`), or of
    members each with its own inertia (`members`: `member_rows`, one column per member, the
    batch padded to whole blocks; `body` then only says whether J is principal); None for
    any other solver."""
    fused = _FUSED.get(type(solver))
    if fused is None:
        return None
    return fused(scan_kind=solver.scan_kind, body=body, members=members, interpret=interpret)
