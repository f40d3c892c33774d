#!/usr/bin/env python3
"""IFToMM A04 Bricard mechanism -- independent cross-check of bricard_reference.csv.

Sources: see bricard_reference.py (IFToMM/Coruna benchmark A04, Gonzalez et al., Multibody
System Dynamics 16 (2006) 179-190; geometry as in Exudyn TestModels/bricardMechanism.py and
the OpenSim port RehabEngGroup/MBSbenchmarksInOpenSim).

Method 2 (independent of the joint-coordinate formulation of bricard_reference.py):
  absolute coordinates -- COM position r_i and unit quaternion q_i of each of the 5 rods,
  COM velocity v_i and spatial angular velocity w_i; Newton-Euler equations; the 6 revolute
  joints give 30 constraint rows (3 position + 2 axis-alignment rows each) of rank 29.
  Index-1 DAE: [M G^T; G 0][a; lambda] = [f; -gamma] solved by least squares (the
  accelerations are unique, lambda is the minimum-norm multiplier).  DOP853 (rtol 1e-12)
  between the 0.01 s output times; after each interval positions and velocities are
  projected back on the constraint manifold by minimum-norm (pseudo-inverse) corrections.
It also reruns method 1 at rtol 1e-13 to show how many digits of the CSV are converged.

Run:  python3 bricard_crosscheck.py    (after bricard_reference.py; ~2-4 min)
"""
import numpy as np
from scipy.integrate import solve_ivp
import bricard_reference as ref

P, AXES, C_REF, I_REF, M, GV = ref.P, ref.AXES, ref.C_REF, ref.I_REF, ref.M_ROD, ref.GVEC
NB = 5
# joint k: (body a, body b), -1 = ground.  Joint 0: ground-rod0, k=1..4: rod k-1 - rod k,
# joint 5: rod4-ground
JOINTS = [(-1, 0), (0, 1), (1, 2), (2, 3), (3, 4), (4, -1)]


def perp(e):
    u1 = np.cross(e, [1.0, 0, 0]) if abs(e[0]) < 0.9 else np.cross(e, [0, 1.0, 0])
    u1 /= np.linalg.norm(u1)
    return u1, np.cross(e, u1)


PERP = [perp(e) for e in AXES]


