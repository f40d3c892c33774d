"""Flexible slider crank (B. Simeon's data, IVP Test Set 'crank'): continuum reference solution.

Mechanism (SI units), planar, no gravity, no damping:
  crank O-A rigid, |OA| = L1 = 0.15, phi1(t) = OMEGA t prescribed, OMEGA = 150 rad/s,
      O at the origin, so A(t) = L1 (cos OMEGA t, sin OMEGA t);
  connecting rod A-B: initially straight, unstressed length L2 = 0.30, square section
      8 x 8 mm (A = 6.4e-5 m^2, I = 3.41333e-10 m^4), E = 2e11 Pa, rho = 7870 kg/m^3
      (rod mass 0.151104 kg), nu = 0.3 (only for the Reissner shear stiffness);
      revolute joints at A (crank pin) and at B (slider), i.e. rod end rotations free;
  slider: point mass M3 = 0.075552 kg at B, B on the line y = 0 (no offset).

Two independent planar geometrically exact discretizations (absolute nodal coordinates,
constant mass matrix; joint conditions are coordinate constraints and are eliminated):
  ancf      ANCF cable, cubic Hermite (nodal position + slope): extensible Kirchhoff
            (Euler-Bernoulli) rod, W = 1/2 int (EA eps^2 + EI kappa^2) ds with
            eps = |r'| - 1, kappa = (r' x r'')/|r'|^2; kinetic energy 1/2 int rho A |r_t|^2 ds
            (no rotary inertia); 5-point Gauss quadrature.
  reissner  Reissner/Simo beam, quadratic Lagrange elements, nodal (x, y, theta),
            Gamma1 = e1(theta).r' - 1, Gamma2 = e2(theta).r', kappa = theta';
            W = 1/2 int (EA G1^2 + ks G A G2^2 + EI kappa^2) ds, ks = 5/6, 2-point Gauss
            (reduced) for the strain energy; kinetic energy with rho A and rho I.
  reissner_eb  the same with G A x 1e3 and rho I -> 1e-6 rho I (Kirchhoff limit), for a
            like-for-like comparison with 'ancf'.

Time integration: 3-stage Radau IIA collocation (order 5, stiffly accurate), fixed step,
written for M a = F(t, q) with the stage displacements as unknowns, simplified Newton with a
tangent stiffness refreshed every few steps; the linear algebra is decoupled through the
eigenvalues of A^-2 into one real and one complex banded system (LAPACK gbtrf/gbtrs).

Initial conditions (t = 0, crank along +x):
  'T' (primary; the IVP Test Set start "close to smooth motion" mapped to the continuum):
      rod frame angle 0, chord-frame axial displacement u(s) = q3 Nm(s) + q4 Ne(s) with
      Nm = 4 xi (1 - xi), Ne = xi (2 xi - 1), xi = s/L2, lateral displacement 0,
      q3 = 1.03339863e-5 m, q4 = 1.69327969e-5 m; velocity field
      v(s) = v_A + dphi2 e_z x (r(s) - r_A) + (u_t(s), w_t(s)),  v_A = (0, 22.5) m/s,
      dphi2 = -74.99576703969453 rad/s, u_t = dq3 Nm + dq4 Ne,
      w_t = dq1 sin(pi xi) + dq2 sin(2 pi xi), dq1 = 0.444896112581599 m/s,
      dq2 = 4.63433931923867e-3 m/s, dq3 = -1.78591076000055e-6 m/s,
      dq4 = -2.68938671997904e-6 m/s.  Cross-section rotation = tangent angle.
  'U' (secondary): undeformed straight rod from (0.15, 0) to (0.45, 0), rigid-body velocity
      field v(s) = (0, 22.5 (1 - s/L2)) m/s, rod angular velocity -75 rad/s.

Outputs: slider position x_B and velocity, rod mid-point transverse deflection
  w_mid = (r(L2/2) - (r_A + r_B)/2) . n, n = e_z x (r_B - r_A)/|r_B - r_A|
  (material mid point, measured from the chord A-B, positive to the left of A->B),
  mid-point axial displacement u_mid = (r(L2/2) - r_A) . e1 - L2/2, chord stretch |AB| - L2.

Usage:
  python3 slider_crank_reference.py run MODEL NEL CASE H [T_END DT_OUT]
        one run (MODEL in ancf, reissner, reissner_eb, reissner_rigidshear, reissner_norot;
        CASE in T, U), saved as npz in ./_runs; the runs needed by the report are listed in
        slider_crank_report.py
  python3 slider_crank_reference.py validate     integrator check against scipy Radau
  python3 slider_crank_report.py                 tables of slider_crank_reference.md + CSV files
"""
import os
import sys
import time
import json
import numpy as np
from scipy.linalg import lapack

