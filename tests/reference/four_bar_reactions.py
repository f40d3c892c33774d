#!/usr/bin/env python3
"""IFToMM A02 (N-four-bar, N = 2): in-plane joint reactions, computed outside flexmb.

Definition (examples/four_bar.toml, shared/reference/benchmarks.md A02): five uniform rods of
length 1 m and mass 1 kg (I = m L^2 / 12 about the centre), gravity 9.81 m/s^2 along -y.
Cranks k = 0, 1, 2 pivot on the ground at (k, 0); couplers j = 0, 1 join the tops of cranks
j and j + 1. At t = 0 the cranks are vertical (phi = pi/2) and turn at phi' = -1 rad/s.

Method (planar, two steps, numpy only):
1. Motion: the reduced model of the parallelogram branch in the crank angle phi,
       J phi'' = -((N+1)/2 + N) g cos(phi),   J = (N+1)/3 + N,
   integrated with classical RK4 at h = 1e-5 s (and h = 2e-5 s to measure its error).
   Every crank turns by phi, every coupler translates with the crank tops.
2. Reactions: planar Newton-Euler of the five bodies (15 equations: m a_G = m g + sum F,
   I alpha = sum (r_P - r_G) x F) in the 14 unknown reaction components (x, y of the force
   each joint exerts on its node B, the node A getting the opposite), solved by least squares.
   The system has one equation more than unknowns: its residual checks that the motion of
   step 1 is the motion of the Newton-Euler equations. Away from the singular positions
   (phi = 0 or pi: every link on one line) the 14 columns are independent and the in-plane
   reactions are determined; the smallest singular value of the 15 x 14 matrix says how far
   from singular each row is.

Joint names and their nodes A, B are those of the model file:
  ground0..2: ground -> crank k;  c0_left: crank0 -> coupler0;  c0_right: coupler0 -> crank1;
  c1_left: crank1 -> coupler1;  c1_right: coupler1 -> crank2.

Output: four_bar_reactions.csv, every 0.01 s over 0..2 s: t, phi, sigma_min, then
<joint>_fx, <joint>_fy for the seven joints [N]. Run: python3 four_bar_reactions.py.
"""
import numpy as np

N = 2
G = 9.81
M, L = 1.0, 1.0
I = M * L**2 / 12.0
J = (N + 1) / 3.0 + N
C = ((N + 1) / 2.0 + N) * G
T_END, DT_OUT = 2.0, 0.01

# bodies: cranks 0..2, couplers 3..4
CRANKS = [0, 1, 2]
COUPLERS = [3, 4]
# joints: (name, node A (None: ground), node B)
JOINTS = [
    ("ground0", None, 0),
    ("ground1", None, 1),
    ("ground2", None, 2),
    ("c0_left", 0, 3),
    ("c0_right", 3, 1),
    ("c1_left", 1, 4),
    ("c1_right", 4, 2),
]
# joint points, as functions of phi: crank k pivot (k, 0), top (k + cos, sin)
def joint_point(name, phi):
    c, s = np.cos(phi), np.sin(phi)
    return {
        "ground0": np.array([0.0, 0.0]),
        "ground1": np.array([1.0, 0.0]),
        "ground2": np.array([2.0, 0.0]),
        "c0_left": np.array([c, s]),
        "c0_right": np.array([1.0 + c, s]),
        "c1_left": np.array([1.0 + c, s]),
        "c1_right": np.array([2.0 + c, s]),
    }[name]


def rhs(y):
    return np.array([y[1], -C / J * np.cos(y[0])])


def integrate(h):
    """(t, phi, phi') every DT_OUT by RK4 at step h."""
    y = np.array([np.pi / 2, -1.0])
    per = int(round(DT_OUT / h))
    out = [(0.0, *y)]
    for k in range(1, int(round(T_END / h)) + 1):
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * h * k1)
        k3 = rhs(y + 0.5 * h * k2)
        k4 = rhs(y + h * k3)
        y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        if k % per == 0:
            out.append((k * h, *y))
    return np.array(out)


def body_state(b, phi, w, al):
    """Centre of mass, its acceleration and the angular acceleration of body b."""
    c, s = np.cos(phi), np.sin(phi)
    u = np.array([c, s])
    du = np.array([-s, c])
    if b in CRANKS:
        g = np.array([float(b), 0.0]) + 0.5 * L * u
        a = 0.5 * L * (al * du - w**2 * u)
        return g, a, al
    j = b - 3  # a coupler translates with the top of crank j
    g = np.array([j + 0.5, 0.0]) + L * u
    a = L * (al * du - w**2 * u)
    return g, a, 0.0


def reactions(phi, w):
    al = -C / J * np.cos(phi)
    A = np.zeros((15, 14))
    b = np.zeros(15)
    for i in range(5):
        g, a, alpha = body_state(i, phi, w, al)
        # m a - m g = sum F ;  I alpha = sum r x F
        b[3 * i : 3 * i + 2] = M * a - M * np.array([0.0, -G])
        b[3 * i + 2] = I * alpha
        for k, (name, na, nb) in enumerate(JOINTS):
            p = joint_point(name, phi)
            for node, sign in ((nb, 1.0), (na, -1.0)):
                if node != i:
                    continue
                r = p - g
                A[3 * i, 2 * k] += sign
                A[3 * i + 1, 2 * k + 1] += sign
                A[3 * i + 2, 2 * k] += -sign * r[1]
                A[3 * i + 2, 2 * k + 1] += sign * r[0]
    f, *_ = np.linalg.lstsq(A, b, rcond=None)
    residual = np.linalg.norm(A @ f - b)
    sigma = np.linalg.svd(A, compute_uv=False)[-1]
    return f, residual, sigma


def main():
    fine = integrate(1e-5)
    coarse = integrate(2e-5)
    print(f"RK4 error estimate on phi over {T_END} s: {np.abs(fine[:, 1] - coarse[:, 1]).max():.2e}")
    rows = []
    worst_residual = 0.0
    for t, phi, w in fine:
        f, res, sigma = reactions(phi, w)
        worst_residual = max(worst_residual, res)
        rows.append([t, phi, sigma, *f])
    rows = np.array(rows)
    print(f"largest Newton-Euler residual: {worst_residual:.2e} N")
    print(f"smallest sigma_min: {rows[:, 2].min():.3e} at t = {rows[rows[:, 2].argmin(), 0]:.2f} s")
    header = ["t", "phi", "sigma_min"] + [f"{n}_{c}" for n, *_ in JOINTS for c in ("fx", "fy")]
    np.savetxt(
        "four_bar_reactions.csv",
        rows,
        delimiter=",",
        header=",".join(header),
        comments="",
        fmt="%.12e",
    )


if __name__ == "__main__":
    main()
