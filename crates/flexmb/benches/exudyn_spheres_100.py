"""The spheres_100 contact benchmark of benches/engine.rs, set up in Exudyn's penalty contact.

Not part of flexmb's tests or CI: a measurement script behind BENCHMARKS.md ("Contact and
impact (issue 10)"). It needs Python 3 and Exudyn (written against Exudyn 1.13.6):

    python3 -m venv /tmp/exuvenv && /tmp/exuvenv/bin/pip install exudyn==1.13.6
    /tmp/exuvenv/bin/python crates/flexmb/benches/exudyn_spheres_100.py --steps 1e-3 1e-4 2e-5 1e-5 5e-6
    # compare with flexmb (the same run, its events and final state):
    FLEXMB_SPHERES_OUT=/tmp/flexmb_spheres.json cargo bench -p flexmb --bench engine -- spheres_100
    /tmp/exuvenv/bin/python crates/flexmb/benches/exudyn_spheres_100.py --steps 1e-5 \
        --compare /tmp/flexmb_spheres.json

The problem (as `spheres` in engine.rs): 100 steel balls (radius 20 mm, 0.263 kg, inertia
0.4 m r^2) in a row along x, 45 mm apart, 1 mm above the plane z = 0, moving at +0.3 m/s
(even balls) and -0.3 m/s (odd balls), gravity -9.81 m/s^2 along z, 0.2 s. Contact laws:

* ball-ball (99, ObjectContactSphereSphere) and ball-plane (100, ObjectContactSphereTriangle,
  one large triangle), both F = k delta^1.5 (1 + chi deltadot / v_imp), Exudyn's
  impactModel 1 (Hunt-Crossley, chi = 3 (1 - e') / 2), with e' = 0.82 so that chi = 0.27,
  the Lankarani-Nikravesh factor 3 (1 - e^2) / 4 of flexmb's e = 0.8; k the Hertz stiffness
  of steel 4/3 E* sqrt(R*) with E* = E / (2 (1 - nu^2)), E = 210 GPa, nu = 0.3, R* = r / 2
  between balls and r on the plane; minimum impact velocity 1e-3 m/s;
* ball-plane Coulomb friction mu = 0.3, linear below 1e-3 m/s (frictionProportionalZone).

Solver: Exudyn's implicit generalized-alpha (spectral radius 0.9, as flexmb's rho_inf), its
default modified Newton, sparse LU (EigenSparse), one thread, Euler-parameter nodes, its
default adaptive step (halving when Newton or the discontinuous iteration fails, doubling
after 10 good steps) but without the contacts' recommended step at an onset (see
settings()). Exudyn has no step control that resolves an impact once the contact is closed,
so the largest step is given (--steps): each value is one run. EXUDYN_MODULE=fast selects
Exudyn's exudynCPPfast module (no range checks).

Measured per run, with Exudyn's own counters and timer (solver.it; solver.timer.total, filled
with show.computationTime): accepted steps, Newton iterations, Jacobian updates, discontinuous
iterations, the solve time (the timer counts wall-clock time), and the process's CPU time over
the solve (time.process_time: on a shared machine the wall clock also counts the time other
processes held the core). A second, untimed run of the same problem counts the step attempts
that were repeated (a pre-step function is called at every attempt) and records, at the end
of every accepted step as engine.rs does for flexmb, the events the comparison looks at: the
first contact of balls 0 and 1 and their velocities when it opens again, the landing of
ball 0, the number of ball-ball and ball-plane contact closures, and the final state.
"""

import argparse
import json
import sys
import time

import numpy as np
import exudyn as exu
from exudyn.itemInterface import (
    MarkerBodyRigid,
    NodeGenericData,
    ObjectContactSphereSphere,
    ObjectContactSphereTriangle,
    ObjectGround,
)
from exudyn.utilities import RigidBodyInertia

N_BALLS = 100
RADIUS = 0.02  # [m]
MASS = 0.263  # [kg]
PITCH = 0.045  # [m]
LIFT = 1e-3  # [m] initial gap to the plane
SPEED = 0.3  # [m/s]
T_END = 0.2  # [s]
E_STAR = 210e9 / (2.0 * (1.0 - 0.09))  # [Pa] two steels
CHI = 0.75 * (1.0 - 0.8**2)  # Lankarani-Nikravesh factor of e = 0.8
E_HUNT_CROSSLEY = 1.0 - CHI / 1.5  # Exudyn's impactModel 1: chi = 3 (1 - e') / 2
MU = 0.3
V_STICTION = 1e-3  # [m/s]
V_IMPACT_MIN = 1e-3  # [m/s]


