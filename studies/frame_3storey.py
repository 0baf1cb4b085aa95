"""The three-storey frame (cases/frame_3storey.toml) against the independent frame model (issue 22, item 5).

Each cell size runs the case's ``elastic`` variant (the step lateral load 200 / 400 / 600 kN at the
left joints of floors 2, 3 and the roof, no damping) in-process, on as many ranks as the study was
started on, and samples the horizontal displacement of the three left joints. The independent
model is tests/verification/frame2d_model.py (Timoshenko beam-columns, the columns running through
the joints and the beams' end sections tied to the column faces between the beam flanges; it reads
the same scene file and shares no code with pmpm) and its undamped step response by modal
superposition, exact in time. Reported per cell size:

- the first period, from a least-squares fit of the three joint histories by the undamped step
  response's own form, u_k(t) = sum_i c_ki (1 - cos w_i t) with three frequencies shared by the
  joints (started from the frame model's), over the whole record (the fit's residual is kept, and
  the same fit of the frame model's own record shows what the estimator makes of the window);
- the second period, from a second run (``--t-mode2``, 0.6 s: two of its periods) whose step
  loads at the three joints are orthogonal to the frame model's modes 1 and 3 there
  (``mode_pattern``): its record is nearly one cosine of mode 2. The case's own pattern puts 98%
  of the roof's static drift in mode 1 and 0.4% in mode 2, and a fit of its record leaves T2
  undetermined (0.95 to 1.10 of the frame model's with the window's length at 0.2 m cells);
- the roof's first peak (the largest drift before 0.7 T1) and its largest drift over the record,
  each against the frame model's over the same window;
- the RMS gap of each joint's whole history to the frame model's, relative to the model's largest
  drift of that joint (floors 2, 3, roof);
- the energy balance: the largest |external work - kinetic - strain energy| over the record
  relative to the largest external work (the solver's ``numerical_loss``; losses and gains both
  count, the elastic undamped scene conserves energy);
- particles, steps and wall time.

Then a Markdown table and one JSON line (also written to ``--out``). ``--histories FILE.npz`` keeps
the records, ``--plot PNG`` draws them with the frame model's (joint drifts and storey drifts).

The grid of the case (x in [-0.6, 19.0], y in [0, 12.8]) is tiled by 0.2, 0.1 and 0.05 m cells.
Particles per cell (``--ppc``, default 3) stay the same at every cell size: at 0.2 m the W14 columns
(0.42 m deep) are two cells deep, and 2 x 2 particles per cell would leave four rows, too few to
carry the section's area and inertia (the front end refuses it).

Run::

    python -m studies.frame_3storey --cells 0.2 --t-end 1.5 --plot /tmp/f3.png
    # the finer grids on two ranks (0.1 m: 48,000 particles at 3 x 3; 0.05 m: 190,000, hours here)
    mpirun -n 2 python -m studies.frame_3storey --cells 0.1 --out /tmp/f3_01.json
"""
import argparse
import dataclasses
import json
import os
import sys
import time

import numpy as np

from studies import verification_models

__all__ = ["frame_model", "continuum_reference", "mode_pattern", "with_joint_forces", "scene_at", "run_cell", "fit_periods", "compare",
           "compare_mode", "main"]

_ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
CASE = os.path.join(_ROOT, "cases", "frame_3storey.toml")
#: the tracked left joints of floors 2, 3 and the roof (frame node names)
JOINTS = ("c0_f1", "c0_f2", "c0_f3")
STOREY_HEIGHT = 3.96
#: the first peak is the largest drift before this fraction of the frame model's T1 (its first
#: peak is at 0.46 T1; the next maximum of the roof comes after 1.2 T1)
FIRST_PEAK_WINDOW = 0.7


def frame_model(scene=CASE):
    """The independent frame model of ``scene`` (tests/verification/frame2d_model.py)."""
    return verification_models.load("frame2d_model").from_scene(scene, variant="elastic")


def continuum_reference(levels=(0, 1, 2), h0=0.2, scene=CASE):
    """The plane-stress continuum of the same strips (tests/verification/frame3_fe_model.py,
    scikit-fem): its first three periods extrapolated from ``levels`` (Richardson), and the
    roof's first peak under the case's step loads on the finest mesh (about a minute)."""
    f3 = verification_models.load("frame3_fe_model")
    fem = verification_models.load("frame_fe_model")
    data = f3.read_scene3(scene)
    periods = []
    for level in levels:
        fe = f3.Frame3FE(data, h0, level)
        periods.append(fe.periods(3))
    periods = np.array(periods)
    rich = [fem.richardson(periods[:, k]) for k in range(3)]
    t = np.arange(0.0, 1.5, 5e-4)
    u = f3.responses(fe, t)[0]
    first = t <= FIRST_PEAK_WINDOW * rich[0][0]
    return {"periods": [float(v) for v, _, _ in rich], "order": [float(p) for _, p, _ in rich],
            "error": [float(e) for _, _, e in rich], "roof_first_peak": float(u[-1][first].max()),
            "levels": list(levels), "h0": h0}