L1, L2 = 0.15, 0.30
OMEGA = 150.0
BB = HH = 0.008
EE, NU, RHO = 2.0e11, 0.3, 7870.0
M3 = 0.075552
AREA = BB * HH
II = BB * HH**3 / 12.0
GG = EE / (2 * (1 + NU))
KS = 5.0 / 6.0
EA, EI, GAs = EE * AREA, EE * II, KS * GG * AREA
RHOA, RHOI = RHO * AREA, RHO * II

TS = dict(dphi2=-7.499576703969453e+01,
          q=(0.0, 0.0, 1.033398630000000e-05, 1.693279690000000e-05),
          dq=(4.448961125815990e-01, 4.634339319238670e-03, -1.785910760000550e-06, -2.689386719979040e-06))

RUNDIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "_runs")


def crank_pin(t):
    c, s = np.cos(OMEGA * t), np.sin(OMEGA * t)
    return (np.array([L1 * c, L1 * s]), np.array([-L1 * OMEGA * s, L1 * OMEGA * c]),
            np.array([-L1 * OMEGA**2 * c, -L1 * OMEGA**2 * s]))


def rigid_slider_x(t):
    phi = OMEGA * np.asarray(t)
    return L1 * np.cos(phi) + np.sqrt(L2**2 - (L1 * np.sin(phi))**2)


def initial_fields(case):
    rA = np.array([L1, 0.0]); vA = np.array([0.0, L1 * OMEGA])
    if case == 'U':
        q = (0, 0, 0, 0); dq = (0, 0, 0, 0); dphi2 = -OMEGA * L1 / L2
    elif case == 'T':
        q, dq, dphi2 = TS['q'], TS['dq'], TS['dphi2']
    else:
        raise ValueError(case)
    pi = np.pi

    def fields(s):
        xi = s / L2
        Nm, Ne = 4 * xi * (1 - xi), xi * (2 * xi - 1)
        dNm, dNe = (4 - 8 * xi) / L2, (4 * xi - 1) / L2
        u = q[2] * Nm + q[3] * Ne; du = q[2] * dNm + q[3] * dNe
        w = q[0] * np.sin(pi * xi) + q[1] * np.sin(2 * pi * xi)
        dw = (q[0] * pi * np.cos(pi * xi) + q[1] * 2 * pi * np.cos(2 * pi * xi)) / L2
        ut = dq[2] * Nm + dq[3] * Ne; dut = dq[2] * dNm + dq[3] * dNe
        wt = dq[0] * np.sin(pi * xi) + dq[1] * np.sin(2 * pi * xi)
        dwt = (dq[0] * pi * np.cos(pi * xi) + dq[1] * 2 * pi * np.cos(2 * pi * xi)) / L2
        r = np.array([rA[0] + s + u, rA[1] + w])
        rs = np.array([1 + du, dw])
        rel = r - rA
        v = vA + dphi2 * np.array([-rel[1], rel[0]]) + np.array([ut, wt])
        vs = dphi2 * np.array([-rs[1], rs[0]]) + np.array([dut, dwt])
        theta = np.arctan2(dw, 1 + du)
        thetadot = dphi2 + (dwt * (1 + du) - dw * dut) / ((1 + du)**2 + dw**2)
        return r, rs, v, vs, theta, thetadot
    return fields


