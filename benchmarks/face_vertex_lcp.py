"""A face's contact as the linear complementarity problem of its vertices, each with its own
normal force and Coulomb friction along its own slip, at a state of a random throw: the check
behind docs/contact.md section 7's account of a d12 that neither a face's limit surface nor
a pair fits, and that a face on a support of three vertices (section 2) does.

The throw (`contact_throws.throws(n, seed)[index]`, the d12 of `jaxrb.dice`) is simulated to
time `--t` and the face whose vertices are lowest is taken. With the body's mass matrix M
(world, about the mass centre), each vertex i at offset r_i with unit slip s_i has the normal
row J_i = (n, r_i x n) and the force column C_i = (n - mu s_i, r_i x (n - mu s_i)); the normal
accelerations are a = A lambda + b, A = J M^-1 C^T, b those without contact forces (gravity,
the gyroscopic and centripetal terms). Every active set S of vertices is tried: lambda_S >= 0
with A_SS lambda_S = -b_S (non-negative least squares, residual at roundoff) and a_i >= 0
off S. The consistent sets are printed with their forces (N) and the other vertices'
accelerations (m/s^2).

Run: python -m benchmarks.face_vertex_lcp --n 100 --index 24 --t 1.184364
"""

import argparse
import itertools

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import nnls  # noqa: E402

import jaxrb  # noqa: E402

try:
    from . import contact_throws as T
except ImportError:
    import contact_throws as T  # type: ignore

G = 9.81


def state_at(kind, n, seed, index, t):
    """The scene (with the throw's floor) and the state of throw `index` at time `t` (s)."""
    mass, make_shape, _, _ = T.shape_of(kind)
    state, restitution, friction = T.throws(n, seed)
    state0 = jax.tree.map(lambda x: x[index], state)
    floor = jaxrb.Floor(restitution[index], friction[index])
    scene = jaxrb.Scene(jaxrb.RigidBody(mass, shape=make_shape()), (jaxrb.Gravity(),), floor=floor)
    tr = jaxrb.simulate(
        scene, state0, jnp.array([0.0, t]), max_impacts=200, throw=False, rtol=1e-8, atol=1e-8
    )
    return scene, jax.tree.map(lambda x: np.asarray(x[-1]), tr.states), int(tr.contact.kind[-1])


def vertex_kinematics(scene, state, vertices):
    """(inertia tensor (3, 3, kg m^2), angular velocity (3,, rad/s), offsets from the mass
    centre (K, 3, m), slips (K, 3, m/s)) of `vertices` (body-frame offsets (K, 3)) of a
    body at `state` on the floor (normal +z), all in the world frame."""
    R = np.asarray(jaxrb.quat_to_matrix(jnp.asarray(state.quat)))
    inertia = R @ np.asarray(scene.body.inertia_matrix) @ R.T
    w = R @ np.asarray(state.omega)
    r = np.asarray(vertices) @ R.T
    vel = np.asarray(state.vel) + np.cross(w, r)
    slip = vel * np.array([1.0, 1.0, 0.0])
    return inertia, w, r, slip


def vertex_problem(scene, state, vertices):
    """(A, b, slips) of `vertices` (body-frame offsets from the mass centre (K, 3), m) of a
    body on the floor (normal +z), each vertex with its own Coulomb friction along its own
    slip: a = A f + b, a the vertices' normal accelerations (m/s^2), f their normal forces
    (N); A = J M^-1 C^T with J_i = (n, r_i x n), C_i = (n - mu s_i, r_i x (n - mu s_i)), b the
    accelerations without contact force (gravity, the gyroscopic and centripetal terms; the
    drag of the mass centre is horizontal here); slips (K, 3) world (m/s)."""
    body, mu = scene.body, float(scene.floor.friction)
    inertia, w, r, slip = vertex_kinematics(scene, state, vertices)
    n = np.array([0.0, 0.0, 1.0])
    s_hat = slip / np.linalg.norm(slip, axis=1, keepdims=True)
    w_dot = np.linalg.solve(inertia, -np.cross(w, inertia @ w))  # without contact forces
    m_inv = np.zeros((6, 6))
    m_inv[:3, :3] = np.eye(3) / float(body.mass)
    m_inv[3:, 3:] = np.linalg.inv(inertia)
    J = np.concatenate([np.broadcast_to(n, r.shape), np.cross(r, n)], axis=1)
    force = n - mu * s_hat
    C = np.concatenate([force, np.cross(r, force)], axis=1)
    b = -G + (np.cross(w_dot, r) + np.cross(w, np.cross(w, r))) @ n
    return J @ m_inv @ C.T, b, slip


def consistent_sets(A, b, tol=1e-9):
    """Every active set of the complementarity problem a = A lambda + b that has a solution:
    (set, lambda, accelerations of the others)."""
    k = len(b)
    found = []
    for size in range(1, k + 1):
        for active in itertools.combinations(range(k), size):
            active = list(active)
            others = [i for i in range(k) if i not in active]
            lam_active, residual = nnls(A[np.ix_(active, active)], -b[active])
            if residual > tol * (1.0 + np.linalg.norm(b)):
                continue
            lam = np.zeros(k)
            lam[active] = lam_active
            a = A @ lam + b
            if np.all(a[others] >= -tol * (1.0 + np.linalg.norm(b))):
                found.append((active, lam, a[others]))
    return found


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--kind", default="d12", help="a shape of contact_throws (a die)")
    p.add_argument("--n", type=int, default=100, help="throws drawn (as contact_throws --n)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--index", type=int, default=24, help="which throw")
    p.add_argument("--t", type=float, default=1.184364, help="time of the state (s)")
    a = p.parse_args(argv)
    jaxrb.speed_up_compilation(cache=False)
    scene, state, mode_kind = state_at(a.kind, a.n, a.seed, a.index, a.t)
    body = scene.body
    R = np.asarray(jaxrb.quat_to_matrix(jnp.asarray(state.quat)))
    heights = state.pos[2] + np.asarray(body.shape.vertices) @ R.T[:, 2]
    face = max(body.shape.faces, key=lambda f: -max(heights[list(f)]))
    points = list(face)
    A, b, slip = vertex_problem(scene, state, np.asarray(body.shape.vertices)[points])
    print(f"{a.kind} throw {a.index} at t = {a.t} s: engine's mode kind {mode_kind}")
    print(f"friction {float(scene.floor.friction):.4f}; face vertices {points}")
    print("heights (m):", np.array2string(heights[points], precision=3))
    print("slip speeds (mm/s):", np.array2string(np.linalg.norm(slip, axis=1) * 1e3, precision=3))
    sym = np.linalg.eigvalsh(0.5 * (A + A.T))
    print("eigenvalues of A's symmetric part (1/kg):", np.array2string(sym, precision=4))
    found = consistent_sets(A, b)
    for active, lam, a_others in found:
        print(
            f"consistent: active {[points[i] for i in active]}, normal forces (N) "
            f"{np.array2string(lam, precision=6)}, others' accelerations "
            f"{np.array2string(a_others, precision=3)}"
        )
    print(f"{len(found)} consistent active sets")


if __name__ == "__main__":
    main()