def hertz(r_star):
    """Hertz stiffness 4/3 E* sqrt(R*) [N/m^1.5]."""
    return 4.0 / 3.0 * E_STAR * np.sqrt(r_star)


def build(mbs):
    """The balls, the plane and the 199 contacts; returns the balls' node indices."""
    ground = mbs.AddObject(ObjectGround())
    m_ground = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=[0, 0, 0]))
    inertia = RigidBodyInertia(mass=MASS, inertiaTensor=np.eye(3) * 0.4 * MASS * RADIUS**2)
    nodes, markers = [], []
    for i in range(N_BALLS):
        body = mbs.CreateRigidBody(
            referencePosition=[i * PITCH, 0, RADIUS + LIFT],
            initialVelocity=[SPEED if i % 2 == 0 else -SPEED, 0, 0],
            inertia=inertia,
            gravity=[0, 0, -9.81],
            nodeType=exu.NodeType.RotationEulerParameters,
            show=False,
        )
        nodes.append(mbs.GetObject(body)["nodeNumber"])
        markers.append(mbs.AddMarker(MarkerBodyRigid(bodyNumber=body, localPosition=[0, 0, 0])))
    # one triangle, normal +z ((p1 - p0) x (p2 - p0)), far larger than the row
    plane = [[-2.0, -2.0, 0.0], [10.0, -2.0, 0.0], [-2.0, 10.0, 0.0]]
    law = dict(
        contactStiffnessExponent=1.5,
        contactDamping=0.0,
        impactModel=1,
        restitutionCoefficient=E_HUNT_CROSSLEY,
        minimumImpactVelocity=V_IMPACT_MIN,
    )
    for i in range(N_BALLS):
        data = mbs.AddNode(NodeGenericData(numberOfDataCoordinates=4, initialCoordinates=[LIFT, 0, 0, 0]))
        mbs.AddObject(
            ObjectContactSphereTriangle(
                markerNumbers=[markers[i], m_ground],
                nodeNumber=data,
                sphereRadius=RADIUS,
                trianglePoints=exu.Vector3DList(plane),
                includeEdges=0,
                dynamicFriction=MU,
                frictionProportionalZone=V_STICTION,
                contactStiffness=hertz(RADIUS),
                **law,
            )
        )
        if i > 0:
            gap = PITCH - 2 * RADIUS
            data = mbs.AddNode(NodeGenericData(numberOfDataCoordinates=4, initialCoordinates=[gap, 0, 0, 0]))
            mbs.AddObject(
                ObjectContactSphereSphere(
                    markerNumbers=[markers[i - 1], markers[i]],
                    nodeNumber=data,
                    spheresRadii=[RADIUS, RADIUS],
                    dynamicFriction=0.0,
                    contactStiffness=hertz(RADIUS / 2),
                    **law,
                )
            )
    return nodes


def settings(h):
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.endTime = T_END
    ti.numberOfSteps = int(round(T_END / h))
    ti.generalizedAlpha.spectralRadius = 0.9
    ti.verboseMode = 0
    # With the recommended step of the contacts (the default), the run stops at the first
    # ball-ball contact (t = 8.33 ms): the step that ends at the onset leaves a gap of ~0,
    # the next recommendation (gap / gap rate) is ~0 and the step reaches the minimum step
    # size while the error |gap| k (tolerance 1) stays above the tolerance. Exudyn's
    # documented way out: ignore the recommendation.
    ti.discontinuous.useRecommendedStepSize = False
    s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    s.parallel.numberOfThreads = 1
    s.solution.file.write = False
    s.show.computationTime = True  # fills solver.timer
    s.show.statistics = False
    return s