# ========================================================================================
class Model:
    def setup(self):
        n = self.ndof
        self.pdofs = np.array([d for d, _ in self.prescribed])
        self.fdofs = np.setdiff1d(np.arange(n), self.pdofs)
        self.Mff = self.M[np.ix_(self.fdofs, self.fdofs)]
        self.Mfp = self.M[np.ix_(self.fdofs, self.pdofs)]
        self.nf = len(self.fdofs)
        nz = np.nonzero(self.Mff)
        self.band = int(np.max(np.abs(nz[0] - nz[1])))
        # stiffness couples nodes within node_reach -> band in free-dof ordering
        self.band = max(self.band, (self.node_reach + 1) * self.dofs_per_node)

    def prescribed_values(self, t):
        rA, vA, aA = crank_pin(t)
        qp = np.zeros(len(self.pdofs)); vp = np.zeros_like(qp); ap = np.zeros_like(qp)
        for i, (_, kind) in enumerate(self.prescribed):
            if kind == 'Ax':
                qp[i], vp[i], ap[i] = rA[0], vA[0], aA[0]
            elif kind == 'Ay':
                qp[i], vp[i], ap[i] = rA[1], vA[1], aA[1]
        return qp, vp, ap

    def full(self, t, qf, which='q'):
        qf = np.atleast_2d(qf)
        q = np.empty((qf.shape[0], self.ndof))
        q[:, self.fdofs] = qf
        for k in range(qf.shape[0]):
            tk = t[k] if np.ndim(t) else t
            vals = self.prescribed_values(tk)[0 if which == 'q' else 1]
            q[k, self.pdofs] = vals
        return q

    def force(self, ts, Qf):
        """F(t, q) = -fint_f(q) - M_fp a_p(t) for a batch of stage states (k, nf)."""
        q = self.full(ts, Qf)
        f = -self.fint(q)[:, self.fdofs]
        for k, tk in enumerate(ts):
            f[k] -= self.Mfp @ self.prescribed_values(tk)[2]
        return f

    def stiffness(self, t, qf):
        """Tangent stiffness of the free dofs by grouped forward differences."""
        q = self.full(t, qf)[0]
        n = self.ndof
        dpn, r = self.dofs_per_node, self.node_reach
        stride = (2 * r + 1) * dpn
        groups = [np.arange(g, n, stride) for g in range(stride)]
        Q = np.repeat(q[None, :], stride + 1, axis=0)
        hs = []
        for g, cols in enumerate(groups):
            h = 1e-7 * np.maximum(1.0, np.abs(q[cols]))
            Q[g + 1, cols] += h; hs.append(h)
        F = self.fint(Q)
        K = np.zeros((n, n))
        for g, cols in enumerate(groups):
            df = F[g + 1] - F[0]
            for c, hc in zip(cols, hs[g]):
                node = c // dpn
                rows = np.arange(max(0, (node - r) * dpn), min(n, (node + r + 1) * dpn))
                K[rows, c] = df[rows] / hc
        return K[np.ix_(self.fdofs, self.fdofs)]

    def outputs(self, q, v):
        rA, rB, rM = self.point(q, 0.0), self.point(q, L2), self.point(q, 0.5 * L2)
        vB = self.point(v, L2)
        d = rB - rA
        chord = np.linalg.norm(d)
        e1 = d / chord
        n = np.array([-e1[1], e1[0]])
        w_mid = (rM - 0.5 * (rA + rB)) @ n
        u_mid = (rM - rA) @ e1 - 0.5 * L2
        return np.array([rB[0], vB[0], w_mid, u_mid, chord - L2])

    def energy(self, q, v):
        """Kinetic + strain energy of rod + slider (the crank is driven, so not conserved)."""
        return 0.5 * v @ self.M @ v + self.strain_energy(q)


