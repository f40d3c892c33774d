#!/usr/bin/env python3
"""IFToMM multibody benchmark A04 -- Bricard mechanism: independent reference solution.

Sources
-------
* Problem: IFToMM TC multibody benchmark library, problem A04 "Bricard's mechanism"
  (originally the Coruna MBS benchmark: M. Gonzalez, D. Dopico, U. Lugris, J. Cuadrado,
  "A benchmarking system for MBS simulation software: problem standardization and
  performance measurement", Multibody System Dynamics 16 (2006) 179-190).
  R. Bricard, "Memoire sur la theorie de l'octaedre articule", J. Math. Pures Appl. (1897).
* Geometry/axes as in Exudyn `main/pythonDev/TestModels/bricardMechanism.py`
  (jgerstmayr/EXUDYN) and the OpenSim port RehabEngGroup/MBSbenchmarksInOpenSim
  (`src/A04-BricardsMechanism/createModel.cpp`: rods 1 kg, 1 m, 0.1 m square section,
  inertia = brick), as summarised in shared/reference/benchmarks.md, section "A04".

Definition used
---------------
Joint points P0..P5 = (0,0,0), (1,0,0), (1,-1,0), (1,-1,1), (0,-1,1), (0,0,1) m,
joint axes (global, initial configuration) y, z, x, y, z, x.  Rod i (i = 0..4) runs from
P_i to P_{i+1}; joint P0: ground-rod0, joint P_i: rod(i-1)-rod(i), joint P5: rod4-ground.
Rods: m = 1 kg, uniform 1 x 0.1 x 0.1 m box, COM at mid-point,
J_axial = m(0.1^2+0.1^2)/12, J_transverse = m(1^2+0.1^2)/12.
Gravity 9.81 m/s^2 along -y, V = sum m g y_COM.  At rest at t = 0.  t in [0, 10] s.

Method 1 (primary, "minimal coordinate"):
  relative joint angles theta_0..theta_5 of the open chain ground-rod0-...-rod4, closed by
  joint 5.  The loop closure (6 equations, rank 5) is solved for theta_1..theta_5 by a
  least-squares Gauss-Newton iteration for given theta_0 (residual < 1e-14); velocities and
  accelerations come from the 1-D null space of the 6x6 loop twist matrix (SVD), and the
  equation of motion is the virtual-power balance projected on that null space.
  The resulting scalar ODE in (theta_0, dtheta_0/dt) is integrated with DOP853.
Method 2 (cross-check, see bricard_crosscheck.py): absolute coordinates, quaternions,
  Newton-Euler equations, index-1 DAE with least-squares multipliers and projection.

Run:  python3 bricard_reference.py   (writes bricard_reference.csv and bricard_theta0.csv
= time, theta0, dtheta0/dt; prints the tables used in bricard_reference.md; numpy, scipy; ~10 s).
"""
import numpy as np
from scipy.integrate import solve_ivp

L, M_ROD, W, G = 1.0, 1.0, 0.1, 9.81
P = np.array([[0, 0, 0], [L, 0, 0], [L, -L, 0], [L, -L, L], [0, -L, L], [0, 0, L]], float)
EX, EY, EZ = np.eye(3)
AXES = [EY, EZ, EX, EY, EZ, EX]
J_AX = M_ROD * (W**2 + W**2) / 12.0
J_TR = M_ROD * (L**2 + W**2) / 12.0
GVEC = np.array([0.0, -G, 0.0])
# inertia about the COM of rod i in the initial (reference) configuration, global axes
DIRS = [(P[i + 1] - P[i]) / L for i in range(5)]
I_REF = [J_TR * np.eye(3) + (J_AX - J_TR) * np.outer(d, d) for d in DIRS]
C_REF = [(P[i] + P[i + 1]) / 2 for i in range(5)]


def rot(a, t):
    """Rotation matrix for angle t about the unit axis a (Rodrigues)."""
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def kin(th):
    """Forward kinematics of the open chain.  Returns rod rotations R[0..4], current joint
    points p[0..5], current joint axes a[0..5], rod COMs c[0..4] and the closure residual."""
    R, p, a, c = [], [P[0].copy()], [], []
    Rp = np.eye(3)
    for i in range(5):
        a.append(Rp @ AXES[i])
        Ri = Rp @ rot(AXES[i], th[i])
        R.append(Ri)
        c.append(p[i] + Ri @ (C_REF[i] - P[i]))
        p.append(p[i] + Ri @ (P[i + 1] - P[i]))
        Rp = Ri
    a.append(R[4] @ AXES[5])
    Rend = R[4] @ rot(AXES[5], th[5])          # must be the identity (ground)
    S = 0.5 * (Rend - Rend.T)
    res = np.concatenate([p[5] - P[5], [S[2, 1], S[0, 2], S[1, 0]]])
    return R, p, a, c, res


