#!/usr/bin/env python3
"""
Lee's frame (right-angle frame, dead point load): independent reference solution.

Definition (source)
-------------------
J. S. Lee, F. S. Manuel, E. C. Rossow, "Large deflections and stability of elastic frames",
J. Eng. Mech. Div. ASCE 94 (1968) 521-547; used with FE/arc-length by
K. Schweizerhof, P. Wriggers, "Consistent linearization for path following methods in
nonlinear FE analysis", CMAME 59 (1986) 261-279, and J. C. Simo, L. Vu-Quoc, "A three-dimensional
finite-strain rod model. Part II", CMAME 58 (1986) 79-116 (planar case).  The parameters below
are exactly those of AeroBeams.jl `test/LeeFrameDeadLoad.jl` (luizpancini/AeroBeams.jl):
L = 120, A = 6, I = 2, E = 7.2e6 (N, cm) -> here E = 7200 kN/cm^2, forces in kN, lengths in cm;
EA = 43200 kN, EI = 14400 kN cm^2, GA = "infinity" (shear rigid), nu = 0.
Note: the value is sometimes quoted as "E = 720 kN/cm^2"; 7.2e6 N/cm^2 is 7200 kN/cm^2.  Only
with 7200 kN/cm^2 is the limit load ~18.5 kN (the literature value).  Since every stiffness is
proportional to E, P scales exactly with E at fixed displacements: for E = 720 kN/cm^2 divide all
loads by 10.  With E = 7200 kN/cm^2, P [kN] = P L^2/EI (dimensionless), a convenient check.

Geometry: support A at (0,0), knee K at (0,120), support B at (120,120).  Member 1 = column A->K,
member 2 = beam K->B.  A and B pinned (x, y fixed, rotation free), knee welded (rigid).
Dead load P (kN, downward) at C = (24,120), i.e. 24 cm from the knee on the beam.
Outputs: v = downward displacement of C, u = horizontal (+x) displacement of C, both in cm.

Methods
-------
A) "shoot": multiple shooting on the exact planar Reissner (extensible, optionally shear
   deformable) rod equations, classical RK4 with variational equations, 20 segments of 12 cm,
   pseudo-arclength continuation in (state, P).  Error is O(h^4) in the RK4 step h.
B) "fe": geometrically exact planar Reissner (Simo-Vu-Quoc) 2-node FE with one-point (reduced)
   integration, written from scratch, with a pseudo-arclength (Riks) continuation; error O(h^2),
   meshes of 40/80/160/320 elements per member and Richardson extrapolation of the limit load.
C) Linear frame theory (exact Euler-Bernoulli/Timoshenko frame stiffness matrices, 3 elements)
   for the initial stiffness.

Limit points (dP/ds = 0) and turning points of v (dv/ds = 0) are located to Newton accuracy by
Brent root-finding in the arc-length step of the tangent component; crossings v = 10, 20, ...
likewise (root of v(s) - target).

Usage:  python3 lee_frame_reference.py            (everything; writes lee_frame_reference.csv)
        python3 lee_frame_reference.py --quick    (shooting only, coarse)
"""
import argparse

import math
import os
import sys
import time

import numpy as np
from scipy.optimize import brentq

HERE = os.path.dirname(os.path.abspath(__file__))

# ------------------------------------------------------------------ problem data (kN, cm)
L = 120.0
E = 7200.0           # kN/cm^2  (= 7.2e6 N/cm^2 = 72 GPa; see the note on "720" below)
AREA = 6.0           # cm^2
INERTIA = 2.0        # cm^4
EA = E * AREA        # 43200 kN
EI = E * INERTIA     # 14400 kN cm^2  (so P L^2/EI = P in kN: the loads below are also P L^2/EI)
G_TIM = E / 2.0      # nu = 0
GA_TIM = G_TIM * AREA * 1.0   # shear factor 1 -> 21600 kN
PSTOP = 40.0         # trace the path until P > PSTOP (kN)
XLOAD = 24.0         # load position measured from the knee along the beam