# ----------------------------------------------------------------------------------------
class ANCF(Model):
    name = 'ancf'

    def __init__(self, nel, ngp=5):
        self.nel, self.le = nel, L2 / nel
        self.nnode, self.ndof = nel + 1, 4 * (nel + 1)
        self.dofs_per_node, self.node_reach = 4, 1
        le = self.le
        xg, wg = np.polynomial.legendre.leggauss(ngp)
        xi = 0.5 * (xg + 1); self.wg = 0.5 * wg * le
        self.S1 = np.stack([(-6 * xi + 6 * xi**2) / le, 1 - 4 * xi + 3 * xi**2,
                            (6 * xi - 6 * xi**2) / le, -2 * xi + 3 * xi**2], axis=1)
        self.S2 = np.stack([(-6 + 12 * xi) / le**2, (-4 + 6 * xi) / le,
                            (6 - 12 * xi) / le**2, (-2 + 6 * xi) / le], axis=1)
        xg6, wg6 = np.polynomial.legendre.leggauss(6)
        x6 = 0.5 * (xg6 + 1); w6 = 0.5 * wg6 * le
        S6 = self.shape(x6)
        me4 = RHOA * np.einsum('g,ga,gb->ab', w6, S6, S6)
        M = np.zeros((self.ndof, self.ndof))
        for e in range(nel):
            for a in range(4):
                for b in range(4):
                    ia, ib = 4 * e + 2 * a, 4 * e + 2 * b   # a: 0 x0-block,1 slope0,2 x1,3 slope1
                    for k in range(2):
                        M[ia + k, ib + k] += me4[a, b]
        last = 4 * nel
        M[last, last] += M3; M[last + 1, last + 1] += M3
        self.M = M
        self.prescribed = [(0, 'Ax'), (1, 'Ay'), (last + 1, 'zero')]
        self.setup()

    def shape(self, xi):
        le = self.le
        return np.stack([1 - 3 * xi**2 + 2 * xi**3, le * (xi - 2 * xi**2 + xi**3),
                         3 * xi**2 - 2 * xi**3, le * (-xi**2 + xi**3)], axis=-1)

    def _elem(self, q):
        nb = q.shape[0]
        Qn = q.reshape(nb, self.nnode, 4)
        E = np.concatenate([Qn[:, :-1, :], Qn[:, 1:, :]], axis=2)     # (nb, nel, 8)
        return E[..., 0::2], E[..., 1::2]

    def fint(self, q):
        q = np.atleast_2d(q)
        Ex, Ey = self._elem(q)
        x1 = Ex @ self.S1.T; y1 = Ey @ self.S1.T
        x2 = Ex @ self.S2.T; y2 = Ey @ self.S2.T
        d = x1**2 + y1**2; sd = np.sqrt(d)
        num = x1 * y2 - y1 * x2
        N = EA * (sd - 1); Mb = EI * num / d
        gx1 = (N * x1 / sd + Mb * (y2 / d - 2 * num * x1 / d**2)) * self.wg
        gy1 = (N * y1 / sd + Mb * (-x2 / d - 2 * num * y1 / d**2)) * self.wg
        gx2 = Mb * (-y1 / d) * self.wg
        gy2 = Mb * (x1 / d) * self.wg
        fx = gx1 @ self.S1 + gx2 @ self.S2
        fy = gy1 @ self.S1 + gy2 @ self.S2
        fe = np.empty(fx.shape[:2] + (8,)); fe[..., 0::2] = fx; fe[..., 1::2] = fy
        nb = q.shape[0]
        f = np.zeros((nb, self.nnode, 4))
        f[:, :-1, :] += fe[..., :4]; f[:, 1:, :] += fe[..., 4:]
        return f.reshape(nb, self.ndof)

    def strain_energy(self, q):
        Ex, Ey = self._elem(np.atleast_2d(q))
        x1 = Ex @ self.S1.T; y1 = Ey @ self.S1.T
        x2 = Ex @ self.S2.T; y2 = Ey @ self.S2.T
        d = x1**2 + y1**2
        return float(np.sum(0.5 * (EA * (np.sqrt(d) - 1)**2 + EI * ((x1 * y2 - y1 * x2) / d)**2) * self.wg))

    def point(self, q, s):
        e = min(int(round(s / self.le, 12)), self.nel - 1) if s < L2 else self.nel - 1
        xi = s / self.le - e
        Sv = self.shape(np.array(xi))
        Ee = np.concatenate([q[4 * e:4 * e + 4], q[4 * e + 4:4 * e + 8]])
        return np.array([Sv @ Ee[0::2], Sv @ Ee[1::2]])

    def initial_state(self, case):
        f = initial_fields(case)
        q = np.zeros(self.ndof); v = np.zeros(self.ndof)
        for i in range(self.nnode):
            r, rs, vv, vs, _, _ = f(i * self.le)
            q[4 * i:4 * i + 4] = [r[0], r[1], rs[0], rs[1]]
            v[4 * i:4 * i + 4] = [vv[0], vv[1], vs[0], vs[1]]
        return q, v


