#!/usr/bin/env python3
"""Where the time of a step goes: the cost model of BENCHMARKS.md.

    cargo bench -p flexmb --bench engine --no-run
    python3 crates/flexmb/benches/cost_model.py [case ...]

Samples each case of the engine bench with `perf record` (Linux perf, cpu-clock) in its own
process and splits the samples by the function they fall in (a flat profile: inlined code
counts where it is inlined):

* assembly: the assembly loop, elements, joints and what they call by name (the beam,
  rigid-body, spring and joint kernels, their primitives, the tangent operator, nalgebra's
  small products; for beams the SE(3) maps of their strains);
* factorization: the LU factorizations (faer's dense LU with its blocked products, the
  sparse and block LUs);
* solves: the triangular solves;
* rest: the step itself (predictor, kinematics and the configuration update, corrections,
  norms, the end of the step), copies and the run's set-up (symbolic analysis, model);
  kernel samples (page clearing at set-up) are left out.

Prints one markdown row per case.
"""
import glob
import os
import re
import subprocess
import sys
import tempfile

CASES = ["heavy_top_r3so3", "chain_100", "chain_1000", "right_angle_cantilever", "beam_1000",
         "springs_500"]

# First match wins.
PHASES = [
    ("factorization", re.compile(r"factoriz|lu_in_place|::lu::|matmul")),
    ("solves", re.compile(r"solve_in_place|solve_impl|triangular_solve|solve_transpose|"
                          r"partial_pivoting::solve")),
    ("assembly", re.compile(r"assembly::|joints::|elements::|physical::|beam|rigid_body|"
                            r"spring|so3::tangent|se3::|nalgebra::")),
]


def bench_binary():
    root = os.path.join(os.path.dirname(__file__), "..", "..", "..", "target", "release", "deps")
    exes = [p for p in glob.glob(os.path.join(root, "engine-*"))
            if os.access(p, os.X_OK) and not p.endswith(".d")]
    if not exes:
        sys.exit("build the bench first: cargo bench -p flexmb --bench engine --no-run")
    return max(exes, key=os.path.getmtime)


def profile(exe, case):
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        subprocess.run(["perf", "record", "-q", "-o", data, exe, case, "--child"],
                       capture_output=True, text=True, check=True)
        report = subprocess.run(["perf", "report", "-i", data, "--no-children", "--stdio",
                                 "--sort", "symbol", "--percent-limit", "0"],
                                capture_output=True, text=True, check=True).stdout
    shares = {name: 0.0 for name, _ in PHASES}
    shares["rest"] = 0.0
    for line in report.splitlines():
        # User-space samples only ("[.]"; the kernel's are page clearing at set-up).
        m = re.match(r"\s+([0-9.]+)%\s+\[\.\]\s+(.*)", line)
        if not m:
            continue
        pct, symbol = float(m.group(1)), m.group(2)
        for name, pattern in PHASES:
            if pattern.search(symbol):
                shares[name] += pct
                break
        else:
            shares["rest"] += pct
    total = sum(shares.values()) or 1.0
    return {k: 100.0 * v / total for k, v in shares.items()}


def main():
    exe = bench_binary()
    cases = sys.argv[1:] or CASES
    print("| case | assembly | factorization | solves | rest |")
    print("|---|---|---|---|---|")
    for case in cases:
        s = profile(exe, case)
        print(f"| {case} | {s['assembly']:.0f} % | {s['factorization']:.0f} % | "
              f"{s['solves']:.0f} % | {s['rest']:.0f} % |")


if __name__ == "__main__":
    main()
