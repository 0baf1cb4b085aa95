"""The load-factor controls on the beam-column of tests/unit/test_implicit_arclength.py (docs/
implicit.md, "Load factor and arc length"): the figures the tests assert, printed.

    python -m studies.beam_column_control [--sweep]

1. Displacement control of the elastic column's top particle, 10 mm a step, with and without
   the axial load N = 30 MN/m: the secant stiffnesses' ratio against the second-order
   beam-column's (pmpm.benchmarks.implicit_static.beam_column_drift), and N = 0 against
   Timoshenko's drift.
2. Arc length on the elastic-perfectly-plastic column with N (first lambda 0.5, 40 steps, stopped
   past 0.25 m): the peak, the second-order first yield and Mp(N) / (arm - 2 h) beside it, the
   last lambda, the largest difference from displacement control's path at the same drift, and
   the descending branch's slope against -N / arm.
3. ``--sweep``: arc length with other first increments and step counts (which pass, which stop).

Prints the figures and a final JSON line.
"""
import argparse
import json

import numpy as np

import pmpm
from pmpm.benchmarks.implicit_static import (COLUMN_AXIAL_ARM, COLUMN_LATERAL_ARM, beam_column_drift,
                                             column_load_factor_scene, column_plastic_moment)
from pmpm.errors import UnstableRunError

H, N, h = 1e6, 30e6, 0.1


def run(**kw):
    r = pmpm.run(column_load_factor_scene(h=h, lateral=H, **kw), dataframes=False)
    return -np.asarray(r.reactions["base"]["Rx"])[1:] / H, np.asarray(r.histories["lateral"]["ux"])[1:]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sweep", action="store_true")
    args = ap.parse_args(argv)
    out = {}
    z = COLUMN_LATERAL_ARM + h / 4
    k = {}
    for axial in (0.0, N):
        lam, u = run(control="displacement", steps=2, axial=axial, displacement=0.02, material="linear_elastic")
        k[axial] = H * (lam[1] - lam[0]) / (u[1] - u[0])
    theory = beam_column_drift(H, 0.0, z) / beam_column_drift(H, N, z)
    timoshenko = H / beam_column_drift(H, 0.0, z)
    out.update(ratio=k[N] / k[0.0], ratio_theory=theory, stiffness_N0=k[0.0], timoshenko=timoshenko)
    print(f"1. elastic, displacement control: k(N)/k(0) = {k[N] / k[0.0]:.5f}, beam-column {theory:.5f} "
          f"({100 * (k[N] / k[0.0] / theory - 1):+.2f} %); k(0) = {k[0.0] / 1e6:.3f} MN/m, Timoshenko "
          f"{timoshenko / 1e6:.3f} ({100 * (k[0.0] / timoshenko - 1):+.2f} %)")
    lam, u = run(control="arc_length", steps=40, axial=N, increment=0.5, stop_drift=0.25)
    dlam, du = run(control="displacement", steps=40, axial=N, displacement=0.25)
    a = COLUMN_LATERAL_ARM
    first_yield = (250e6 - N / 0.4) * 0.4 ** 2 / 6 / (a + N * beam_column_drift(1.0, N, COLUMN_AXIAL_ARM))
    upper = column_plastic_moment(N) / (a - 2 * h)
    within = u <= du[-1]
    diff = np.abs(lam[within] / np.interp(u[within], du, dlam) - 1)
    first = beam_column_drift(H * lam[0], N, z)
    peak = int(np.argmax(dlam))
    tail = slice(len(dlam) // 2, None)
    slope = np.polyfit(du[tail], H * dlam[tail], 1)[0]
    out.update(peak=float(lam.max()), first_yield=first_yield / H, upper=upper / H, last=float(lam[-1]),
               steps=len(lam), largest_difference=float(diff.max()), first_step_error=float(u[0] / first - 1),
               descending_slope=float(slope), pdelta_slope=[-N / a, -N / (a - 2 * h)],
               displacement_peak=float(dlam[peak]), displacement_peak_drift=float(du[peak]))
    print(f"2. arc length: {len(lam)} samples, drift {1e3 * u[0]:.2f} ... {1e3 * u[-1]:.2f} mm; first step's drift "
          f"{100 * (u[0] / first - 1):+.2f} % from the beam-column's; peak lambda {lam.max():.4f} (first yield "
          f"{first_yield / H:.4f}, Mp(N)/(arm - 2h) {upper / H:.4f}); last {lam[-1]:.4f}; largest difference "
          f"from displacement control at the same drift {100 * diff.max():.2f} %")
    print(f"   displacement control: peak lambda {dlam[peak]:.4f} at {1e3 * du[peak]:.1f} mm; descending slope "
          f"{slope / 1e6:.2f} MN/m over the second half, -N/arm {-N / a / 1e6:.2f}, -N/(arm - 2h) "
          f"{-N / (a - 2 * h) / 1e6:.2f}")
    if args.sweep:
        out["sweep"] = {}
        for inc, steps in ((0.5, 40), (0.5, 50), (0.4, 40), (0.3, 40), (0.25, 60), (0.1, 100)):
            try:
                lam, u = run(control="arc_length", steps=steps, axial=N, increment=inc, stop_drift=0.25)
                result = f"passed: peak {lam.max():.4f}, last {lam[-1]:.4f} at {1e3 * u[-1]:.1f} mm"
            except UnstableRunError as exc:
                result = f"stopped: {str(exc)[:120]}"
            out["sweep"][f"{inc}/{steps}"] = result
            print(f"3. arc length, first increment {inc}, {steps} steps: {result}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