def mode_pattern(model, mode, peak=6e5):
    """Horizontal forces (N) at the three left joints that excite none of the first three modes
    but ``mode`` (0-based) in the frame model: the direction orthogonal to the other two modes'
    shapes at those joints, scaled so the largest force is ``peak``. A step load in this pattern
    makes the record a single cosine of that mode (plus a trace of the higher modes), so its period
    is well determined from two of its periods (the case's own pattern puts 0.4% of the roof's
    static drift in mode 2)."""
    _, phi, *_ = model.modes(3)
    shapes = phi[[model.node_dofs[n][0] for n in JOINTS], :]
    others = np.delete(shapes, mode, axis=1).T          # 2 x 3
    f = np.linalg.svd(others)[2][-1]                     # their null space
    f = f * np.sign(f @ shapes[:, mode]) * np.sign(shapes[2, mode])   # the roof moves in +x
    return peak * f / np.abs(f).max()


def with_joint_forces(model, forces):
    """A copy of the frame model loaded by ``forces`` at the left joints instead of the case's."""
    import copy
    m = copy.copy(model)
    m.F = np.zeros_like(model.F)
    for n, f in zip(JOINTS, forces):
        m.add_nodal_force(n, (f, 0.0))     # shared over the joint as the model shares a nodal load
    return m


def scene_at(h, ppc=3, variant="elastic", scene=CASE, joint_forces=None):
    """The case's ``variant`` on cells of ``h`` over the case's own domain, ``ppc`` x ``ppc``
    particles per cell; ``joint_forces``: horizontal step forces at the left joints (floors 2, 3,
    roof) in place of the case's."""
    from pmpm.scene.config import apply_overrides, parse_scene, read_toml
    data = read_toml(scene)
    data = apply_overrides(data, data["variants"][variant], f"variants.{variant}")
    if joint_forces is not None:
        for load in data["frame"]["loads"]:
            load["force"] = [float(joint_forces[JOINTS.index(load["node"])]), 0.0]
    grid = data["grid"]
    extent = [grid["cell_size"] * n for n in grid["cells"]]
    cells = [int(round(e / h)) for e in extent]
    if any(abs(n * h - e) > 1e-9 for n, e in zip(cells, extent)):
        raise ValueError(f"cells of {h} m do not tile the case's domain {extent}")
    data["grid"] = dict(grid, cell_size=float(h), cells=cells)
    data["particles_per_cell"] = int(ppc)
    return dataclasses.replace(parse_scene(data, scene), variant=variant)


def run_cell(h, ppc=3, t_end=1.5, every=10, comm=None, progress=True, joint_forces=None):
    """Run the elastic variant at cell size ``h`` to ``t_end`` (the case's loads, or
    ``joint_forces``); sample the joints' ux and the energies every ``every`` steps."""
    from mpi4py import MPI

    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    comm = comm or MPI.COMM_WORLD
    scene = scene_at(h, ppc, joint_forces=joint_forces)
    s = build_solver(scene, comm)
    tracker = Tracker([t for t in scene.output.track if t.name in JOINTS], s)
    order = [[t.name for t in scene.output.track if t.name in JOINTS].index(n) for n in JOINTS]
    particles = comm.allreduce(len(s.particles["x"]))
    t, u, loss, work = [0.0], [np.zeros(3)], [0.0], [0.0]
    start = time.perf_counter()
    shown = 0.0
    while s.t < t_end:
        s.step()
        if s.step_count % every == 0 or s.t >= t_end:   # and the end itself
            e = s.energies()
            t.append(s.t)
            u.append(tracker.sample()[order, 0].copy())
            loss.append(e["numerical_loss"])
            work.append(e["external_work"])
            if progress and comm.rank == 0 and s.t >= shown:
                el = time.perf_counter() - start
                print(f"\r  {h} m: t = {s.t:.3f} / {t_end} s, {s.step_count} steps, {el:.0f} s",
                      end="", file=sys.stderr, flush=True)
                shown += t_end / 50
    wall = time.perf_counter() - start
    if progress and comm.rank == 0:
        print(file=sys.stderr)
    return {"h": h, "ppc": ppc, "t": np.array(t), "u": np.array(u), "loss": np.array(loss),
            "external_work": np.array(work), "particles": particles, "steps": s.step_count,
            "wall": wall, "ranks": comm.size, "joint_forces": joint_forces}


