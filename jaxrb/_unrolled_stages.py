"""Explicit Runge-Kutta steps with their stages written out: the same diffrax solvers
(tableau, step-size control, dense output, events, adjoints), one step traced as straight-line
code instead of diffrax's loop over the stages.

diffrax runs an explicit method's stages in a loop, each stage a dot product of a full row
of the (zero-padded) tableau with the buffer of all stages' increments: every stage reads all
of them. Written out, stage i reads only the increments its tableau row uses (its non-zero
coefficients, known when the step is traced), and the compiler can fuse a stage's
combination with its evaluation of the right-hand side. For a batch as one solve on a GPU,
where each pass over the batch's arrays costs memory bandwidth, this is what a step costs.

`unrolled_solver(solver)` (public as `jaxrb.unrolled_solver`) returns the written-out twin
of `diffrax.Tsit5`, `Dopri5` or `Dopri8` (anything else is returned as it is). A step falls
back to diffrax's own for what this does not cover: several terms, implicit tableaus, or
vector fields diffrax marks as expensive.
The twins take the same steps as diffrax's solvers; their results differ by roundoff (the
sums run in another order and skip the tableau's zeros).

Where it pays (benchmarks/README.md, "stages written out"):
- a batch as one solve on a GPU: B1 (the torque-free body, N = 1e6) on an NVIDIA H200,
  Dopri8 at tol 5e-10 in float64 0.63 -> 0.25 us per body, float32 Dopri8 at tol 1e-6
  0.16 -> 0.06 us. On a 2-core x86 CPU, where a batch runs in parts that fit a core's cache,
  it cost 0-10 % more: `batch_solver` uses the twins off a CPU only. (A batch sharing one
  free body goes further on a GPU: each step one kernel, `_fused_rotation_step.py`.)
- one body's forward runs, alone or under `jax.vmap`, on a CPU (B1, N = 1000, error < 1e-8:
  `jax.vmap(simulate)` with Dopri8 124 -> 30 us per body, with Tsit5 168 -> 56 us).
Where it costs: compiling. A reverse-mode gradient's backward pass holds every stage's
derivative written out (one free body's first gradient, Tsit5: 3.4 -> 5.1 s; Dopri8: 3.2 ->
9.3 s), and a contact simulation's right-hand side is large: the die's program compiled
4 s longer and ran no faster. So one body's solves keep diffrax's loop unless asked.
"""

import diffrax as dfx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp


def weighted_sum(coefficients, ks):
    """sum_j c_j k_j over the non-zero c_j (Python floats: the sum keeps the increments'
    dtype), or None if every c_j is zero."""
    terms = [(float(c), k) for c, k in zip(coefficients, ks, strict=True) if float(c) != 0.0]
    if not terms:
        return None

    def leaf(*k_leaves):
        inc = None
        for (c, _), k in zip(terms, k_leaves, strict=True):
            inc = c * k if inc is None else inc + c * k
        return inc

    return jax.tree.map(leaf, *[k for _, k in terms])


def combine_increments(y0, coefficients, ks):
    """y0 + sum_j c_j k_j over the non-zero c_j."""
    inc = weighted_sum(coefficients, ks)
    return y0 if inc is None else jax.tree.map(jnp.add, y0, inc)