def qmat(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def unpack(y):
    r = y[0:15].reshape(5, 3)
    q = y[15:35].reshape(5, 4)
    v = y[35:50].reshape(5, 3)
    w = y[50:65].reshape(5, 3)
    return r, q, v, w


def constraints(r, R, w=None):
    """Constraint residual Phi (30), Jacobian G (30 x 30, w.r.t. (v_i, w_i) per body) and,
    if angular velocities w are given, the acceleration bias gamma (G a + gamma = 0)."""
    Phi, Gm, gam = np.zeros(30), np.zeros((30, 30)), np.zeros(30)
    for k, (ba, bb) in enumerate(JOINTS):
        row = 5 * k
        e = AXES[k]
        terms = []
        for sgn, b in ((1.0, ba), (-1.0, bb)):
            if b < 0:
                terms.append((sgn, b, P[k].copy(), np.zeros(3)))
            else:
                s = R[b] @ (P[k] - C_REF[b])
                terms.append((sgn, b, r[b] + s, s))
        Phi[row:row + 3] = terms[0][2] - terms[1][2]
        for sgn, b, x, s in terms:
            if b >= 0:
                Gm[row:row + 3, 6 * b:6 * b + 3] = sgn * np.eye(3)
                Gm[row:row + 3, 6 * b + 3:6 * b + 6] = -sgn * skew(s)
                if w is not None:
                    gam[row:row + 3] += sgn * np.cross(w[b], np.cross(w[b], s))
        Ra = np.eye(3) if ba < 0 else R[ba]
        Rb = np.eye(3) if bb < 0 else R[bb]
        B = Rb @ e
        for m, u in enumerate(PERP[k]):
            A = Ra @ u
            Phi[row + 3 + m] = A @ B
            AxB = np.cross(A, B)
            if ba >= 0:
                Gm[row + 3 + m, 6 * ba + 3:6 * ba + 6] = AxB
            if bb >= 0:
                Gm[row + 3 + m, 6 * bb + 3:6 * bb + 6] = -AxB
            if w is not None:
                wa = np.zeros(3) if ba < 0 else w[ba]
                wb = np.zeros(3) if bb < 0 else w[bb]
                dAxB = np.cross(np.cross(wa, A), B) + np.cross(A, np.cross(wb, B))
                gam[row + 3 + m] = dAxB @ (wa - wb)
    return Phi, Gm, gam


def rhs(t, y):
    r, q, v, w = unpack(y)
    R = [qmat(qi) for qi in q]
    _, Gm, gam = constraints(r, R, w)
    Mm, f = np.zeros((30, 30)), np.zeros(30)
    for i in range(NB):
        Ii = R[i] @ I_REF[i] @ R[i].T
        Mm[6 * i:6 * i + 3, 6 * i:6 * i + 3] = M * np.eye(3)
        Mm[6 * i + 3:6 * i + 6, 6 * i + 3:6 * i + 6] = Ii
        f[6 * i:6 * i + 3] = M * GV
        f[6 * i + 3:6 * i + 6] = -np.cross(w[i], Ii @ w[i])
    K = np.block([[Mm, Gm.T], [Gm, np.zeros((30, 30))]])
    sol = np.linalg.lstsq(K, np.concatenate([f, -gam]), rcond=1e-12)[0]
    acc = sol[:30].reshape(5, 6)
    qd = np.array([0.5 * qmul(np.concatenate([[0.0], w[i]]), q[i]) for i in range(NB)])
    return np.concatenate([v.ravel(), qd.ravel(), acc[:, :3].ravel(), acc[:, 3:].ravel()])


def project(y):
    r, q, v, w = (a.copy() for a in unpack(y))
    for it in range(10):
        R = [qmat(qi) for qi in q]
        Phi, Gm, _ = constraints(r, R)
        if np.abs(Phi).max() < 1e-15:
            break
        dx = -np.linalg.lstsq(Gm, Phi, rcond=1e-12)[0].reshape(5, 6)
        r += dx[:, :3]
        for i in range(NB):
            ang = np.linalg.norm(dx[i, 3:])
            dq = np.concatenate([[np.cos(ang / 2)], np.sinc(ang / 2 / np.pi) / 2 * dx[i, 3:]])
            q[i] = qmul(dq, q[i])
    q /= np.linalg.norm(q, axis=1)[:, None]
    R = [qmat(qi) for qi in q]
    Phi, Gm, _ = constraints(r, R)
    nu = np.hstack([v, w]).ravel()
    nu -= np.linalg.lstsq(Gm, Gm @ nu, rcond=1e-12)[0]
    nu = nu.reshape(5, 6)
    return np.concatenate([r.ravel(), q.ravel(), nu[:, :3].ravel(), nu[:, 3:].ravel()]), np.abs(Phi).max()


def outputs(y):
    r, q, v, w = unpack(y)
    R = [qmat(qi) for qi in q]
    T = sum(0.5 * M * v[i] @ v[i] + 0.5 * w[i] @ (R[i] @ I_REF[i] @ R[i].T) @ w[i] for i in range(NB))
    V = sum(M * ref.G * r[i][1] for i in range(NB))
    p3 = r[2] + R[2] @ (P[3] - C_REF[2])
    Phi, Gm, _ = constraints(r, R)
    vres = np.abs(Gm @ np.hstack([v, w]).ravel()).max()
    return p3, T, V, np.abs(Phi).max(), vres


def method2(rtol=1e-12, atol=1e-13, dt=0.01, tend=10.0):
    y = np.concatenate([np.array(C_REF).ravel(), np.tile([1.0, 0, 0, 0], NB), np.zeros(30)])
    rows, maxres = [], 0.0
    n = int(round(tend / dt))
    for k in range(n + 1):
        p3, T, V, pres, vres = outputs(y)
        rows.append([k * dt, *p3, T, V, pres, vres])
        if k == n:
            break
        sol = solve_ivp(rhs, (k * dt, (k + 1) * dt), y, method="DOP853", rtol=rtol, atol=atol)
        y, res_before = project(sol.y[:, -1])
        maxres = max(maxres, res_before)
    return np.array(rows), maxres


if __name__ == "__main__":
    csv = np.loadtxt("bricard_reference.csv", delimiter=",", skiprows=1)
    # method 1 at a tighter tolerance
    m1, _ = ref.run(1e-13, 1e-14)
    d1 = np.abs(m1[:, 1:6] - csv[:, 1:6]).max(axis=0)
    print("method 1, rtol 1e-13 vs CSV (rtol 1e-12): max diff p3x p3y p3z T V:",
          " ".join("%.1e" % x for x in d1))
    m2, maxres = method2()
    d2 = np.abs(m2[:, 1:6] - csv[:, 1:6]).max(axis=0)
    print("method 2 (Cartesian DAE) vs CSV: max diff p3x p3y p3z T V:", " ".join("%.1e" % x for x in d2))
    E = m2[:, 4] + m2[:, 5]
    print("method 2: max |E-E0| = %.2e J; max constraint residual before projection %.1e, "
          "after projection %.1e; max velocity residual %.1e" %
          (np.abs(E - E[0]).max(), maxres, m2[:, 6].max(), m2[:, 7].max()))
    for t in (1.0, 2.0, 5.0, 10.0):
        k = int(round(t / 0.01))
        print("t=%g method2 P3 = (%.10f, %.10f, %.10f)  T = %.10f" % (t, *m2[k, 1:5]))