# ----------------------------------------------------------------------------------------
class Reissner(Model):
    name = 'reissner'

    def __init__(self, nel, eb_limit=False, shear_rigid=False, no_rot_inertia=False):
        self.nel, self.le = nel, L2 / nel
        self.nnode, self.ndof = 2 * nel + 1, 3 * (2 * nel + 1)
        self.dofs_per_node, self.node_reach = 3, 2
        if eb_limit:
            self.name = 'reissner_eb'
            shear_rigid = no_rot_inertia = True
        self.GAs = GAs * (1e3 if shear_rigid else 1.0)
        rhoI = 1e-6 * RHOI if no_rot_inertia else RHOI
        le = self.le
        xg, wg = np.polynomial.legendre.leggauss(2)
        xi = 0.5 * (xg + 1); self.wk = 0.5 * wg * le
        self.Nk = self.shape(xi)
        self.dNk = np.stack([(4 * xi - 3) / le, (-8 * xi + 4) / le, (4 * xi - 1) / le], axis=1)
        xg3, wg3 = np.polynomial.legendre.leggauss(3)
        x3 = 0.5 * (xg3 + 1); w3 = 0.5 * wg3 * le
        N3 = self.shape(x3)
        m3 = np.einsum('g,ga,gb->ab', w3, N3, N3)
        M = np.zeros((self.ndof, self.ndof))
        for e in range(nel):
            for a in range(3):
                for b in range(3):
                    ia, ib = 3 * (2 * e + a), 3 * (2 * e + b)
                    M[ia, ib] += RHOA * m3[a, b]
                    M[ia + 1, ib + 1] += RHOA * m3[a, b]
                    M[ia + 2, ib + 2] += rhoI * m3[a, b]
        last = 3 * (self.nnode - 1)
        M[last, last] += M3; M[last + 1, last + 1] += M3
        self.M = M
        self.prescribed = [(0, 'Ax'), (1, 'Ay'), (last + 1, 'zero')]
        self.setup()

    @staticmethod
    def shape(xi):
        return np.stack([2 * (xi - 0.5) * (xi - 1), -4 * xi * (xi - 1), 2 * xi * (xi - 0.5)], axis=-1)

    def _elem(self, q):
        nb = q.shape[0]
        Qn = q.reshape(nb, self.nnode, 3)
        E = np.concatenate([Qn[:, 0:-1:2, :], Qn[:, 1::2, :], Qn[:, 2::2, :]], axis=2)  # (nb,nel,9)
        return E[..., 0::3], E[..., 1::3], E[..., 2::3]

    def fint(self, q):
        q = np.atleast_2d(q)
        X, Y, T = self._elem(q)
        th = T @ self.Nk.T
        x1 = X @ self.dNk.T; y1 = Y @ self.dNk.T; th1 = T @ self.dNk.T
        c, s = np.cos(th), np.sin(th)
        G1 = c * x1 + s * y1 - 1; G2 = -s * x1 + c * y1
        N = EA * G1; Q = self.GAs * G2; Mb = EI * th1
        w = self.wk
        fx = ((N * c - Q * s) * w) @ self.dNk
        fy = ((N * s + Q * c) * w) @ self.dNk
        ft = ((N * G2 - Q * (1 + G1)) * w) @ self.Nk + (Mb * w) @ self.dNk
        nb = q.shape[0]
        f = np.zeros((nb, self.nnode, 3))
        fe = np.stack([fx, fy, ft], axis=-1)          # (nb, nel, 3 nodes, 3 comps)
        f[:, 0:-1:2, :] += fe[:, :, 0, :]
        f[:, 1::2, :] += fe[:, :, 1, :]
        f[:, 2::2, :] += fe[:, :, 2, :]
        return f.reshape(nb, self.ndof)

    def strain_energy(self, q):
        X, Y, T = self._elem(np.atleast_2d(q))
        th = T @ self.Nk.T
        x1 = X @ self.dNk.T; y1 = Y @ self.dNk.T; th1 = T @ self.dNk.T
        G1 = np.cos(th) * x1 + np.sin(th) * y1 - 1; G2 = -np.sin(th) * x1 + np.cos(th) * y1
        return float(np.sum(0.5 * (EA * G1**2 + self.GAs * G2**2 + EI * th1**2) * self.wk))

    def point(self, q, s):
        e = min(int(round(s / self.le, 12)), self.nel - 1) if s < L2 else self.nel - 1
        xi = s / self.le - e
        Nv = self.shape(np.array(xi))
        idx = [3 * (2 * e + a) for a in range(3)]
        return np.array([Nv @ q[idx], Nv @ q[[i + 1 for i in idx]]])

    def initial_state(self, case):
        f = initial_fields(case)
        q = np.zeros(self.ndof); v = np.zeros(self.ndof)
        for i in range(self.nnode):
            r, rs, vv, vs, th, thd = f(i * self.le / 2)
            q[3 * i:3 * i + 3] = [r[0], r[1], th]
            v[3 * i:3 * i + 3] = [vv[0], vv[1], thd]
        return q, v