# ====================================================================== generic continuation
class Continuation:
    """Pseudo-arclength continuation of R(z) = 0, z in R^{n+1}, with a weighted norm.

    fun(z) -> (R, J) with R of size n and J of shape (n, n+1).
    w: weights (z scaled as w*z in the arc-length norm)."""

    def __init__(self, fun, w, tol=1e-10, maxit=25):
        self.fun = fun
        self.w = np.asarray(w, float)
        self.tol = tol
        self.maxit = maxit

    def tangent(self, z, t_prev):
        R, J = self.fun(z)
        n1 = z.size
        A = np.vstack([J, (self.w**2 * t_prev)[None, :]])
        b = np.zeros(n1)
        b[-1] = 1.0
        t = np.linalg.solve(A, b)
        return t / np.linalg.norm(self.w * t)

    def correct(self, z0, t0, ds):
        """Predictor z0 + ds t0, corrector on the hyperplane orthogonal (weighted) to t0."""
        z = z0 + ds * t0
        wt = self.w**2 * t0
        for it in range(self.maxit):
            R, J = self.fun(z)
            g = wt @ (z - z0) - ds
            res = np.concatenate([R, [g]])
            A = np.vstack([J, wt[None, :]])
            dz = np.linalg.solve(A, -res)
            z = z + dz
            if np.linalg.norm(self.w * dz) < self.tol:
                R, J = self.fun(z)
                return z, it + 1
        raise RuntimeError("corrector did not converge (ds=%g)" % ds)

    def point(self, z0, t0, ds):
        z, _ = self.correct(z0, t0, ds)
        return z, self.tangent(z, t0)


def trace(cont, z0, t0, ds, stop, nmax=100000, verbose=False):
    """Fixed step path following; returns list of (z, t)."""
    path = [(z0.copy(), t0.copy())]
    z, t = z0, t0
    for k in range(nmax):
        z, t = cont.point(z, t, ds)
        path.append((z.copy(), t.copy()))
        if stop(z):
            break
    return path


def refine_events(cont, path, qfun, dqfun=None, targets=()):
    """Locate along a traced path
       * extrema of the scalar q (zeros of dq/ds, dqfun(t) gives dq/ds from the tangent);
       * crossings q(z) = target for each target.
    Each returned item: (kind, target, z, key) with key = k + s/ds (position along the path, k the
    path index).  Refinement by Brent in the step from the previous path point (re-corrected
    from it with the same predictor)."""
    out = []
    for k in range(len(path) - 1):
        z0, t0 = path[k]
        z1, t1 = path[k + 1]
        ds_full = cont.w**2 * t0 @ (z1 - z0)
        if dqfun is not None:
            a, b = dqfun(t0), dqfun(t1)
            if a * b < 0:
                f = lambda s: dqfun(cont.point(z0, t0, s)[1])
                s = brentq(f, 0.0, ds_full, xtol=1e-13 * abs(ds_full), rtol=1e-15)
                out.append(("extremum", None, cont.point(z0, t0, s)[0], k + s / ds_full))
        for tg in targets:
            a, b = qfun(z0) - tg, qfun(z1) - tg
            if a == 0.0:
                out.append(("cross", tg, z0, float(k)))
            elif a * b < 0:
                f = lambda s: qfun(cont.point(z0, t0, s)[0]) - tg
                s = brentq(f, 0.0, ds_full, xtol=1e-13 * abs(ds_full), rtol=1e-15)
                out.append(("cross", tg, cont.point(z0, t0, s)[0], k + s / ds_full))
    return out