def twists(p, a):
    """6x6 matrix whose columns are the spatial joint twists (a_j, p_j x a_j)."""
    return np.array([np.concatenate([a[j], np.cross(p[j], a[j])]) for j in range(6)]).T


def close_loop(th0, guess):
    """Solve the loop closure for theta_1..theta_5 at given theta_0 (Gauss-Newton, lstsq)."""
    th = np.concatenate([[th0], guess])
    for it in range(50):
        R, p, a, c, res = kin(th)
        if np.max(np.abs(res)) < 1e-14:
            return th, res
        # derivative of (position of p5, rotation vector of Rend) w.r.t. theta_1..5
        Jn = np.array([np.concatenate([np.cross(a[j], p[5] - p[j]), a[j]]) for j in range(1, 6)]).T
        th[1:] -= np.linalg.lstsq(Jn, res, rcond=None)[0]
    raise RuntimeError("loop closure did not converge at theta0=%r (res %.3e)" % (th0, np.max(np.abs(res))))


def ad(V, xi):
    w, v = V[:3], V[3:]
    return np.concatenate([np.cross(w, xi[:3]), np.cross(w, xi[3:]) + np.cross(v, xi[:3])])


class Bricard:
    def __init__(self):
        self.guess = np.zeros(5)
        self.last_th0 = 0.0
        self.last_slope = np.zeros(5)

    def state(self, th0, thd0):
        """Full configuration and velocities for the minimal state (theta0, dtheta0)."""
        guess = self.guess + self.last_slope * (th0 - self.last_th0)
        th, res = close_loop(th0, guess)
        R, p, a, c, res = kin(th)
        Xi = twists(p, a)
        U, s, Vt = np.linalg.svd(Xi)
        n = Vt[-1]
        n = n / n[0]                               # parameterise by theta_0
        self.guess, self.last_th0, self.last_slope = th[1:].copy(), th0, n[1:].copy()
        thd = n * thd0
        return dict(th=th, thd=thd, R=R, p=p, a=a, c=c, res=res, Xi=Xi, n=n, sv=s)

    def body_vel(self, S, thd):
        """Spatial twists V_i of the rods (i = 0..4) and of the 'upstream' bodies."""
        V, acc = [], np.zeros(6)
        for j in range(5):
            acc = acc + thd[j] * S["Xi"][:, j]
            V.append(acc.copy())
        return V

    def rhs(self, t, y):
        S = self.state(y[0], y[1])
        Xi, thd, n = S["Xi"], S["thd"], S["n"]
        V = self.body_vel(S, thd)
        Vup = [np.zeros(6)] + V                    # twist of the body carrying joint j
        xid = [ad(Vup[j], Xi[:, j]) for j in range(6)]
        bias = sum(thd[j] * xid[j] for j in range(6))
        thdd_p = -np.linalg.lstsq(Xi, bias, rcond=None)[0]

        def virtual_power(sdd):
            thdd = thdd_p + n * sdd
            F, Vd, dV = 0.0, np.zeros(6), np.zeros(6)
            for i in range(5):
                Vd = Vd + thdd[i] * Xi[:, i] + thd[i] * xid[i]
                dV = dV + n[i] * Xi[:, i]
                w, v, wd, vd = V[i][:3], V[i][3:], Vd[:3], Vd[3:]
                c = S["c"][i]
                vc = v + np.cross(w, c)
                ac = vd + np.cross(wd, c) + np.cross(w, vc)
                Ii = S["R"][i] @ I_REF[i] @ S["R"][i].T
                dw, dvc = dV[:3], dV[3:] + np.cross(dV[:3], c)
                F += M_ROD * (ac - GVEC) @ dvc + (Ii @ wd + np.cross(w, Ii @ w)) @ dw
            return F

        F0 = virtual_power(0.0)
        sdd = -F0 / (virtual_power(1.0) - F0)
        return [y[1], thdd_p[0] + sdd]

    def outputs(self, th0, thd0):
        S = self.state(th0, thd0)
        V = self.body_vel(S, S["thd"])
        T = Vp = 0.0
        for i in range(5):
            w, v, c = V[i][:3], V[i][3:], S["c"][i]
            vc = v + np.cross(w, c)
            Ii = S["R"][i] @ I_REF[i] @ S["R"][i].T
            T += 0.5 * M_ROD * vc @ vc + 0.5 * w @ Ii @ w
            Vp += M_ROD * G * c[1]
        # P3 as carried by rod 2 (chain from P0) and by rod 3 going the other way round
        # (ground -> joint 5 -> rod 4 -> rod 3): an independent closure check
        p3_a = S["p"][3]
        R4 = rot(EX, -S["th"][5])                  # rod 4 orientation seen from the ground
        R3 = R4 @ rot(EZ, -S["th"][4])
        p4_b = P[5] + R4 @ (P[4] - P[5])
        p3_b = p4_b + R3 @ (P[3] - P[4])
        # constraint velocity residual: sum of joint twists times rates must vanish
        vres = np.max(np.abs(S["Xi"] @ S["thd"]))
        return dict(S=S, T=T, V=Vp, p3=p3_a, p3_gap=np.max(np.abs(p3_a - p3_b)),
                    res=np.max(np.abs(S["res"])), vres=vres)