class Recorder:
    """Events at the end of every accepted step (the same definitions as SphereEvents in
    engine.rs) and the number of step attempts."""

    def __init__(self, mbs, nodes):
        self.mbs = mbs
        idx = np.array([mbs.GetNodeODE2Index(n) for n in nodes])
        self.ix, self.iz = idx, idx + 2
        self.ref = np.array([mbs.GetNodeParameter(n, "referenceCoordinates")[:3] for n in nodes])
        self.attempts = 0
        self.last = None
        self.first_contact_01 = None
        self.separation_01 = None
        self.landing_0 = None
        self.pair_closures = 0
        self.floor_closures = 0

    def pre_step(self, mbs, t):
        self.attempts += 1
        return True

    def post_step(self, mbs, t):
        q = mbs.systemData.GetODE2Coordinates()
        v = mbs.systemData.GetODE2Coordinates_t()
        x = self.ref[:, 0] + q[self.ix]
        z = self.ref[:, 2] + q[self.iz]
        # the balls stay in the plane y = 0 (nothing pushes them out of it)
        pairs = np.hypot(np.diff(x), np.diff(z)) - 2 * RADIUS
        floor = z - RADIUS
        if self.last is not None:
            t0, p0, f0 = self.last

            def crossing(g0, g1):
                return t0 + (t - t0) * g0 / (g0 - g1)

            closed = (p0 >= 0) & (pairs < 0)
            self.pair_closures += int(closed.sum())
            if closed[0] and self.first_contact_01 is None:
                self.first_contact_01 = crossing(p0[0], pairs[0])
            if p0[0] < 0 <= pairs[0] and self.separation_01 is None:
                self.separation_01 = (crossing(p0[0], pairs[0]), v[self.ix[0]], v[self.ix[1]])
            landed = (f0 >= 0) & (floor < 0)
            self.floor_closures += int(landed.sum())
            if landed[0] and self.landing_0 is None:
                self.landing_0 = crossing(f0[0], floor[0])
        self.last = (t, pairs, floor)
        return True


def final_state(mbs, nodes):
    pos = np.array([mbs.GetNodeOutput(n, exu.OutputVariableType.Position) for n in nodes])
    vel = np.array([mbs.GetNodeOutput(n, exu.OutputVariableType.Velocity) for n in nodes])
    omega = np.array([mbs.GetNodeOutput(n, exu.OutputVariableType.AngularVelocity) for n in nodes])
    return pos[:, [0, 2]].tolist(), vel[:, [0, 2]].tolist(), omega[:, 1].tolist()


def run(h, record):
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    nodes = build(mbs)
    mbs.Assemble()
    rec = None
    if record:
        rec = Recorder(mbs, nodes)  # the nodes' coordinate indices are known after Assemble
        mbs.SetPreStepUserFunction(rec.pre_step)
        mbs.SetPostStepUserFunction(rec.post_step)
    solver = exu.MainSolverImplicitSecondOrder()
    wall, cpu = time.perf_counter(), time.process_time()
    ok = solver.SolveSystem(mbs, settings(h))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    it = solver.it
    out = {
        "tool": "exudyn " + exu.__version__,
        "h": h,
        "success": bool(ok),
        "t": mbs.systemData.GetTime(),
        "steps": it.currentStepIndex - 1,
        "newton_iterations": it.newtonStepsCount,
        "jacobians": it.newtonJacobiCount,
        "discontinuous_iterations": it.discontinuousIterationsCount,
        "solve_seconds": solver.timer.total,
        "wall_seconds": wall,
        "cpu_seconds": cpu,
        "timer": solver.timer.ToString(),
    }
    if record:
        x, v, wy = final_state(mbs, nodes)
        out.update(
            attempts=rec.attempts,
            first_contact_01=rec.first_contact_01,
            separation_01=rec.separation_01,
            landing_0=rec.landing_0,
            pair_closures=rec.pair_closures,
            floor_closures=rec.floor_closures,
            x=x,
            v=v,
            wy=wy,
        )
    return out


def restitution(r):
    """(v1 - v0) after the first impact of balls 0 and 1 over 2 * SPEED before it."""
    if r.get("separation_01") is None:
        return float("nan")
    _, v0, v1 = r["separation_01"]
    return (v1 - v0) / (2 * SPEED)