def fit_periods(t, u, periods):
    """Periods of a least-squares fit of the joints' records ``u`` (n x joints) by
    sum_i c_ki (1 - cos w_i t), frequencies shared, started from ``periods``; and the fit's RMS
    residual relative to the largest |u|."""
    from scipy.optimize import least_squares

    def basis(w):
        return 1.0 - np.cos(np.outer(t, w))

    def residual(w):
        b = basis(w)
        c, *_ = np.linalg.lstsq(b, u, rcond=None)
        return (b @ c - u).ravel()

    sol = least_squares(residual, 2 * np.pi / np.asarray(periods, float))
    rms = np.sqrt(np.mean(residual(sol.x) ** 2)) / np.abs(u).max()
    return 2 * np.pi / sol.x, rms


def compare(run, model):
    """The case-pattern run's figures against the frame model's (see the module's docstring)."""
    t, u = run["t"], run["u"]
    periods = model.modes(3)[0]
    fitted, residual = fit_periods(t, u, periods)
    ref = np.array([model.step_response(t, model.node_dofs[n][0]) for n in JOINTS]).T
    first = t <= FIRST_PEAK_WINDOW * periods[0]
    out = {"h": run["h"], "ppc": run["ppc"], "particles": run["particles"], "steps": run["steps"],
           "wall_s": round(run["wall"], 1), "ranks": run["ranks"], "t_end": float(t[-1]),
           "periods": [float(p) for p in fitted], "frame_periods": [float(p) for p in periods],
           "period_ratios": [float(a / b) for a, b in zip(fitted, periods)], "fit_residual": float(residual),
           # the same estimator on the frame model's own record: how well the fit can recover
           # the eigenperiods from this window at all
           "frame_fit_ratios": [float(a / b) for a, b in zip(fit_periods(t, ref, periods)[0], periods)],
           "roof_first_peak": float(u[first, 2].max()), "frame_roof_first_peak": float(ref[first, 2].max()),
           "roof_peak": float(u[:, 2].max()), "frame_roof_peak": float(ref[:, 2].max()),
           "rms_gap": [float(np.sqrt(np.mean((u[:, k] - ref[:, k]) ** 2)) / np.abs(ref[:, k]).max())
                       for k in range(3)],
           "energy_gap": energy_gap(run)}
    out["roof_first_peak_ratio"] = out["roof_first_peak"] / out["frame_roof_first_peak"]
    out["roof_peak_ratio"] = out["roof_peak"] / out["frame_roof_peak"]
    return out


def compare_mode(run, model, mode):
    """The period of ``mode`` (0-based) from a run loaded in ``mode_pattern(model, mode)``: a fit
    of the joints' records by one shared frequency, c_k (1 - cos w t); the same fit of the frame
    model's response to the same loads shows what the estimator itself makes of the window."""
    t, u = run["t"], run["u"]
    period = model.modes(3)[0][mode]
    loaded = with_joint_forces(model, run["joint_forces"])
    ref = np.array([loaded.step_response(t, model.node_dofs[n][0]) for n in JOINTS]).T
    fitted, residual = fit_periods(t, u, [period])
    own, own_residual = fit_periods(t, ref, [period])
    return {"mode": mode + 1, "h": run["h"], "ppc": run["ppc"], "steps": run["steps"],
            "wall_s": round(run["wall"], 1), "t_end": float(t[-1]),
            "joint_forces": [float(f) for f in run["joint_forces"]], "period": float(fitted[0]),
            "frame_period": float(period), "period_ratio": float(fitted[0] / period),
            "fit_residual": float(residual), "frame_fit_ratio": float(own[0] / period),
            "frame_fit_residual": float(own_residual), "energy_gap": energy_gap(run)}


def energy_gap(run):
    """The largest |numerical loss| over the record relative to the largest external work."""
    return float(np.abs(run["loss"]).max() / max(np.abs(run["external_work"]).max(), 1e-300))


def markdown_table(rows):
    """One row per cell size: the case-pattern run's figures and T2 from the mode-2 run."""
    lines = ["| cells (m) | ppc | particles | steps to t_end | wall (s), case + mode-2 runs | ranks | T1 / frame "
             "| T2 / frame (mode-2 run) | roof first peak / frame | roof peak / frame "
             "| RMS gap floors 2, 3, roof | energy gap | T1, T2, first peak / continuum |",
             "|" + "---:|" * 13]
    for r in rows:
        m2 = r.get("mode2")
        wall = f"{r['wall_s']:.0f}" + (f" + {m2['wall_s']:.0f}" if m2 else "")
        lines.append(f"| {r['h']} | {r['ppc']} x {r['ppc']} | {r['particles']:,} | {r['steps']:,} | {wall} | {r['ranks']} "
                     f"| {r['period_ratios'][0]:.3f} | " + (f"{m2['period_ratio']:.3f}" if m2 else "not run")
                     + f" | {r['roof_first_peak_ratio']:.3f} | {r['roof_peak_ratio']:.3f} | "
                     + " / ".join(f"{100 * g:.1f}%" for g in r["rms_gap"])
                     + f" | {100 * max(r['energy_gap'], m2['energy_gap'] if m2 else 0):.2f}% | "
                     + (" / ".join(f"{x:.3f}" if x == x else "-" for x in r["continuum_ratios"])
                        if "continuum_ratios" in r else "not run") + " |")
    return "\n".join(lines)


