"""Reproduce the IVP Test Set 'crank' problem (Simeon's flexible slider crank, 4-mode model).

Port of RESMBS from crank.f (IVP Test Set for IVP solvers, Bari; B. Simeon 1995/1998),
with ipar = (0, 0): linear stiffness term, no damping.  Constants are copied exactly,
including PI = 3.1415927 and the axial mass block MQ(3:4,3:4) = rho*A*L*[8 1; 1 2]
(which is 15 times the consistent quadratic-element mass rho*A*L/15*[8 1; 1 2]).

The index-2 DAE is integrated here in index-1 form (accelerations and multipliers from the
augmented system), with DOP853 at rtol 1e-13; the position/velocity constraint drift is
reported.  The purpose is only to check that the transcription of the model, its data and
initial values reproduces the published reference solution at t = 0.1 s.

Usage: python3 slider_crank_testset.py
"""
import numpy as np
from scipy.integrate import solve_ivp

M1, M2, M3 = 0.36, 0.151104, 0.075552
L1, L2 = 0.15, 0.30
J1, J2 = 0.002727, 0.0045339259
PI = 3.1415927
EE, BB, HH, RHO = 0.20e12, 0.0080, 0.0080, 7870.0
GRAV, OMEGA = 0.0, 150.0
NQ, NP = 4, 7

FACM = RHO * BB * HH * L2
FACK = EE * BB * HH / L2
FACB = BB * HH * L2
MQ = np.zeros((4, 4)); KQ = np.zeros((4, 4)); BQ = np.zeros((4, 4))
MQ[0, 0] = FACM * .5; MQ[1, 1] = FACM * .5
MQ[2, 2] = FACM * 8.; MQ[2, 3] = MQ[3, 2] = FACM * 1.; MQ[3, 3] = FACM * 2.
KQ[0, 0] = FACK * PI**4 / 24. * (HH / L2)**2
KQ[1, 1] = FACK * PI**4 * 2. / 3. * (HH / L2)**2
KQ[2, 2] = FACK * 16. / 3.; KQ[2, 3] = KQ[3, 2] = -FACK * 8. / 3.; KQ[3, 3] = FACK * 7. / 3.
BQ[0, 2] = -FACB * 16. / PI**3
BQ[0, 3] = FACB * (8. / PI**3 - 1. / PI)
BQ[1, 3] = FACB * 0.5 / PI
BQ[2, 0] = FACB * 16. / PI**3
BQ[3, 0] = -FACB * (8. / PI**3 - 1. / PI)
BQ[3, 1] = -FACB * 0.5 / PI
c1 = np.array([0, 0, FACB * 2. / 3., FACB / 6.])
c2 = np.array([FACB * 2. / PI, 0, 0, 0])
c12 = np.array([0, 0, L2 * FACB / 3., L2 * FACB / 6.])
c21 = np.array([L2 * FACB / PI, -L2 * FACB * 0.5 / PI, 0, 0])


VARIANT = dict(nonlinear=False, MQ=MQ)


def accel(t, p, v):
    MQ = VARIANT['MQ']
    q = p[3:]; qd = v[3:]
    cp1, sp1 = np.cos(p[0]), np.sin(p[0])
    cp2, sp2 = np.cos(p[1]), np.sin(p[1])
    c12_, s12_ = np.cos(p[0] - p[1]), np.sin(p[0] - p[1])
    V1, V2 = v[0], v[1]
    c1q, c1qd = c1 @ q, c1 @ qd
    c2q, c2qd = c2 @ q, c2 @ qd
    c12q, c12qd = c12 @ q, c12 @ qd
    MQQ = MQ.T @ q                 # MQQ(I) = sum_J MQ(J,I) Q(J)
    KQQ = KQ.T @ q
    QTBQ = BQ.T @ q                # QTBQ(I) = sum_J Q(J) BQ(J,I)
    BQQD = BQ @ qd                 # BQQD(I) = sum_J BQ(I,J) QD(J)
    QTMQQ = q @ MQQ; QDTMQQ = qd @ MQQ; QDTBQQD = qd @ BQQD
    AM = np.zeros((7, 7))
    AM[0, 0] = J1 + M2 * L1 * L1
    AM[0, 1] = .5 * L1 * L2 * M2 * c12_ + RHO * L1 * (s12_ * c2q + c12_ * c1q)
    AM[1, 1] = J2 + QTMQQ + 2.0 * RHO * c12q
    AM[2, 2] = M3
    AM[0, 3:] = RHO * L1 * (-s12_ * c1 + c12_ * c2)
    AM[1, 3:] = RHO * c21 + RHO * QTBQ
    AM[3:, 3:] = MQ
    AM = np.triu(AM) + np.triu(AM, 1).T
    QKU = q[3]; QDKU = qd[3]
    GP = np.zeros((3, 7))
    GP[0, 0] = L1 * cp1; GP[0, 1] = L2 * cp2 + QKU * cp2
    GP[1, 0] = L1 * sp1; GP[1, 1] = L2 * sp2 + QKU * sp2; GP[1, 2] = 1.
    GP[2, 0] = 1.
    GP[0, 6] = sp2; GP[1, 6] = -cp2
    F = np.zeros(7)
    F[0] = -.5 * L1 * GRAV * (M1 + 2 * M2) * cp1 - .5 * L1 * L2 * M2 * V2 * V2 * s12_
    F[1] = -.5 * L2 * GRAV * M2 * cp2 + .5 * L1 * L2 * M2 * V1 * V1 * s12_
    F[0] += RHO * L1 * V2 * V2 * (-s12_ * c1q + c12_ * c2q) - 2 * RHO * L1 * V2 * (c12_ * c1qd + s12_ * c2qd)
    F[1] += (RHO * L1 * V1 * V1 * (s12_ * c1q - c12_ * c2q) - 2 * RHO * V2 * c12qd
             - 2 * V2 * QDTMQQ - RHO * QDTBQQD - RHO * GRAV * (cp2 * c1q - sp2 * c2q))
    F[3:] = (V2 * V2 * MQQ + RHO * (V2 * V2 * c12 + L1 * V1 * V1 * (c12_ * c1 + s12_ * c2) + 2 * V2 * BQQD)
             - RHO * GRAV * (sp2 * c1 + cp2 * c2)) - KQQ
    if VARIANT['nonlinear']:          # ipar(1) = 1 of crank.f: nonlinear stiffness term
        fk = 0.5 * EE * BB * HH / L2**2 * PI**2
        fb = 80.0 / (PI**2 * 9.0)
        F[3] -= fk * (q[0] * q[3] - fb * q[1] * (-4 * q[2] + 2 * q[3]))
        F[4] -= fk * (4 * q[1] * q[3] - fb * q[0] * (-4 * q[2] + 2 * q[3]))
        F[5] -= fk * 4.0 * fb * q[0] * q[1]
        F[6] -= fk * (0.5 * q[0]**2 + 2 * q[1]**2 - 2 * fb * q[0] * q[1])
    # acceleration constraint: GP w + g = 0
    g = np.array([-L1 * sp1 * V1 * V1 - (L2 + QKU) * sp2 * V2 * V2 + 2 * V2 * cp2 * QDKU,
                  L1 * cp1 * V1 * V1 + (L2 + QKU) * cp2 * V2 * V2 + 2 * V2 * sp2 * QDKU,
                  0.0])
    # residual form: AM w - F + GP^T lam = 0
    A = np.zeros((10, 10)); A[:7, :7] = AM; A[:7, 7:] = GP.T; A[7:, :7] = GP
    sol = np.linalg.solve(A, np.concatenate([F, -g]))
    return sol[:7], sol[7:]