def run(rtol, atol, dt=0.01, tend=10.0):
    sysm = Bricard()
    t_out = np.round(np.arange(0, tend + dt / 2, dt), 10)
    sol = solve_ivp(sysm.rhs, (0, tend), [0.0, 0.0], method="DOP853", t_eval=t_out,
                    rtol=rtol, atol=atol)
    assert sol.success, sol.message
    rows = []
    out = Bricard()
    for k, t in enumerate(sol.t):
        o = out.outputs(sol.y[0, k], sol.y[1, k])
        rows.append([t, *o["p3"], o["T"], o["V"], sol.y[0, k], sol.y[1, k],
                     o["res"], o["vres"], o["p3_gap"], o["S"]["sv"][-2], o["S"]["sv"][-1]])
    return np.array(rows), sol.nfev


if __name__ == "__main__":
    tight, nf_t = run(1e-12, 1e-13)
    loose, nf_l = run(1e-10, 1e-11)
    # columns: 0 t, 1-3 P3, 4 T, 5 V, 6 theta0, 7 dtheta0, 8 closure res, 9 velocity res,
    #          10 P3 gap, 11 sigma5, 12 sigma6
    np.savetxt("bricard_reference.csv", tight[:, :6], delimiter=",", comments="",
               header="time,p3_x,p3_y,p3_z,kinetic,potential", fmt="%.12f")
    np.savetxt("bricard_theta0.csv", tight[:, [0, 6, 7]], delimiter=",", comments="",
               header="time,theta0,theta0_dot", fmt="%.12f")
    for name, r, nf in (("rtol 1e-12", tight, nf_t), ("rtol 1e-10", loose, nf_l)):
        E = r[:, 4] + r[:, 5]
        print("%s: nfev %d, E0 = %.12f J, max |E-E0| = %.2e J (relative %.2e)" %
              (name, nf, E[0], np.abs(E - E[0]).max(), np.abs(E - E[0]).max() / abs(E[0])))
    print("max closure residual %.2e, max velocity-closure residual %.2e, "
          "max P3 gap (two ways round the loop) %.2e" %
          (tight[:, 8].max(), tight[:, 9].max(), tight[:, 10].max()))
    print("loop twist matrix: min sigma5 = %.3f, max sigma6 = %.1e" %
          (tight[:, 11].min(), tight[:, 12].max()))
    print("theta0 range [%.6f, %.6f] rad" % (tight[:, 6].min(), tight[:, 6].max()))
    d = np.abs(tight[:, 1:8] - loose[:, 1:8]).max(axis=0)
    print("max |tight - loose| for p3x p3y p3z T V theta0 dtheta0:", " ".join("%.1e" % x for x in d))
    print("\n| t [s] | p3_x [m] | p3_y [m] | p3_z [m] | kinetic [J] | potential [J] | theta0 [rad] | dtheta0/dt [rad/s] |")
    print("|---|---|---|---|---|---|---|---|")
    for t in (1.0, 2.0, 5.0, 10.0):
        r = tight[int(round(t / 0.01))]
        print("| %g | %.10f | %.10f | %.10f | %.10f | %.10f | %.10f | %.10f |" % tuple(r[:8]))