# ====================================================================== method A: shooting
class Shooting:
    """Multiple shooting for the planar Reissner rod.

    State along each member: y = (x, y, phi, Fx, Fy, M), with phi the section (tangent) angle,
    F the force exerted by the part beyond s on the part before s, M the moment (same sense).
        N = F.t, Q = F.n, eps = N/EA, gam = Q/GA, r' = (1+eps) t + gam n,
        phi' = M/EI, F' = 0 (no distributed load), M' = -(r' x F).
    Segments of length SEG; segment starts at s = 0, 12, ..., 228 along A->K->B.
    Jumps: knee (start of seg 10): phi -= pi/2; load (start of seg 12): Fy += P.
    Unknowns z = (y_0, ..., y_19, P)."""

    SEG = 12.0
    NSEG = 20
    KNEE = 10
    LOADSEG = 12

    def __init__(self, nsteps=48, ea=EA, ga=None, ei=EI):
        self.n = nsteps
        self.h = self.SEG / nsteps
        self.iea = 0.0 if ea is None else 1.0 / ea
        self.iga = 0.0 if ga is None else 1.0 / ga
        self.iei = 1.0 / ei

    def rhs(self, Y):
        """Y: (m, 6). Returns f (m,6) and df/dy (m,6,6)."""
        x, y, ph, Fx, Fy, M = Y.T
        c, s = np.cos(ph), np.sin(ph)
        N = Fx * c + Fy * s
        Q = -Fx * s + Fy * c
        e = N * self.iea
        g = Q * self.iga
        xp = (1 + e) * c - g * s
        yp = (1 + e) * s + g * c
        f = np.zeros_like(Y)
        f[:, 0] = xp
        f[:, 1] = yp
        f[:, 2] = M * self.iei
        f[:, 5] = yp * Fx - xp * Fy
        # derivatives
        e_ph, g_ph = Q * self.iea, -N * self.iga
        e_Fx, e_Fy = c * self.iea, s * self.iea
        g_Fx, g_Fy = -s * self.iga, c * self.iga
        xp_ph = e_ph * c - (1 + e) * s - g_ph * s - g * c
        yp_ph = e_ph * s + (1 + e) * c + g_ph * c - g * s
        xp_Fx = e_Fx * c - g_Fx * s
        xp_Fy = e_Fy * c - g_Fy * s
        yp_Fx = e_Fx * s + g_Fx * c
        yp_Fy = e_Fy * s + g_Fy * c
        D = np.zeros(Y.shape + (6,))
        D[:, 0, 2], D[:, 0, 3], D[:, 0, 4] = xp_ph, xp_Fx, xp_Fy
        D[:, 1, 2], D[:, 1, 3], D[:, 1, 4] = yp_ph, yp_Fx, yp_Fy
        D[:, 2, 5] = self.iei
        D[:, 5, 2] = yp_ph * Fx - xp_ph * Fy
        D[:, 5, 3] = yp_Fx * Fx + yp - xp_Fx * Fy
        D[:, 5, 4] = yp_Fy * Fx - xp_Fy * Fy - xp
        return f, D

    def flow(self, Y0):
        """Integrate all segments (RK4 with variational equations). Returns Y(end), Phi."""
        Y = Y0.copy()
        m = Y.shape[0]
        Phi = np.broadcast_to(np.eye(6), (m, 6, 6)).copy()
        h = self.h
        for _ in range(self.n):
            k1, D1 = self.rhs(Y)
            P1 = D1 @ Phi
            k2, D2 = self.rhs(Y + 0.5 * h * k1)
            P2 = D2 @ (Phi + 0.5 * h * P1)
            k3, D3 = self.rhs(Y + 0.5 * h * k2)
            P3 = D3 @ (Phi + 0.5 * h * P2)
            k4, D4 = self.rhs(Y + h * k3)
            P4 = D4 @ (Phi + h * P3)
            Y = Y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            Phi = Phi + h / 6 * (P1 + 2 * P2 + 2 * P3 + P4)
        return Y, Phi

    def fun(self, z):
        ns = self.NSEG
        Y0 = z[:-1].reshape(ns, 6)
        P = z[-1]
        Ye, Phi = self.flow(Y0)
        n = 6 * ns
        R = np.zeros(n)
        J = np.zeros((n, n + 1))
        # BC at A
        R[0:3] = Y0[0, [0, 1, 5]]
        J[0, 0] = J[1, 1] = J[2, 5] = 1.0
        r = 3
        for k in range(ns - 1):
            jump = np.zeros(6)
            if k + 1 == self.KNEE:
                jump[2] = -math.pi / 2
            if k + 1 == self.LOADSEG:
                jump[4] = P
                J[r + 4, -1] = -1.0
            R[r:r + 6] = Y0[k + 1] - (Ye[k] + jump)
            J[r:r + 6, 6 * (k + 1):6 * (k + 2)] += np.eye(6)
            J[r:r + 6, 6 * k:6 * (k + 1)] -= Phi[k]
            r += 6
        # BC at B
        R[r:r + 3] = Ye[-1, [0, 1, 5]] - np.array([L, L, 0.0])
        J[r:r + 3, 6 * (ns - 1):6 * ns] = Phi[-1][[0, 1, 5], :]
        return R, J

    def initial(self):
        ns = self.NSEG
        Y = np.zeros((ns, 6))
        for k in range(ns):
            s = k * self.SEG
            if k < self.KNEE:
                Y[k, :3] = [0.0, s, math.pi / 2]
            else:
                Y[k, :3] = [s - L, L, 0.0]
        return np.concatenate([Y.ravel(), [0.0]])

    def weights(self):
        w = np.tile([1 / L, 1 / L, 1.0, 1 / 50.0, 1 / 50.0, 1 / 2000.0], self.NSEG) / math.sqrt(self.NSEG)
        return np.concatenate([w, [1 / 50.0]])

    # observables
    def uvP(self, z):
        Y = z[:-1].reshape(self.NSEG, 6)
        return Y[self.LOADSEG, 0] - XLOAD, L - Y[self.LOADSEG, 1], z[-1]

    def v_index(self):
        return 6 * self.LOADSEG + 1   # v = L - z[idx], dv/ds = -t[idx]