def constraints(t, p, v):
    q4 = p[6]
    plc = np.array([L1 * np.sin(p[0]) + (L2 + q4) * np.sin(p[1]),
                    p[2] - L1 * np.cos(p[0]) - (L2 + q4) * np.cos(p[1]),
                    p[0] - OMEGA * t])
    return plc


def rhs(t, y):
    p, v = y[:7], y[7:]
    w, _ = accel(t, p, v)
    return np.concatenate([v, w])


y0 = np.array([0.0, 0.0, 4.500169330000000e-01, 0.0, 0.0, 1.033398630000000e-05, 1.693279690000000e-05,
               1.500000000000000e+02, -7.499576703969453e+01, -2.689386719979040e-06, 4.448961125815990e-01,
               4.634339319238670e-03, -1.785910760000550e-06, -2.689386719979040e-06])
yref = np.array([0.1500000000000104e+02, -0.3311734988256260e+00, 0.1697373328427860e+00,
                 0.1893192899613509e-03, 0.2375751249879174e-04, -0.5323896770569702e-05,
                 -0.8363313279112129e-05, 0.1500000000000000e+03, 0.6025346755138369e+02,
                 -0.8753116326670527e+01, -0.3005541400289738e-01, -0.5500431812571696e-02,
                 0.4974111734266989e-03, 0.1105560003626645e-02])

def history(t_out, nonlinear=False, consistent_axial_mass=False, rtol=1e-11):
    """Time history (x3, q1) of the 4-mode model, optionally with the ipar(1)=1 nonlinear
    stiffness and/or the consistent quadratic axial mass rho A L/15 [8 1; 1 2]."""
    MQc = MQ.copy()
    if consistent_axial_mass:
        MQc[2:, 2:] /= 15.0
    VARIANT['nonlinear'] = nonlinear; VARIANT['MQ'] = MQc
    sol = solve_ivp(rhs, (0, t_out[-1]), y0, method="DOP853", rtol=rtol, atol=rtol * 1e-3, t_eval=t_out)
    VARIANT['nonlinear'] = False; VARIANT['MQ'] = MQ
    return sol.y[2], sol.y[3]


if __name__ == "__main__":
    w0, lam0 = accel(0.0, y0[:7], y0[7:])
    print("consistent initial accelerations:", w0)
    print("initial multipliers:", lam0)
    print("initial constraint residual:", constraints(0.0, y0[:7], y0[7:]))
    for rtol in (1e-10, 1e-13):
        sol = solve_ivp(rhs, (0, 0.1), y0, method="DOP853", rtol=rtol, atol=rtol * 1e-3, dense_output=True)
        y = sol.y[:, -1]
        print(f"rtol {rtol:g}: nfev {sol.nfev}")
        print("  constraint residual at 0.1:", constraints(0.1, y[:7], y[7:]))
        names = ["phi1", "phi2", "x3", "q1", "q2", "q3", "q4"] + ["d" + n for n in ["phi1", "phi2", "x3", "q1", "q2", "q3", "q4"]]
        for n, a, b in zip(names, y, yref):
            print(f"  {n:6s} {a: .15e}  ref {b: .15e}  rel diff {abs(a - b) / max(abs(b), 1e-30):.2e}")
