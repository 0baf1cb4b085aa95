"""Refinement study of the portal frame's plane-stress finite-element model (issue 11, item 1).

The model is tests/verification/frame_fe_model.py (scikit-fem, 9-node quadrilaterals, the same
strips, supports and load as cases/portal_frame.toml; it imports nothing from pmpm's solver). On
nested meshes (every element edge halved per level) it prints the static drift of the upper-left
joint under the step load's force, the lateral stiffness P / drift, the first two eigenperiods
(consistent mass), and the first peak of the undamped step response with its time
(mode-acceleration superposition of ``--modes`` modes), then the Richardson extrapolation of the
last three levels with the observed order and the estimated error of the finest level, and the
convergence of the peak in the number of modes at the finest level; last, one JSON line.

Run::

    python -m studies.frame_fe --h0 0.2 --levels 0 1 2 3 --modes 40

Level 3 at h0 = 0.2 (0.025 m elements, about 150k unknowns) takes a few minutes on this machine;
levels 0-2 take seconds. Nothing is written.
"""
import argparse
import json
import os
import sys

import numpy as np

from studies import verification_models

__all__ = ["fe_module", "study", "markdown_table", "fit_history", "main"]



def fe_module():
    """tests/verification/frame_fe_model.py (needs scikit-fem and scipy)."""
    return verification_models.load("frame_fe_model")


def study(h0=0.2, levels=(0, 1, 2), n_modes=40, mode_counts=(5, 10, 20, 40, 80)):
    """The refinement table, Richardson estimates and the peak's convergence in modes."""
    fe = fe_module()
    res = fe.refinement_study(levels, h0, n_modes)
    finest = fe.frame_fe(h0, levels[-1])
    res["modes"] = [dict(zip(("modes", "peak", "t_peak"), (n, *fe.first_peak(finest, n))))
                    for n in mode_counts]
    res["settings"] = {"h0": h0, "levels": list(levels), "n_modes": n_modes,
                       "mass_kg": finest.total_mass(), "load_mass_kg": finest.load_volume * finest.data.rho}
    return res


def fit_history(t, u, omegas):
    """Least-squares fit of a step-response record u(t) by
    u_s - a_1 exp(-zeta w_1 t) cos(w_1 t) - sum_k a_k cos(w_k t) (w_1, zeta, the a's and the w_k free,
    started from ``omegas``: the FE's first mode and the higher modes that show in ux).

    Returns
    -------
    dict
        static (m), a1 (m), f1 (Hz), zeta, and per higher mode (f Hz, a m).
    """
    from scipy.optimize import least_squares

    def model(p):
        us, a1, w1, z = p[:4]
        out = us - a1 * np.exp(-z * w1 * t) * np.cos(w1 * t)
        for a, w in zip(p[4::2], p[5::2]):
            out = out - a * np.cos(w * t)
        return out

    p0 = [u.mean(), u.mean(), omegas[0], 0.0]
    for w in omegas[1:]:
        p0 += [0.0, w]
    p = least_squares(lambda q: model(q) - u, p0, x_scale="jac").x
    return {"static": p[0], "a1": p[1], "f1": p[2] / (2 * np.pi), "zeta": p[3],
            "higher": [(w / (2 * np.pi), a) for a, w in zip(p[4::2], p[5::2])],
            "rms_residual": float(np.std(model(p) - u))}


def markdown_table(res):
    """Markdown tables of :func:`study`'s result."""
    lines = ["| element edge (m) | elements | unknowns | static drift (mm) | k (MN/m) | T1 (ms) | T2 (ms) "
             "| first peak (mm) | at (s) | estimator period (ms) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['h']:.4g} | {r['elements']} | {r['dofs']} | {r['drift'] * 1e3:.4f} | {r['k'] / 1e6:.4f} "
                     f"| {r['T1'] * 1e3:.4f} | {r['T2'] * 1e3:.4f} | {r['peak'] * 1e3:.4f} | {r['t_peak']:.5f} "
                     f"| {r['period_est'] * 1e3:.4f} |")
    rich = res["richardson"]
    scale = {"drift": 1e3, "k": 1e-6, "T1": 1e3, "T2": 1e3, "peak": 1e3, "t_peak": 1.0, "period_est": 1e3}
    for name, pick in (("Richardson", "value"), ("observed order", "order"), ("error of the finest", "error")):
        cells = []
        for q in ("drift", "k", "T1", "T2", "peak", "t_peak", "period_est"):
            v = rich[q][pick]
            cells.append(f"{v:.2f}" if pick == "order" else f"{v * scale[q]:.4g}")
        lines.append(f"| {name} | | | " + " | ".join(cells) + " |")
    lines += ["", "| modes in the dynamic part | first peak (mm) | at (s) |", "|---|---|---|"]
    lines += [f"| {m['modes']} | {m['peak'] * 1e3:.4f} | {m['t_peak']:.5f} |" for m in res["modes"]]
    return "\n".join(lines)


def compare_records(paths, h0, level, n_modes):
    """The estimator and the fit on each MPM record, and on the FE record sampled like the first."""
    fe = fe_module()
    model = fe.frame_fe(h0, level)
    omega = model.modes(n_modes)[0]
    out = {}
    for path in paths:
        rec = np.load(path)
        t, u = rec["t"], rec["ux"]
        out[os.path.basename(path)] = _analyse(fe, t, u, omega)
        if "FE" not in out:
            out["FE"] = _analyse(fe, t, fe.step_response(model, t, n_modes), omega)
    return out


def _analyse(fe, t, u, omega):
    peak, t_peak, period = fe.peak_and_period(t, u)
    return {"peak": peak, "t_peak": t_peak, "period": period,
            "fit": fit_history(t, u, [omega[0], omega[3], omega[5]])}


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.frame_fe",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--h0", type=float, default=0.2, help="largest element edge at level 0 (m)")
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2], help="refinement levels (nested)")
    ap.add_argument("--modes", type=int, default=40, help="modes in the step response's dynamic part")
    ap.add_argument("--mode-counts", type=int, nargs="+", default=[5, 10, 20, 40, 80],
                    help="mode counts for the peak's convergence in modes at the finest level")
    ap.add_argument("--mpm-history", nargs="+", default=[], metavar="NPZ",
                    help="also analyse MPM records (npz with t, ux) and the FE record of the finest level the "
                         "same way: the tests' estimator and fit_history")
    args = ap.parse_args(argv)
    if len(args.levels) < 3:
        ap.error("Richardson extrapolation needs three levels")
    res = study(args.h0, tuple(args.levels), args.modes, tuple(args.mode_counts))
    print(markdown_table(res))
    if args.mpm_history:
        res["records"] = compare_records(args.mpm_history, args.h0, args.levels[-1], args.modes)
        print()
        for name, r in res["records"].items():
            hi = ", ".join(f"{f:.1f} Hz {a * 1e3:.3f} mm" for f, a in r["fit"]["higher"])
            print(f"- {name}: first peak {r['peak'] * 1e3:.3f} mm at {r['t_peak']:.5f} s, period (estimator) "
                  f"{r['period'] * 1e3:.3f} ms; fit: static {r['fit']['static'] * 1e3:.3f} mm, first mode "
                  f"{r['fit']['a1'] * 1e3:.3f} mm at {r['fit']['f1']:.3f} Hz, zeta {r['fit']['zeta']:.5f}; {hi}; "
                  f"rms residual {r['fit']['rms_residual'] * 1e3:.3f} mm")
    print(json.dumps(res, separators=(",", ":"), default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