def plot(runs, model, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5), sharex=True)
    t_ref = np.linspace(0.0, max(r["t"][-1] for r in runs), 2000)
    ref = np.array([model.step_response(t_ref, model.node_dofs[n][0]) for n in JOINTS]).T
    labels = ("floor 2", "floor 3", "roof")
    for k in range(3):
        a.plot(t_ref, 1e3 * ref[:, k], "k-", lw=1.0, label="frame model" if k == 0 else None)
        storey = ref[:, k] - (ref[:, k - 1] if k else 0.0)
        b.plot(t_ref, 100 * storey / STOREY_HEIGHT, "k-", lw=1.0, label="frame model" if k == 0 else None)
    for r in runs:
        for k in range(3):
            a.plot(r["t"], 1e3 * r["u"][:, k], "--", lw=1.0, label=f"MPM {r['h']} m, {labels[k]}")
            storey = r["u"][:, k] - (r["u"][:, k - 1] if k else 0.0)
            b.plot(r["t"], 100 * storey / STOREY_HEIGHT, "--", lw=1.0, label=f"MPM {r['h']} m, storey {k + 1}")
    a.set(xlabel="t (s)", ylabel="joint drift ux (mm)", title="Left joints under the step lateral load")
    b.set(xlabel="t (s)", ylabel="storey drift ratio (%)", title="Storey drifts")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None):
    from mpi4py import MPI
    ap = argparse.ArgumentParser(prog="python -m studies.frame_3storey",
                                 description="The three-storey frame against the independent frame model.")
    ap.add_argument("--cells", type=float, nargs="+", default=[0.2], help="cell sizes (m)")
    ap.add_argument("--ppc", type=int, default=3, help="particles per cell along each axis (all cell sizes)")
    ap.add_argument("--t-end", type=float, default=1.5, help="end of each run (s); T1 is about 0.94 s")
    ap.add_argument("--t-mode2", type=float, default=0.6,
                    help="end of the run loaded in the mode-2 pattern, for T2 (s; 0: not run)")
    ap.add_argument("--every", type=int, default=10, help="sample every this many steps")
    ap.add_argument("--no-continuum", action="store_true",
                    help="skip the plane-stress continuum of the same strips (scikit-fem, about a minute)")
    ap.add_argument("--out", help="write the JSON summary here")
    ap.add_argument("--histories", help="write the records here (.npz)")
    ap.add_argument("--plot", help="draw the joint and storey drifts here (.png)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    model = frame_model()
    runs, rows = [], []
    for h in args.cells:
        run = run_cell(h, args.ppc, args.t_end, args.every, comm)
        runs.append(run)
        rows.append(compare(run, model))
        if args.t_mode2 > 0:
            mode2 = run_cell(h, args.ppc, args.t_mode2, args.every, comm, joint_forces=mode_pattern(model, 1))
            rows[-1]["mode2"] = compare_mode(mode2, model, 1)
    if comm.rank:
        return 0
    continuum = None if args.no_continuum else continuum_reference()
    if continuum:
        for r in rows:
            m2 = r.get("mode2")
            r["continuum_ratios"] = [r["periods"][0] / continuum["periods"][0],
                                     m2["period"] / continuum["periods"][1] if m2 else float("nan"),
                                     r["roof_first_peak"] / continuum["roof_first_peak"]]
        print("continuum of the same strips (frame3_fe_model, Richardson over levels 0-2): T = "
              + ", ".join(f"{v:.4f}" for v in continuum["periods"])
              + f" s, roof first peak {continuum['roof_first_peak']:.4f} m")
    print(markdown_table(rows))
    if args.histories:
        np.savez(args.histories, **{f"{k}_{r['h']}": r[k] for r in runs for k in ("t", "u", "loss", "external_work")})
    if args.plot:
        plot(runs, model, args.plot)
    summary = {"study": "frame_3storey", "rows": rows, "continuum": continuum}
    line = json.dumps(summary)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(line + "\n")
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