# ====================================================================== method B: Reissner FE
class ReissnerFE:
    """Planar geometrically exact (Simo-Reissner) beam, 2-node linear elements, one-point
    integration.  Nodal dofs (ux, uy, theta).  Strains at the element midpoint:
        eps = r'.t(phi) - 1, gam = r'.n(phi), kappa = theta', phi = alpha + (th1+th2)/2."""

    def __init__(self, nel, ea=EA, ga=None, ei=EI, ga_penalty=1e4):
        assert nel % 5 == 0
        self.nel = nel
        self.ea, self.ei = ea, ei
        self.ga = ga if ga is not None else ga_penalty * ea
        h = L / nel
        # nodes: column 0..nel, beam nel..2nel
        X = [(0.0, i * h) for i in range(nel + 1)] + [(i * h, L) for i in range(1, nel + 1)]
        self.X = np.array(X)
        self.nn = len(X)
        self.conn = np.array([(i, i + 1) for i in range(2 * nel)])
        self.alpha = np.array([math.pi / 2] * nel + [0.0] * nel)
        self.h = h
        self.nload = nel + nel // 5
        assert abs(self.X[self.nload, 0] - XLOAD) < 1e-12
        fixed = [0, 1, 3 * (self.nn - 1), 3 * (self.nn - 1) + 1]
        self.free = np.setdiff1d(np.arange(3 * self.nn), fixed)
        dofs = np.array([[3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1, 3 * b + 2] for a, b in self.conn])
        self.dofs = dofs
        self.fhat = np.zeros(3 * self.nn)
        self.fhat[3 * self.nload + 1] = -1.0
        # map full -> free index
        self.mapf = -np.ones(3 * self.nn, int)
        self.mapf[self.free] = np.arange(self.free.size)

    def elem(self, q):
        """Vectorised element internal forces (ne,6) and tangents (ne,6,6)."""
        u = q[self.dofs]                        # (ne,6)
        Xa = self.X[self.conn[:, 0]]
        Xb = self.X[self.conn[:, 1]]
        h = np.linalg.norm(Xb - Xa, axis=1)     # element reference lengths
        t0 = (Xb - Xa) / h[:, None]             # exact initial tangents (no cos(pi/2) round-off)
        d = (Xb - Xa + u[:, 3:5] - u[:, 0:2]) / h[:, None]
        thm = 0.5 * (u[:, 2] + u[:, 5])
        ct, st = np.cos(thm), np.sin(thm)
        c = t0[:, 0] * ct - t0[:, 1] * st       # t = R(theta_m) t0 = (cos phi, sin phi)
        s = t0[:, 1] * ct + t0[:, 0] * st
        t = np.stack([c, s], 1)
        nv = np.stack([-s, c], 1)
        eps = (d * t).sum(1) - 1
        gam = (d * nv).sum(1)
        kap = (u[:, 5] - u[:, 2]) / h
        N, Q, M = self.ea * eps, self.ga * gam, self.ei * kap
        ne = u.shape[0]
        Be = np.zeros((ne, 6)); Bg = np.zeros((ne, 6)); Bk = np.zeros((ne, 6))
        hc = h[:, None]
        Be[:, 0:2] = -t / hc; Be[:, 3:5] = t / hc; Be[:, 2] = Be[:, 5] = 0.5 * gam
        Bg[:, 0:2] = -nv / hc; Bg[:, 3:5] = nv / hc; Bg[:, 2] = Bg[:, 5] = -0.5 * (1 + eps)
        Bk[:, 2] = -1 / h; Bk[:, 5] = 1 / h
        fe = hc * (Be * N[:, None] + Bg * Q[:, None] + Bk * M[:, None])
        Ke = h[:, None, None] * (self.ea * Be[:, :, None] * Be[:, None, :]
                                 + self.ga * Bg[:, :, None] * Bg[:, None, :]
                                 + self.ei * Bk[:, :, None] * Bk[:, None, :])
        # geometric part: d depends on translations (Dd = [-I/h, I/h]), phi on rotations (1/2, 1/2)
        Dd = np.zeros((ne, 2, 6))
        Dd[:, 0, 0] = Dd[:, 1, 1] = -1 / h
        Dd[:, 0, 3] = Dd[:, 1, 4] = 1 / h
        dphi = np.zeros(6); dphi[2] = dphi[5] = 0.5
        # d2eps: d-phi cross = n, phi-phi = -(1+eps); d2gam: d-phi cross = -t, phi-phi = -gam
        a = np.einsum('ei,eij->ej', N[:, None] * nv - Q[:, None] * t, Dd)   # (ne,6)
        G = a[:, :, None] * dphi[None, None, :] + dphi[None, :, None] * a[:, None, :]
        G += (-(N * (1 + eps)) - Q * gam)[:, None, None] * np.outer(dphi, dphi)[None]
        Ke += h[:, None, None] * G
        return fe, Ke

    def fun(self, z):
        nf = self.free.size
        q = np.zeros(3 * self.nn)
        q[self.free] = z[:-1]
        lam = z[-1]
        fe, Ke = self.elem(q)
        fint = np.zeros(3 * self.nn)
        np.add.at(fint, self.dofs, fe)
        R = (fint - lam * self.fhat)[self.free]
        K = np.zeros((nf, nf + 1))
        idx = self.mapf[self.dofs]              # (ne,6)
        ii = np.repeat(idx, 6, axis=1)
        jj = np.tile(idx, (1, 6))
        vals = Ke.reshape(-1, 36)
        m = (ii >= 0) & (jj >= 0)
        np.add.at(K, (ii[m], jj[m]), vals[m])
        K[:, -1] = -self.fhat[self.free]
        return R, K

    def initial(self):
        return np.zeros(self.free.size + 1)

    def weights(self):
        w = np.zeros(3 * self.nn)
        w[0::3] = w[1::3] = 1 / L
        w[2::3] = 1.0
        w = w[self.free] / math.sqrt(self.nn)
        return np.concatenate([w, [1 / 50.0]])

    def uvP(self, z):
        q = np.zeros(3 * self.nn)
        q[self.free] = z[:-1]
        return q[3 * self.nload], -q[3 * self.nload + 1], z[-1]

    def v_index(self):
        return self.mapf[3 * self.nload + 1]   # v = -z[idx]