def unrolled_step(solver, terms, t0, t1, y0, args, solver_state, made_jump):
    """One step of the explicit single-term `solver` with its stages written out; returns
    what `solver.step` returns (y1, error estimate, dense information, solver state,
    result), the dense information in diffrax's layout (`k`: each leaf stacked over the
    stages), so that the solver's own interpolation serves saves and events; None where
    diffrax's own step must be taken. An FSAL method (Tsit5) evaluates its first stage only
    on the first step or after a jump, as diffrax does."""
    tableau = solver.tableau
    if not isinstance(tableau, dfx.ButcherTableau) or tableau.implicit:
        return None
    if terms.is_vf_expensive(t0, t1, y0, args):
        return None
    fsal = tableau.fsal
    control = terms.contr(t0, t1)
    dt = t1 - t0

    if fsal:
        first_step, f_last = solver_state
        again = eqxi.unvmap_any(first_step | made_jump)
        f0 = jax.lax.cond(again, lambda: terms.vf(t0, y0, args), lambda: f_last)
        ks = [terms.prod(f0, control)]
    else:
        ks = [terms.vf_prod(t0, y0, args, control)]

    n_stages = len(tableau.c) + 1
    f1 = None
    y_stage = y0
    for i in range(1, n_stages):
        y_stage = combine_increments(y0, tableau.a_lower[i - 1], ks)
        c = float(tableau.c[i - 1])
        t_stage = t1 if c == 1.0 else t0 + c * dt  # as diffrax: exactly t1 at c = 1
        if fsal and i == n_stages - 1:
            f1 = terms.vf(t_stage, y_stage, args)
            k = terms.prod(f1, control)
        else:
            k = terms.vf_prod(t_stage, y_stage, args, control)
        # Each increment is computed once and read by the later stages: the barrier keeps
        # XLA from fusing a stage's right-hand side into every stage that reads it (and
        # computing it again there). On a CPU it changed nothing measurable; the GPU
        # figures above were measured with it.
        ks.append(jax.lax.optimization_barrier(k))

    y1 = y_stage if tableau.ssal else combine_increments(y0, tableau.b_sol, ks)
    y_error = weighted_sum(tableau.b_error, ks)
    if y_error is None:  # a tableau without an error estimate
        y_error = jax.tree.map(jnp.zeros_like, y0)
    k_stacked = jax.tree.map(lambda *k: jnp.stack(k), *ks)
    dense_info = dict(y0=y0, y1=y1, k=k_stacked)
    new_state = (jnp.array(False), f1) if fsal else None
    return y1, y_error, dense_info, new_state, dfx.RESULTS.successful


class _Unrolled:
    """The `step` of the written-out twins (see the module docstring)."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        out = unrolled_step(self, terms, t0, t1, y0, args, solver_state, made_jump)
        if out is None:
            return super().step(terms, t0, t1, y0, args, solver_state, made_jump)
        return out


class UnrolledTsit5(_Unrolled, dfx.Tsit5):
    """`diffrax.Tsit5` with its stages written out."""


class UnrolledDopri5(_Unrolled, dfx.Dopri5):
    """`diffrax.Dopri5` with its stages written out."""


class UnrolledDopri8(_Unrolled, dfx.Dopri8):
    """`diffrax.Dopri8` with its stages written out."""


_TWINS = {dfx.Tsit5: UnrolledTsit5, dfx.Dopri5: UnrolledDopri5, dfx.Dopri8: UnrolledDopri8}


def unrolled_solver(solver):
    """The written-out twin of a `diffrax.Tsit5`, `Dopri5` or `Dopri8` (its exact class, not
    a subclass); any other solver unchanged.

    The twin is the same method: the same tableau, steps, dense output and adjoints, with
    results equal to diffrax's to roundoff. Each step is traced as straight-line code instead
    of diffrax's loop over the stages. Pass it as `simulate`'s `solver` for many forward
    runs of one body without a floor: on a 2-core CPU, `jax.vmap(simulate)` of B1 cost 3-4x
    less per body. A reverse-mode gradient compiles 1.5-3x longer with it. A batch as one
    solve already uses it off a CPU (or, on a GPU, a step as one kernel); passed explicitly, a batch
    keeps it (one XLA kernel per stage). It is not for scenes with a floor: there it compiles
    longer and runs no faster."""
    twin = _TWINS.get(type(solver))
    if twin is None:
        return solver
    return twin(scan_kind=solver.scan_kind)


def batch_solver(solver):
    """The solver a batch integrated as one solve uses: the written-out twin (`unrolled_solver`)
    except on a CPU (see the module docstring for the measurements behind the choice)."""
    return solver if on_cpu() else unrolled_solver(solver)


def on_cpu() -> bool:
    return jax.default_backend() == "cpu"
