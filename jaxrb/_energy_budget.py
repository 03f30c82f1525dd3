"""The energy budget of a trajectory: the work of the forces without a potential, and the
solver's drift.

E(t) (J) is kinetic plus potential energy (`jaxrb.energy`): gravity has a potential; drag,
damping moments and applied wrenches do not. Those forces do the work

    W(t) = integral from t_0 to t of P dt',   P = F . v_C + M_C . omega

(F world frame, at the mass centre; M_C about it, body frame; each with its own velocity),
integrated over the save times (on each interval, the cubic through the four nearest
saves: fourth order); W <= 0 for drag and damping. A
joint's reaction does no work (its point does not move). Without a floor, physics says
E(t) = E(0) + W(t), so what is left, E(t) - E(0) - W(t), is the solver's drift (plus the
quadrature error of W, where W is not zero). With a floor, impacts and sliding friction also
take energy, and the work of sliding friction is not recorded: there the drift is not
separated from physics.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cumulative_integral", "energy_budget", "has_potential"]


def has_potential(force) -> bool:
    """Whether the force model has a potential energy (it overrides `potential_energy`)."""
    import jaxrb

    return type(force).potential_energy is not jaxrb.AbstractForce.potential_energy


def _power(traj, scene, forces) -> np.ndarray:
    """P(t) (W) of `forces` at each save time: F . v_C + M_C . omega."""
    import jax
    import jax.numpy as jnp

    def power(t, state):
        total = jnp.zeros_like(state.pos[..., 0])
        for force in forces:
            f, m = force.wrench(t, state, scene.body)
            total = total + jnp.sum(f * state.vel, axis=-1) + jnp.sum(m * state.omega, axis=-1)
        return total

    return np.asarray(jax.jit(jax.vmap(power))(traj.ts, traj.states), dtype=float)


def cumulative_integral(t, p) -> np.ndarray:
    """integral from t_0 to t_i of p dt at every sample t_i (increasing; any spacing).

    On each interval, the integral of the cubic through the four nearest samples (fourth-order
    accurate for smooth p); with fewer than four samples, the trapezoidal rule.
    """
    t, p = np.asarray(t, dtype=float), np.asarray(p, dtype=float)
    n = t.size
    if n < 4:
        return np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t))])
    nodes = np.clip(np.arange(n - 1) - 1, 0, n - 4)[:, None] + np.arange(4)  # (n - 1, 4)
    h = np.diff(t)
    x = (t[nodes] - t[:-1, None]) / h[:, None]  # the nodes, the interval scaled to [0, 1]
    # quadrature weights w: sum_j w_j x_j^k = integral_0^1 x^k dx = 1 / (k + 1), k = 0..3
    vandermonde_t = np.swapaxes(x[:, :, None] ** np.arange(4), 1, 2)
    moments = np.broadcast_to(1.0 / np.arange(1, 5), (n - 1, 4))[..., None]
    w = np.linalg.solve(vandermonde_t, moments)[..., 0]
    return np.concatenate([[0.0], np.cumsum(h * np.sum(w * p[nodes], axis=-1))])


def energy_budget(traj, scene) -> dict:
    """The energy budget of an unbatched trajectory (numpy arrays, one entry per save).

    **Returns:** a dict with `energy` E(t) (J); `work` W(t) (J) of the forces without a
    potential (zeros if there are none); `nonpotential` (their class names); `drift`
    E(t) - E(0) - W(t) (J), or None for a scene with a floor.
    """
    from ._host import energy as host_energy

    energy = np.asarray(host_energy(scene, traj.states), dtype=float)
    forces = [f for f in scene.forces if not has_potential(f)]
    work = np.zeros_like(energy)
    if forces:
        work = cumulative_integral(traj.ts, _power(traj, scene, forces))
    drift = None if scene.floor is not None else energy - energy[0] - work
    names = [type(f).__name__ for f in forces]
    return {"energy": energy, "work": work, "nonpotential": names, "drift": drift}
