"""Figures of the portal frame's pushover (cases/portal_pushover.toml, issue 23, item 2).

Reads a results file of the case (``--results``; run it with ``pmpm cases/portal_pushover.toml``,
about 5 minutes on one rank) and prints: the capacity curve's initial stiffness beside the
plane-stress FE model's P / static drift (tests/verification/frame_fe_model.py, levels 0-2 of
0.2 m elements, Richardson-extrapolated), the first yield and the mechanism (pmpm/results/
capacity.py), the base shear at drifts of 1, 2 and 4 times the first-yield drift, the sway
mechanism's plastic collapse load P_c = (2 Mp,col + 2 Mp,beam (1 + 2 e / L_b)) / h from the
cuts' Mp, and the quasi-static check; then one JSON line. ``--plot PNG`` draws the curve with
P_c.

Run::

    pmpm cases/portal_pushover.toml
    python -m studies.pushover --results portal_pushover_results/portal_pushover.h5 \\
        --plot docs/structural_results_capacity.png
"""
import argparse
import json
import os

import numpy as np

from studies import verification_models

__all__ = ["collapse_load", "fe_stiffness", "main"]



def collapse_load(h5_path):
    """P_c of the sway mechanism from the cuts' Mp and the scene's geometry (N)."""
    import h5py
    from pmpm.results.post import read_tables
    sections = read_tables(h5_path)["sections"]
    with h5py.File(h5_path, "r") as f:
        scene = json.loads(f.attrs["scene"])
    bodies = {b["name"]: b["geometry"] for b in scene["bodies"]}
    col, beam = bodies["left column"], bodies["beam"]
    e, L_b, h = col["depth"] / 2, beam["end"][0] - beam["start"][0], beam["start"][1]
    mp_col = 0.5 * (sections["left_column_base"]["attrs"]["Mp"] + sections["right_column_base"]["attrs"]["Mp"])
    mp_beam = 0.5 * (sections["beam_left_end"]["attrs"]["Mp"] + sections["beam_right_end"]["attrs"]["Mp"])
    return (2 * mp_col + 2 * mp_beam * (1 + 2 * e / L_b)) / h, mp_col, mp_beam


def fe_stiffness():
    """P / static drift of the FE model (levels 0-2 at h0 = 0.2 m, Richardson) and the drifts."""
    fem = verification_models.load("frame_fe_model")
    drifts = [fem.frame_fe(0.2, level).static()[1] for level in (0, 1, 2)]
    return fem.read_scene().load[0] / fem.richardson(drifts)[0], drifts


def main(argv=None):
    from pmpm.results.capacity import capacity_curve, plot_capacity
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", required=True)
    ap.add_argument("--plot")
    ap.add_argument("--hinge-fraction", type=float, help="replace the run's [pushover] hinge_fraction")
    args = ap.parse_args(argv)
    from pmpm.results.capacity import pushover_spec
    spec = dict(pushover_spec(args.results))
    if args.hinge_fraction is not None:
        spec["hinge_fraction"] = args.hinge_fraction
    c = capacity_curve(args.results, spec)
    P_c, mp_col, mp_beam = collapse_load(args.results)
    k_fe, drifts = fe_stiffness()
    out = {"initial_stiffness": c["initial_stiffness"], "fe_stiffness": k_fe,
           "stiffness_ratio": c["initial_stiffness"] / k_fe, "P_c": P_c, "Mp_col": mp_col, "Mp_beam": mp_beam,
           "first_yield": c["first_yield"], "mechanism": c["mechanism"], "peak_base_shear": c["peak_base_shear"],
           "max_kinetic_ratio": c["max_kinetic_ratio"]}
    print(f"initial stiffness {c['initial_stiffness'] / 1e6:.4g} MN/m ({c['elastic_samples']} samples); FE model "
          f"{k_fe / 1e6:.4g} MN/m (drifts {', '.join(f'{d * 1e3:.3f}' for d in drifts)} mm at levels 0-2): "
          f"ratio {out['stiffness_ratio']:.4f}")
    fy, mech = c["first_yield"], c["mechanism"]
    if fy:
        print(f"first yield: {fy['cut']} at {fy['base_shear'] / 1e3:.1f} kN, drift {fy['drift'] * 1e3:.1f} mm "
              f"(t = {fy['t']:.3f} s)")
        for m in (1, 2, 4):
            k = int(np.argmin(np.abs(c["drift"] - m * fy["drift"])))
            out[f"V_at_{m}uy"] = float(c["base_shear"][k])
            print(f"  base shear at {m} x the first-yield drift ({c['drift'][k] * 1e3:.1f} mm): "
                  f"{c['base_shear'][k] / 1e3:.1f} kN = {c['base_shear'][k] / P_c:.3f} P_c")
    if mech:
        print(f"mechanism ({', '.join(mech['hinges'])} at {c['hinge_fraction']:g} Mp): {mech['base_shear'] / 1e3:.1f} kN "
              f"= {mech['base_shear'] / P_c:.3f} P_c, drift {mech['drift'] * 1e3:.1f} mm (t = {mech['t']:.3f} s)")
    print(f"P_c = {P_c / 1e3:.1f} kN (Mp col {mp_col / 1e6:.4f}, beam {mp_beam / 1e6:.4f} MN m); peak base shear "
          f"{c['peak_base_shear'] / 1e3:.1f} kN; kinetic / (strain + plastic) after the first ramp <= "
          f"{c['max_kinetic_ratio']:.3g}, after 0.1 s <= {np.max(c['kinetic_ratio'][c['t'] >= 0.1]):.3g}")
    if args.plot:
        plot_capacity(c, args.plot, "cases/portal_pushover.toml",
                      extra=[(f"P_c = {P_c / 1e3:.0f} kN (virtual work, the cuts' Mp)", P_c)])
    print(json.dumps(out))


if __name__ == "__main__":
    main()
