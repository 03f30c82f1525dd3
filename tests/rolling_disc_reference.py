"""The rolling disc (a coin of radius r and thickness 2h rolling without slipping on the rim
of one cap on a level floor), by Kane's method in sympy.physics.mechanics: an independent
reference for jaxrb's contact engine (nothing here uses jaxrb).

Coordinates: yaw q1 (about N.z), lean q2 (about A.x), spin q3 (about B.y, the disc's axis),
contact point (q4, q5) on the floor; generalised speeds u1..u3 = the body's angular velocity
in B, u4, u5 = the contact point's velocity (dependent: no slip).
"""

import numpy as np
import sympy as sp
import sympy.physics.mechanics as me


def rolling_disc_rhs(m, r, h, g):
    """The equations of motion as a numpy right-hand side over y = (q1..q5, u1..u3), and
    `extras(y)`: the mass centre (world, m), the body axes of a cylinder whose z axis is
    the disc's axis (rows: x, y, z in world components), the angular velocity (world,
    rad/s) and the mass centre's velocity (world, m/s)."""
    q1, q2, q3, q4, q5 = me.dynamicsymbols("q1:6")  # yaw, lean, spin, contact x, y
    q1d, q2d, q3d, q4d, q5d = me.dynamicsymbols("q1:6", 1)
    qs, qds = [q1, q2, q3, q4, q5], [q1d, q2d, q3d, q4d, q5d]
    u1, u2, u3, u4, u5 = me.dynamicsymbols("u1:6")
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Axis", [q1, N.z])
    B = A.orientnew("B", "Axis", [q2, A.x])
    C = B.orientnew("C", "Axis", [q3, B.y])
    C.set_ang_vel(N, u1 * B.x + u2 * B.y + u3 * B.z)
    origin = me.Point("O")
    origin.set_vel(N, 0)
    P = origin.locatenew("P", q4 * N.x + q5 * N.y)  # the contact point on the floor
    P.set_vel(N, u4 * N.x + u5 * N.y)
    G = P.locatenew("G", r * B.z + h * B.y)  # mass centre: over the contacting cap's centre
    # express the angular velocity through the angle rates
    w_angles = q1d * N.z + q2d * A.x + q3d * B.y
    kd_eqs = [
        u1 - w_angles.dot(B.x),
        u2 - w_angles.dot(B.y),
        u3 - w_angles.dot(B.z),
        u4 - q4d,
        u5 - q5d,
    ]
    rates = zip(qs, qds, strict=True)
    G.set_vel(N, sum((G.pos_from(origin).diff(q, N) * qd for q, qd in rates), me.Vector(0)))
    kin = sp.solve(kd_eqs, [q1d, q2d, q3d, q4d, q5d], dict=True)[0]
    G.set_vel(N, G.vel(N).subs(kin))
    contact_vel = G.vel(N) + C.ang_vel_in(N).cross(P.pos_from(G))
    constraints = [contact_vel.dot(N.x), contact_vel.dot(N.y)]
    I_axis = m * r**2 / 2
    I_trans = m * (3 * r**2 + (2 * h) ** 2) / 12
    inertia = me.inertia(B, I_trans, I_axis, I_trans)
    disc = me.RigidBody("disc", G, C, m, (inertia, G))
    kane = me.KanesMethod(
        N,
        q_ind=[q1, q2, q3, q4, q5],
        u_ind=[u1, u2, u3],
        u_dependent=[u4, u5],
        kd_eqs=kd_eqs,
        velocity_constraints=constraints,
    )
    kane.kanes_equations([disc], [(G, -m * g * N.z)])
    states = [q1, q2, q3, q4, q5, u1, u2, u3, u4, u5]
    MM = kane.mass_matrix_full
    F = kane.forcing_full
    mm = sp.lambdify(states, MM, "numpy")
    ff = sp.lambdify(states, F, "numpy")
    dep = sp.solve(constraints, [u4, u5], dict=True)[0]
    dep_f = sp.lambdify([q1, q2, q3, q4, q5, u1, u2, u3], [dep[u4], dep[u5]], "numpy")
    gpos = sp.lambdify([q1, q2, q3, q4, q5], [G.pos_from(origin).dot(v) for v in (N.x, N.y, N.z)])
    # body axes of the cylinder: z = the disc's axis B.y (the contacting cap at -h), x = C.z,
    # y = C.x (right-handed), as rows of world components
    axes = sp.lambdify(
        [q1, q2, q3],
        sp.Matrix(
            [
                [C.z.dot(v) for v in (N.x, N.y, N.z)],
                [C.x.dot(v) for v in (N.x, N.y, N.z)],
                [C.y.dot(v) for v in (N.x, N.y, N.z)],
            ]
        ),
    )
    wvec = sp.lambdify(states, [C.ang_vel_in(N).dot(v) for v in (N.x, N.y, N.z)])
    gvel = sp.lambdify(states, [G.vel(N).dot(v) for v in (N.x, N.y, N.z)])

    def rhs(t, y):
        q, ui = y[:5], y[5:8]
        ud = np.asarray(dep_f(*q, *ui), float).ravel()
        full = np.concatenate([q, ui, ud])
        sol = np.linalg.solve(np.asarray(mm(*full), float), np.asarray(ff(*full), float).ravel())
        return sol[:8]

    def extras(y):
        q, ui = y[:5], y[5:8]
        ud = np.asarray(dep_f(*q, *ui), float).ravel()
        full = np.concatenate([q, ui, ud])
        return (
            np.asarray(gpos(*q), float),
            np.asarray(axes(*q[:3]), float),
            np.asarray(wvec(*full), float),
            np.asarray(gvel(*full), float),
        )

    return rhs, extras