# ====================================================================== method C: linear frame
def linear_frame(ea=EA, ga=None, ei=EI):
    """Exact linear stiffness (Euler-Bernoulli or Timoshenko with shear) of the frame with
    3 elements A-K, K-C, C-B. Returns (du/dP, dv/dP) at C."""
    nodes = np.array([[0, 0], [0, L], [XLOAD, L], [L, L]], float)
    els = [(0, 1), (1, 2), (2, 3)]
    K = np.zeros((12, 12))
    for a, b in els:
        dx = nodes[b] - nodes[a]
        l = np.linalg.norm(dx)
        c, s = dx / l
        phi = 0.0 if ga is None else 12 * ei / (ga * l**2)
        k = ei / (l**3 * (1 + phi))
        kl = np.zeros((6, 6))
        kl[0, 0] = kl[3, 3] = ea / l
        kl[0, 3] = kl[3, 0] = -ea / l
        kb = k * np.array([[12, 6 * l, -12, 6 * l],
                           [6 * l, (4 + phi) * l**2, -6 * l, (2 - phi) * l**2],
                           [-12, -6 * l, 12, -6 * l],
                           [6 * l, (2 - phi) * l**2, -6 * l, (4 + phi) * l**2]])
        ib = [1, 2, 4, 5]
        kl[np.ix_(ib, ib)] = kb
        T = np.zeros((6, 6))
        r = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        T[:3, :3] = T[3:, 3:] = r
        kg = T.T @ kl @ T
        d = [3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1, 3 * b + 2]
        K[np.ix_(d, d)] += kg
    free = [2, 3, 4, 5, 6, 7, 8, 11]
    f = np.zeros(12)
    f[7] = -1.0
    x = np.zeros(12)
    x[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    return x[6], -x[7]


# ====================================================================== literature data
# Leahu-Aluas & Abed-Meraim, Struct. Eng. Mech. 38(6) (2011) 767, doi 10.12989/sem.2011.38.6.767,
# Table 11 (as transcribed in betelgeuze-kang/Structural-Analysis, benchmark/lee_frame.py; there
# converted to m, here back to cm): (u [cm], v [cm], P [kN]).
LEAHU_ALUAS_2011 = [
    (0.000, 0.000, 0.00), (0.096, 2.045, 2.99), (1.006, 7.300, 8.02), (4.376, 17.849, 12.85),
    (12.032, 32.687, 16.57), (22.602, 45.160, 18.47), (28.531, 49.916, 18.59),
    (37.873, 55.282, 17.78), (47.475, 58.826, 16.01), (57.242, 60.741, 13.45),
    (67.061, 60.574, 9.84), (76.393, 56.363, 3.88), (78.947, 53.369, 0.59),
    (80.896, 50.916, -3.63), (83.117, 51.439, -6.63), (86.972, 54.360, -8.92),
    (90.642, 58.737, -9.51), (93.210, 63.913, -8.86), (94.400, 69.411, -7.52),
    (94.223, 74.880, -5.74), (92.826, 80.094, -3.50), (88.987, 87.205, 2.02),
    (86.206, 91.649, 12.91)]


def compare_literature(pts, lit=LEAHU_ALUAS_2011):
    """pts: dense path (u, v, P).  For each literature point, the nearest point of our path in
    the (u, v) plane (projection on the polyline, P interpolated linearly)."""
    out = []
    for (ul, vl, Pl) in lit:
        best = None
        for k in range(len(pts) - 1):
            a, b = pts[k], pts[k + 1]
            d = b[:2] - a[:2]
            tt = 0.0 if d @ d == 0 else np.clip(((np.array([ul, vl]) - a[:2]) @ d) / (d @ d), 0, 1)
            p = a + tt * (b - a)
            dist = math.hypot(p[0] - ul, p[1] - vl)
            if best is None or dist < best[0]:
                best = (dist, p)
        out.append((ul, vl, Pl, best[0], best[1][2]))
    return out


# ====================================================================== driver helpers
def run_path(model, ds, stop_v=None, pmax_stop=None, nmax=20000, verbose=True):
    cont = Continuation(model.fun, model.weights())
    z0 = model.initial()
    R, J = model.fun(z0)
    assert np.linalg.norm(R) < 1e-9, np.linalg.norm(R)
    # initial tangent: null vector of J with positive P component
    t = np.zeros(z0.size); t[-1] = 1.0
    t = cont.tangent(z0, t)
    if t[-1] < 0:
        t = -t

    def stop(z):
        u, v, P = model.uvP(z)
        return (pmax_stop is not None and P > pmax_stop) or (stop_v is not None and v > stop_v)
    t0 = time.time()
    path = trace(cont, z0, t, ds, stop, nmax=nmax)
    if verbose:
        print("   traced %d points in %.1f s" % (len(path), time.time() - t0), flush=True)
    return cont, path


def analyse(model, cont, path, vtargets):
    iv = model.v_index()
    sgn = -1.0   # v = const - z[iv] for both models
    limP = refine_events(cont, path, lambda z: z[-1], dqfun=lambda t: t[-1], targets=(0.0,))
    limv = refine_events(cont, path, lambda z: model.uvP(z)[1], dqfun=lambda t: sgn * t[iv],
                         targets=vtargets)
    zeroP = [model.uvP(e[2]) for e in limP if e[0] == "cross" and model.uvP(e[2])[1] > 1.0]
    # all special points with their position along the path (for the CSV)
    analyse.events = [(e[3], model.uvP(e[2])) for e in limP + limv
                      if not (e[0] == "cross" and model.uvP(e[2])[1] <= 1.0)]
    return ([model.uvP(e[2]) for e in limP if e[0] == "extremum"],
            [model.uvP(e[2]) for e in limv if e[0] == "extremum"],
            [(e[1],) + tuple(model.uvP(e[2])) for e in limv if e[0] == "cross"],
            zeroP)


def first_limit(model, ds):
    """Trace until just after the first load maximum and refine it."""
    cont, path = run_path(model, ds, stop_v=62.0, verbose=False)
    for k in range(len(path) - 1):
        if path[k][1][-1] > 0 and path[k + 1][1][-1] < 0:
            z0, t0 = path[k]
            z1 = path[k + 1][0]
            dsf = cont.w**2 * t0 @ (z1 - z0)
            s = brentq(lambda s: cont.point(z0, t0, s)[1][-1], 0, dsf, xtol=1e-14 * dsf, rtol=1e-15)
            return model.uvP(cont.point(z0, t0, s)[0]), cont, path
    raise RuntimeError("no limit point")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--skip-fe", action="store_true")
    ap.add_argument("--skip-shoot", action="store_true", help="FE part only (CSV not rewritten)")
    args = ap.parse_args()
    np.set_printoptions(precision=10)
    results = {}
    vt = [10.0 * k for k in range(1, 11)]

    # ---------------- linear check
    print("== linear frame theory (exact frame elements)")
    lin = {}
    for name, ea, ga in [("EB, EA finite", EA, None), ("EB, inextensible", 1e14, None),
                         ("Timoshenko G=E/2 k=1", EA, GA_TIM)]:
        du, dv = linear_frame(ea=ea, ga=ga)
        lin[name] = (du, dv)
        print("   %-22s du/dP = %.10e  dv/dP = %.10e  (cm/kN)  -> P/v = %.8f kN/cm" % (name, du, dv, 1 / dv))
    results["linear"] = lin

    # ---------------- method A: shooting, primary, shear rigid
    ds = 0.02 if args.quick else 0.01
    if not args.skip_shoot:
        run_shooting(args, ds, vt, results)
    if not args.skip_fe:
        run_fe(args, ds, vt, results)


def run_shooting(args, ds, vt, results):
    steps_list = [24, 48] if args.quick else [24, 48, 96]
    print("== method A: multiple shooting, shear-rigid (GA = inf), EA = %g" % EA)
    shoot = {}
    for nst in steps_list:
        m = Shooting(nsteps=nst)
        t0 = time.time()
        cont, path = run_path(m, ds, stop_v=None, pmax_stop=PSTOP, nmax=4000)
        limP, limv, cross, zeroP = analyse(m, cont, path, vt)
        # initial slope
        z0, t0v = path[0]
        dvdP = -t0v[m.v_index()] / t0v[-1]
        dudP = t0v[6 * m.LOADSEG] / t0v[-1]
        shoot[nst] = dict(limP=limP, limv=limv, cross=cross, path=path, model=m,
                          dvdP0=dvdP, dudP0=dudP, events=list(analyse.events))
        print("   RK4 steps/segment %d (h=%.4f cm): %.1f s" % (nst, m.h, time.time() - t0))
        print("     initial du/dP = %.10e dv/dP = %.10e" % (dudP, dvdP))
        for (u, v, P) in limP:
            print("     load limit  P = %.10f  u = %.8f  v = %.8f" % (P, u, v))
        for (u, v, P) in limv:
            print("     v extremum  v = %.8f  u = %.8f  P = %.10f" % (v, u, P))
        for (tg, u, v, P) in cross:
            print("     v = %5.1f   P = %.10f  u = %.8f" % (tg, P, u))
        for (u, v, P) in zeroP:
            print("     P = 0 crossing  v = %.8f  u = %.8f" % (v, u))
        print("     end of trace    P = %.6f  u = %.6f  v = %.6f" % (m.uvP(path[-1][0])[2], m.uvP(path[-1][0])[0], m.uvP(path[-1][0])[1]))
    best = steps_list[-1]
    m = shoot[best]["model"]
    path = shoot[best]["path"]
    # write CSV: every k-th point, ~200 rows, up to v max region / P = 60
    pts = np.array([m.uvP(z) for z, _ in path])
    stride = max(1, len(pts) // 200)
    rows = [(float(k), tuple(pts[k])) for k in range(0, len(pts), stride)]
    if (len(pts) - 1) % stride:
        rows.append((float(len(pts) - 1), tuple(pts[-1])))
    # insert the exact special points (load limits, v extrema, v = 10..90 and P = 0 crossings)
    rows += shoot[best]["events"]
    rows.sort(key=lambda r: r[0])
    with open(os.path.join(HERE, "lee_frame_reference.csv"), "w") as f:
        f.write("v,u,P\n")
        for _, (u, v, P) in rows:
            f.write("%.8f,%.8f,%.8f\n" % (v, u, P))
    print("   wrote lee_frame_reference.csv (%d rows, path order, incl. %d special points)"
          % (len(rows), len(shoot[best]["events"])))
    print("   comparison with Leahu-Aluas & Abed-Meraim (2011) Table 11 (nearest path point in (u,v)):")
    print("       u_lit    v_lit   P_lit  | dist(u,v)  P_here   P_here-P_lit")
    for (ul, vl, Pl, dist, Ph) in compare_literature(pts):
        print("     %7.3f %8.3f %7.2f  | %8.3f  %8.3f  %+7.3f" % (ul, vl, Pl, dist, Ph, Ph - Pl))
    results["shoot"] = {k: dict(limP=d["limP"], limv=d["limv"], cross=d["cross"],
                                dvdP0=d["dvdP0"], dudP0=d["dudP0"]) for k, d in shoot.items()}

    # ---------------- variants: Timoshenko, inextensible
    print("== variants (shooting, 96 steps/segment)")
    var = {}
    for name, kw in [("Timoshenko GA=21600 kN", dict(ga=GA_TIM)), ("inextensible", dict(ea=None))]:
        mv = Shooting(nsteps=48 if args.quick else 96, **kw)
        cont, pth = run_path(mv, ds, pmax_stop=PSTOP, nmax=4000, verbose=False)
        limP, limv, cross, zeroP = analyse(mv, cont, pth, vt)
        var[name] = dict(limP=limP, limv=limv, cross=cross)
        print("   %s:" % name)
        for (u, v, P) in limP:
            print("     load limit  P = %.10f  u = %.8f  v = %.8f" % (P, u, v))
        for (u, v, P) in limv:
            print("     v extremum  v = %.8f  u = %.8f  P = %.10f" % (v, u, P))
        for (tg, u, v, P) in cross:
            if tg in (60.0, 80.0):
                print("     v = %5.1f   P = %.10f  u = %.8f" % (tg, P, u))
    results["variants"] = var


def run_fe(args, ds, vt, results):
    # ---------------- method B: FE
    if True:
        print("== method B: Reissner FE (1-pt integration), shear-rigid via GA = 1e4 EA penalty")
        fe = {}
        for nel in ([20, 40] if args.quick else [40, 80, 160, 320]):
            mf = ReissnerFE(nel)
            t0 = time.time()
            if nel <= 160:
                cont, pth = run_path(mf, ds, pmax_stop=PSTOP, nmax=4000, verbose=False)
                limP, limv, cross, zeroP = analyse(mf, cont, pth, vt)
            else:
                (u, v, P), cont, pth = first_limit(mf, ds)
                limP, limv, cross = [(u, v, P)], [], []
            fe[nel] = dict(limP=limP, limv=limv, cross=cross)
            print("   nel/member %d: %.1f s" % (nel, time.time() - t0))
            for (u, v, P) in limP:
                print("     load limit  P = %.10f  u = %.8f  v = %.8f" % (P, u, v))
            for (u, v, P) in limv:
                print("     v extremum  v = %.8f  u = %.8f  P = %.10f" % (v, u, P))
            for (tg, u, v, P) in cross:
                if tg in (60.0, 80.0):
                    print("     v = %5.1f   P = %.10f  u = %.8f" % (tg, P, u))
        ns = sorted(fe)
        if len(ns) >= 3:
            print("   Richardson on first limit load:")
            for i in range(len(ns) - 2):
                p1, p2, p3 = [fe[n]["limP"][0][2] for n in ns[i:i + 3]]
                rate = math.log2((p2 - p1) / (p3 - p2))
                rich = p3 + (p3 - p2) / 3.0
                print("     %d/%d/%d: observed order %.4f, h^2-extrapolated P_max = %.10f"
                      % (ns[i], ns[i + 1], ns[i + 2], rate, rich))
        results["fe"] = fe
        # Timoshenko FE check (natural GA)
        mf = ReissnerFE(160, ga=GA_TIM)
        (u, v, P), _, _ = first_limit(mf, ds)
        mf2 = ReissnerFE(320, ga=GA_TIM)
        (u2, v2, P2), _, _ = first_limit(mf2, ds)
        print("   Timoshenko FE 160: P_max = %.10f, 320: %.10f, extrap %.10f" % (P, P2, P2 + (P2 - P) / 3))


if __name__ == "__main__":
    main()