def summary(r):
    v = np.array(r["v"])
    x = np.array(r["x"])
    wy = np.array(r["wy"])
    return {
        "momentum_x": MASS * v[:, 0].sum(),
        "kinetic": 0.5 * MASS * (v**2).sum() + 0.5 * 0.4 * MASS * RADIUS**2 * (wy**2).sum(),
        "z_min": x[:, 1].min(),
        "z_max": x[:, 1].max(),
    }


def compare(a, b):
    xa, xb = np.array(a["x"]), np.array(b["x"])
    va, vb = np.array(a["v"]), np.array(b["v"])
    wa, wb = np.array(a["wy"]), np.array(b["wy"])
    print(f"\n{a['tool']} (h = {a.get('h', 'adaptive')}) against {b['tool']}:")
    for key in ("first_contact_01", "landing_0"):
        print(f"  {key}: {a[key]:.6e} s against {b[key]:.6e} s")
    print(f"  restitution of the first impact (0-1): {restitution(a):.4f} against {restitution(b):.4f}")
    print(f"  ball-ball closures {a['pair_closures']} against {b['pair_closures']}; "
          f"ball-plane closures {a['floor_closures']} against {b['floor_closures']}")
    sa, sb = summary(a), summary(b)
    for k in sa:
        print(f"  {k}: {sa[k]:.6e} against {sb[k]:.6e}")
    dx = np.abs(xa[:, 0] - xb[:, 0])
    dvx = np.abs(va[:, 0] - vb[:, 0])
    dw = np.abs(wa - wb)
    print(f"  final x: max |diff| {dx.max():.3e} m (ball {dx.argmax()}), rms {np.sqrt((dx**2).mean()):.3e} m")
    print(f"  final vx: max |diff| {dvx.max():.3e} m/s (ball {dvx.argmax()}), rms {np.sqrt((dvx**2).mean()):.3e} m/s;"
          f" rms vx itself {np.sqrt((vb[:, 0]**2).mean()):.3e} m/s")
    print(f"  final wy: max |diff| {dw.max():.3e} rad/s, rms {np.sqrt((dw**2).mean()):.3e} rad/s;"
          f" rms wy itself {np.sqrt((wb**2).mean()):.3e} rad/s")
    print(f"  balls with |dx| < 1 mm: {(dx < 1e-3).sum()}, with |dvx| < 0.01 m/s: {(dvx < 0.01).sum()}")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=float, nargs="+", default=[1e-5], help="largest step sizes [s], one run each")
    p.add_argument("--repeat", type=int, default=1, help="timed runs per step size (the best is shown)")
    p.add_argument("--compare", help="JSON written by engine.rs with FLEXMB_SPHERES_OUT")
    p.add_argument("--out", help="write the recorded runs to this JSON file")
    args = p.parse_args()
    print("| tool | largest step [s] | steps | solve time [ms] | CPU time [ms] | time/step [us] "
          "| Newton it./step | Jacobians | disc. it. | repeated attempts |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    recorded = []
    for h in args.steps:
        timed = min((run(h, record=False) for _ in range(args.repeat)), key=lambda r: r["solve_seconds"])
        rec = run(h, record=True)
        same = rec["steps"] == timed["steps"] and rec["newton_iterations"] == timed["newton_iterations"]
        n = timed["steps"]
        print(f"| {timed['tool']} | {h:g} | {n} | {timed['solve_seconds'] * 1e3:.0f} "
              f"| {timed['cpu_seconds'] * 1e3:.0f} "
              f"| {timed['solve_seconds'] * 1e6 / n:.0f} | {timed['newton_iterations'] / n:.2f} "
              f"| {timed['jacobians']} | {timed['discontinuous_iterations']} "
              f"| {rec['attempts'] - rec['steps']}{'' if same else ' (recorded run differs!)'} |")
        if not timed["success"]:
            print(f"  run with h = {h:g} failed at t = {timed['t']}", file=sys.stderr)
        recorded.append(rec)
    for r in recorded:
        print(f"\nh = {r['h']:g}: wall {r['wall_seconds']:.3f} s; Exudyn timer:\n{r['timer']}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(recorded, f)
    if args.compare:
        with open(args.compare) as f:
            ref = json.load(f)
        for r in recorded:
            if r["success"]:
                compare(r, ref)
            else:
                print(f"\nh = {r['h']:g}: stopped at t = {r['t']:.6f} s, nothing to compare")


if __name__ == "__main__":
    main()