def make_model(name, nel):
    if name == 'ancf':
        return ANCF(nel)
    if name == 'reissner':
        return Reissner(nel)
    if name == 'reissner_eb':
        return Reissner(nel, eb_limit=True)
    if name == 'reissner_rigidshear':          # G A x 1e3, rho I kept
        m = Reissner(nel, shear_rigid=True); m.name = name; return m
    if name == 'reissner_norot':               # rho I -> 1e-6 rho I, shear kept
        m = Reissner(nel, no_rot_inertia=True); m.name = name; return m
    raise ValueError(name)


# ========================================================================================
S6 = np.sqrt(6.0)
RA = np.array([[(88 - 7 * S6) / 360, (296 - 169 * S6) / 1800, (-2 + 3 * S6) / 225],
               [(296 + 169 * S6) / 1800, (88 + 7 * S6) / 360, (-2 - 3 * S6) / 225],
               [(16 - S6) / 36, (16 + S6) / 36, 1 / 9]])
RC = np.array([(4 - S6) / 10, (4 + S6) / 10, 1.0])
RAI = np.linalg.inv(RA)
RAI2 = RAI @ RAI
_lam, _T = np.linalg.eig(RAI2)
_order = np.argsort(np.abs(_lam.imag))          # real eigenvalue first
LAM = _lam[_order]; TV = _T[:, _order]
TVI = np.linalg.inv(TV)


def to_band(Mat, b):
    n = Mat.shape[0]
    ab = np.zeros((3 * b + 1, n), dtype=Mat.dtype)   # gbtrf storage with kl extra rows
    for j in range(n):
        i0, i1 = max(0, j - b), min(n, j + b + 1)
        ab[2 * b + np.arange(i0, i1) - j, j] = Mat[i0:i1, j]
    return ab


class BandLU:
    def __init__(self, Mat, b):
        self.b = b
        ab = to_band(Mat, b)
        if np.iscomplexobj(Mat):
            self.lu, self.piv, info = lapack.zgbtrf(ab, b, b)
            self.trs = lapack.zgbtrs
        else:
            self.lu, self.piv, info = lapack.dgbtrf(ab, b, b)
            self.trs = lapack.dgbtrs
        if info != 0:
            raise RuntimeError("gbtrf failed %d" % info)

    def solve(self, rhs):
        x, info = self.trs(self.lu, self.b, self.b, rhs, self.piv)
        return x


