"""Tables and CSV files for slider_crank_reference.md from the runs saved by
slider_crank_reference.py (directory _runs).  Prints markdown tables to stdout.

Needed runs (python3 slider_crank_reference.py run MODEL NEL CASE H [T_END DT_OUT]):
  ancf     8 16 32 64 128 (T, U) h=5e-6;  ancf 64 (T, U) h=1e-5 and 2.5e-6;
  ancf 128 (T, U) h=5e-6 dt_out=5e-5;  reissner 16 32 64 (T, U) h=5e-6; reissner 64 (T, U) h=2.5e-6;
  reissner 128 (T, U) h=5e-6 dt_out=5e-5;  reissner_eb 32 64 T, 64 U;
  reissner_rigidshear 32 U, reissner_norot 32 U.
"""
import os
import sys
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import slider_crank_reference as R          # noqa: E402
import slider_crank_testset as TS           # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
H = 5e-6


def ld(name, n, case, h=H, dt_out=1e-3):
    t, o, e, info = R.load(name, n, case, h, 0.1, dt_out)
    return t, o


def peaks(t, w):
    """Extremes of a finely sampled signal with parabolic refinement."""
    res = {}
    for lab, sgn in (('max', 1), ('min', -1)):
        k = int(np.argmax(sgn * w))
        k = min(max(k, 1), len(t) - 2)
        y0, y1, y2 = w[k - 1], w[k], w[k + 1]
        den = y0 - 2 * y1 + y2
        d = 0.5 * (y0 - y2) / den if den != 0 else 0.0
        dt = t[1] - t[0]
        res[lab] = (t[k] + d * dt, y1 - 0.25 * (y0 - y2) * d)
    return res


def conv_table(case):
    ref_t, ref = ld('ancf', 128, case)
    print(f"\n#### Case {case}: mesh and step convergence (max over the 101 output times of |difference| "
          f"from ANCF 128 elements, h = 5e-6 s)\n")
    print("| model | elements | h [s] | max abs diff w_mid [m] | max abs diff x_B [m] | max abs diff v_B [m/s] | w_mid(0.1 s) [m] | x_B(0.1 s) [m] |")
    print("|---|---|---|---|---|---|---|---|")
    rows = [('ancf', n, H) for n in (8, 16, 32, 64)] + [('ancf', 64, 1e-5), ('ancf', 64, 2.5e-6), ('ancf', 128, H)]
    rows += [('reissner_eb', 32, H), ('reissner_eb', 64, H)]
    rows += [('reissner', n, H) for n in (16, 32, 64)]
    rows += [('reissner_rigidshear', 32, H), ('reissner_norot', 32, H)]
    for name, n, h in rows:
        try:
            t, o = ld(name, n, case, h)
        except FileNotFoundError:
            continue
        d = np.abs(o - ref).max(axis=0)
        print(f"| {name} | {n} | {h:g} | {d[2]:.2e} | {d[0]:.2e} | {d[1]:.2e} | {o[-1, 2]:.10e} | {o[-1, 0]:.12f} |")
    # Reissner fine mesh against Reissner 64
    try:
        tr, orr = ld('reissner', 128, case, H, 5e-5)
        t6, o6 = ld('reissner', 64, case)
        d = np.abs(orr[::20] - o6).max(axis=0)
        print(f"\nReissner 128 vs Reissner 64 elements: max abs diff w_mid {d[2]:.2e} m, x_B {d[0]:.2e} m, v_B {d[1]:.2e} m/s")
        t2, o2 = ld('reissner', 64, case, 2.5e-6)
        d = np.abs(o2 - o6).max(axis=0)
        print(f"Reissner 64 elements, h 2.5e-6 vs 5e-6: max abs diff w_mid {d[2]:.2e} m, x_B {d[0]:.2e} m, v_B {d[1]:.2e} m/s")
    except FileNotFoundError:
        pass


def write_csv(case, fname):
    t, o = ld('ancf', 128, case, H, 5e-5)
    tr, orr = ld('reissner', 128, case, H, 5e-5)
    assert np.allclose(t, tr)
    sel = np.arange(0, len(t), 20)           # every 1 ms
    hdr = ("time,crank_angle,slider_x,slider_dx_elastic,slider_vx,rod_mid_deflection,"
           "slider_x_timoshenko,rod_mid_deflection_timoshenko")
    lines = [hdr]
    for k in sel:
        tk = t[k]
        lines.append(f"{tk:.4f},{R.OMEGA * tk:.6f},{o[k, 0]:.12f},{o[k, 0] - R.rigid_slider_x(tk):.6e},"
                     f"{o[k, 1]:.6f},{o[k, 2]:.6e},{orr[k, 0]:.12f},{orr[k, 2]:.6e}")
    with open(os.path.join(HERE, fname), "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"\nwrote {fname} ({len(sel)} rows)")


def summary(case):
    print(f"\n#### Case {case}: key values (from 2001 outputs, dt = 5e-5 s, parabolic refinement)\n")
    print("| quantity | Euler-Bernoulli (ANCF 128) | Timoshenko (Reissner 128) |")
    print("|---|---|---|")
    t, o = ld('ancf', 128, case, H, 5e-5)
    tr, orr = ld('reissner', 128, case, H, 5e-5)
    pa, pr = peaks(t, o[:, 2]), peaks(tr, orr[:, 2])
    print(f"| max w_mid [m] at t [s] | {pa['max'][1]:.6e} at {pa['max'][0]:.5f} | {pr['max'][1]:.6e} at {pr['max'][0]:.5f} |")
    print(f"| min w_mid [m] at t [s] | {pa['min'][1]:.6e} at {pa['min'][0]:.5f} | {pr['min'][1]:.6e} at {pr['min'][0]:.5f} |")
    dxa = o[:, 0] - R.rigid_slider_x(t); dxr = orr[:, 0] - R.rigid_slider_x(tr)
    print(f"| max x_B - x_B,rigid [m] | {dxa.max():.4e} | {dxr.max():.4e} |")
    print(f"| min x_B - x_B,rigid [m] | {dxa.min():.4e} | {dxr.min():.4e} |")
    for tt in (0.01, 0.025, 0.05, 0.075, 0.1):
        k = int(round(tt / 5e-5))
        print(f"| t = {tt:g} s: x_B [m], w_mid [m] | {o[k, 0]:.10f}, {o[k, 2]:.6e} | {orr[k, 0]:.10f}, {orr[k, 2]:.6e} |")


def testset_compare():
    print("\n#### Case T: continuum vs the 4-mode Test Set model (crank.f)\n")
    t_out = np.linspace(0, 0.1, 101)
    x3, q1 = TS.history(t_out, rtol=1e-11)
    x3n, q1n = TS.history(t_out, nonlinear=True, rtol=1e-11)
    t, o = ld('ancf', 128, 'T')
    print("| t [s] | w_mid continuum EB | q1 Test Set (ipar 0) | q1 Test Set ipar(1)=1 | x_B continuum | x3 Test Set |")
    print("|---|---|---|---|---|---|")
    for k in (10, 20, 30, 40, 50, 60, 70, 80, 90, 100):
        print(f"| {t_out[k]:.2f} | {o[k, 2]:.4e} | {q1[k]:.4e} | {q1n[k]:.4e} | {o[k, 0]:.9f} | {x3[k]:.9f} |")
    print(f"\nmax |w_mid| continuum {np.abs(o[:, 2]).max():.4e} (1 ms grid); 4-mode ipar 0: {np.abs(q1).max():.4e}; "
          f"ipar 1: {np.abs(q1n).max():.4e}")


if __name__ == "__main__":
    for case in ('T', 'U'):
        conv_table(case)
        summary(case)
    testset_compare()
    write_csv('T', 'slider_crank_reference.csv')
    write_csv('U', 'slider_crank_reference_caseU.csv')