def integrate(model, case, h, t_end=0.1, dt_out=1e-3, refresh=20, newton_tol=1e-13, verbose=False):
    """Fixed-step Radau IIA(5) for M_ff a = F(t, q_f); returns output times and outputs."""
    nf = model.nf
    M = model.Mff
    q0, v0 = model.initial_state(case)
    q, v = q0[model.fdofs].copy(), v0[model.fdofs].copy()
    n_steps = int(round(t_end / h)); k_out = int(round(dt_out / h))
    assert abs(n_steps * h - t_end) < 1e-12 and abs(k_out * h - dt_out) < 1e-12
    t = 0.0
    a = np.linalg.solve(M, model.force([0.0], q[None, :])[0])
    outs, touts, energies = [], [], []

    def record(t, q, v):
        qq = model.full(t, q)[0]; vv = model.full(t, v, 'v')[0]
        outs.append(model.outputs(qq, vv)); touts.append(t); energies.append(model.energy(qq, vv))
    record(0.0, q, v)
    lus = None; since = 10**9
    n_newton = 0; n_fact = 0
    Mv = None
    t0 = time.time()
    for step in range(n_steps):
        if lus is None or since >= refresh:
            K = model.stiffness(t, q)
            lus = [BandLU(LAM[0].real / h**2 * M + K, model.band),
                   BandLU(LAM[1] / h**2 * M + K.astype(complex), model.band)]
            since = 0; n_fact += 1
        ts = t + RC * h
        Z = np.outer(RC * h, v) + 0.5 * np.outer((RC * h)**2, a)      # (3, nf)
        Mv = M @ v
        w1 = RAI.sum(axis=1)
        converged = False
        prev = np.inf
        for it in range(12):
            R = (RAI2 @ (Z @ M)) / h**2 - np.outer(w1, Mv) / h - model.force(ts, q[None, :] + Z)
            W = TVI @ R                                   # transformed residual (3, nf) complex
            d0 = lus[0].solve(W[0].real.copy())
            d1 = lus[1].solve(W[1].astype(complex).copy())
            dW = np.array([d0.astype(complex), d1, np.conj(d1)])
            dZ = (TV @ dW).real
            Z -= dZ
            n_newton += 1
            err = np.max(np.abs(dZ))
            if err < newton_tol or (it >= 2 and err < 1e-11 and err > 0.3 * prev):
                converged = True          # (second test: stagnation at the round-off floor)
                break
            prev = err
        if not converged:
            if since == 0:
                raise RuntimeError(f"Newton failed at t={t}")
            lus = None
            # retry this step with a fresh Jacobian
            K = model.stiffness(t, q)
            lus = [BandLU(LAM[0].real / h**2 * M + K, model.band),
                   BandLU(LAM[1] / h**2 * M + K.astype(complex), model.band)]
            since = 0; n_fact += 1
            Z = np.outer(RC * h, v) + 0.5 * np.outer((RC * h)**2, a)
            prev = np.inf
            for it in range(30):
                R = (RAI2 @ (Z @ M)) / h**2 - np.outer(w1, Mv) / h - model.force(ts, q[None, :] + Z)
                W = TVI @ R
                d0 = lus[0].solve(W[0].real.copy()); d1 = lus[1].solve(W[1].astype(complex).copy())
                dZ = (TV @ np.array([d0.astype(complex), d1, np.conj(d1)])).real
                Z -= dZ; n_newton += 1
                err = np.max(np.abs(dZ))
                if err < newton_tol or (it >= 2 and err < 1e-11 and err > 0.3 * prev):
                    break
                prev = err
            else:
                raise RuntimeError(f"Newton failed after refresh at t={t}")
        Vst = (RAI @ Z) / h
        Acc = (RAI2 @ Z) / h**2 - np.outer(w1, v) / h
        q = q + Z[2]; v = Vst[2]; a = Acc[2]
        t = (step + 1) * h
        since += 1
        if (step + 1) % k_out == 0:
            record(t, q, v)
            if verbose and (step + 1) % (n_steps // 10) == 0:
                print(f"  t={t:.3f} newton/step={n_newton/(step+1):.2f} fact={n_fact} "
                      f"cpu={time.time()-t0:.0f}s w_mid={outs[-1][2]:.6e}", flush=True)
    info = dict(cpu=time.time() - t0, newton_per_step=n_newton / n_steps, factorizations=n_fact)
    return np.array(touts), np.array(outs), np.array(energies), info


def run_file(name, nel, case, h, t_end=0.1, dt_out=1e-3):
    sfx = "" if dt_out == 1e-3 else f"_o{dt_out:g}"
    return os.path.join(RUNDIR, f"{name}_n{nel}_{case}_h{h:.3g}_T{t_end:g}{sfx}.npz")


def run_and_save(name, nel, case, h, t_end=0.1, dt_out=1e-3, verbose=True):
    os.makedirs(RUNDIR, exist_ok=True)
    m = make_model(name, nel)
    t, out, en, info = integrate(m, case, h, t_end=t_end, dt_out=dt_out, verbose=verbose)
    fn = run_file(name, nel, case, h, t_end, dt_out)
    np.savez(fn, t=t, out=out, energy=en, info=json.dumps(info))
    print(f"{name} nel={nel} case={case} h={h:g}: {info}", flush=True)
    return t, out


def load(name, nel, case, h, t_end=0.1, dt_out=1e-3):
    fn = run_file(name, nel, case, h, t_end, dt_out)
    d = np.load(fn)
    return d['t'], d['out'], d['energy'], json.loads(str(d['info']))


def validate():
    """Check the fixed-step Radau IIA integrator against scipy's adaptive Radau (rtol 1e-11)
    on a coarse model (ANCF, 4 elements, case T, 0 <= t <= 0.01 s)."""
    from scipy.integrate import solve_ivp
    from scipy.linalg import cho_factor, cho_solve
    m = make_model('ancf', 4)
    t_end = 0.01
    for h in (1e-5, 5e-6, 2.5e-6):
        t, out, en, info = integrate(m, 'T', h, t_end=t_end)
        print(f"fixed-step Radau IIA h={h:g}: x_B={out[-1, 0]:.14e} w_mid={out[-1, 2]:.14e}")
    cho = cho_factor(m.Mff); nf = m.nf

    def rhs(t, y):
        return np.concatenate([y[nf:], cho_solve(cho, m.force([t], y[None, :nf])[0])])

    def jac(t, y):
        J = np.zeros((2 * nf, 2 * nf)); J[:nf, nf:] = np.eye(nf)
        J[nf:, :nf] = -cho_solve(cho, m.stiffness(t, y[:nf])); return J
    q0, v0 = m.initial_state('T')
    sol = solve_ivp(rhs, (0, t_end), np.concatenate([q0[m.fdofs], v0[m.fdofs]]), method='Radau',
                    rtol=1e-11, atol=1e-14, jac=jac)
    y = sol.y[:, -1]
    o = m.outputs(m.full(t_end, y[:nf])[0], m.full(t_end, y[nf:], 'v')[0])
    print(f"scipy Radau rtol 1e-11 (nfev {sol.nfev}): x_B={o[0]:.14e} w_mid={o[2]:.14e}")


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd == 'validate':
        validate()
    if cmd == 'run':
        name, nel, case, h = sys.argv[2], int(sys.argv[3]), sys.argv[4], float(sys.argv[5])
        t_end = float(sys.argv[6]) if len(sys.argv) > 6 else 0.1
        dt_out = float(sys.argv[7]) if len(sys.argv) > 7 else 1e-3
        t, out = run_and_save(name, nel, case, h, t_end, dt_out)
        for k in range(0, len(t), max(1, len(t) // 10)):
            print(f"t={t[k]:.3f} x_B={out[k,0]:.12f} w_mid={out[k,2]: .10e}")
