"""The whole response: what each setting loses over the elastic portal frame's record.

``pmpm bench accuracy --response`` (or ``python -m studies.accuracy_response``) runs the
elastic variant of cases/portal_frame.toml (undamped, step load) to ``t_end`` (0.25 s, six sway
cycles) for each setting -- cell size, shape function, scheme, CFL number, transfer (FLIP,
APIC, XPIC(m)) -- and compares it with the repository's continuum finite-element model
(tests/verification/frame_fe_model.py via studies.frame_fe: scikit-fem, 9-node
quadrilaterals, the same strips, supports and load, modal step response; nothing of pmpm's
solver), read at the very particle the run's tracker follows (the FE probe moves with the
cell size, ``mpm_track_point``). Reported per setting:

* **peaks**: the largest ux of the upper-left joint in each sway cycle (windows of the FE's
  first period from t = 0), each against the FE's peak of the same cycle (%), and the worst;
* **period**: the mean spacing of the upward crossings of the record's mean, against the FE's
  same estimator (%);
* **numerical damping**: the energy lost (the run's ``numerical_loss``, pmpm.core.solver) as an
  equivalent viscous damping ratio: an oscillator under a step load F, with viscous damping
  zeta, keeps e^(-4 pi zeta n) of its sway energy E_osc = F u_static / 2 after n cycles, so
  zeta = -ln(1 - loss / E_osc) / (4 pi n), E_osc taken as half the load's mean work over the
  record's whole cycles; and the energy lost over the record as a fraction of the energy in
  play, the mean of kinetic plus strain energy over the record, F u_static = 2 E_osc (the main
  job's 0.3% limit);
* **cost**: the wall (and CPU) time of ``solver.step()`` alone on one core, after a warm-up that
  compiles the kernels.

The table goes to ``response.md`` and ``response.csv``, the plot of numerical damping against cost
to ``response.png`` (against CPU time; in ``--outdir``); the last line printed is one JSON object.
``--quick`` (the CI test's budget): 0.1 m cells with 3 x 3 particles, 0.05 s (one cycle and a
quarter), FLIP, APIC and XPIC(2), against the FE at its coarse level. Results and advice:
docs/accuracy.md, "The whole response".
"""
import argparse
import csv
import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

__all__ = ["Setting", "FULL", "QUICK", "fe_reference", "run_setting", "analyse", "study", "main"]

T_END = 0.25
SAMPLE = 1e-4            # s between samples of the joint (the case's history interval)
FE_H0, FE_LEVEL, FE_MODES = 0.2, 2, 40     # the FE mesh of docs/portal_frame.md section 8
TRACK = "upper_left_joint"


@dataclasses.dataclass(frozen=True)
class Setting:
    """One run of the study: the frame's numerical settings (the rest is the case's)."""
    cell: float = 0.05
    shape: str = "cubic"
    scheme: str = "musl"
    cfl: float = 0.9
    transfer: str = "flip"
    xpic_order: int = 2
    ppc: int = 2
    time_step: float = 0.0      # > 0: the implicit integrator (Newmark, docs/implicit.md) at this step
    edge_mass_ratio: float = 0.0   # implicit: [solver.implicit] edge_mass_ratio (pmpm.core.implicit.edges)

    @property
    def label(self):
        if self.time_step > 0:
            return (f"{self.cell:g} m {self.shape} {self.ppc}x{self.ppc} implicit dt = T1/"
                    f"{FE_PERIOD_NOMINAL / self.time_step:.0f} ({1e3 * self.time_step:.3g} ms)"
                    + (f" edge_mass_ratio {self.edge_mass_ratio:g}" if self.edge_mass_ratio else ""))
        t = f"xpic({self.xpic_order})" if self.transfer == "xpic" else self.transfer
        if self.scheme == "mls":   # the scheme brings its affine transfer (pmpm.core.mls)
            t = "affine"
        return f"{self.cell:g} m {self.shape} {self.ppc}x{self.ppc} {self.scheme.upper()} CFL {self.cfl:g} {t.upper()}"


#: the continuum model's first period (docs/portal_frame.md section 8, Richardson: 40.04 ms), the
#: unit of the implicit rows' time steps (T1/20 ... T1/400, issue 37)
FE_PERIOD_NOMINAL = 0.04004
BASE = Setting()
#: the full study: the main job's setting and one change at a time, plus the finer grids
FULL = (BASE, dataclasses.replace(BASE, cfl=0.5), dataclasses.replace(BASE, cfl=1.0),
        dataclasses.replace(BASE, scheme="usl"), dataclasses.replace(BASE, scheme="usf"),
        dataclasses.replace(BASE, shape="quadratic"), dataclasses.replace(BASE, transfer="apic"),
        dataclasses.replace(BASE, transfer="xpic", xpic_order=2), dataclasses.replace(BASE, ppc=3),
        dataclasses.replace(BASE, cell=1 / 30), dataclasses.replace(BASE, cell=0.025),
        dataclasses.replace(BASE, cell=0.025, shape="quadratic", cfl=1.0),
        dataclasses.replace(BASE, scheme="mls"), dataclasses.replace(BASE, scheme="mls", shape="quadratic"))
QUICK_CELL = 0.1
QUICK = (dataclasses.replace(BASE, cell=QUICK_CELL, ppc=3), dataclasses.replace(BASE, cell=QUICK_CELL, ppc=3, transfer="apic"),
         dataclasses.replace(BASE, cell=QUICK_CELL, ppc=3, transfer="xpic"),
         dataclasses.replace(BASE, cell=QUICK_CELL, ppc=3, scheme="mls"))
QUICK_T_END, QUICK_FE_LEVEL = 0.05, 1
#: ``--implicit``: the main job's explicit setting, then the implicit integrator at T1/20 ...
#: T1/400 on the same grid (issue 37), for the cost side by side
IMPLICIT_DIVISIONS = (20, 40, 100, 200, 400)
IMPLICIT = (BASE,) + tuple(dataclasses.replace(BASE, time_step=FE_PERIOD_NOMINAL / n) for n in IMPLICIT_DIVISIONS) \
    + tuple(dataclasses.replace(BASE, ppc=3, time_step=FE_PERIOD_NOMINAL / n) for n in (20, 40))   # docs/implicit.md


# -- the reference ---------------------------------------------------------------------------

def fe_reference(t, cell, ppc, level=FE_LEVEL, h0=FE_H0, n_modes=FE_MODES):
    """The FE step response ux(t) at the particle the MPM tracker follows on a grid of ``cell``
    with ``ppc`` particles per cell, its first period and its static drift there."""
    from studies.frame_fe import fe_module
    fe_m = fe_module()
    fe = fe_m.frame_fe(h0, level)
    data = dataclasses.replace(fe.data, ppc=ppc)
    px, py = fe_m.mpm_track_point(data, cell)
    probe = fe.basis.probes(np.array([[px], [py]]))
    omega, phi = fe.modes(n_modes)
    u_static_all, _ = fe.static()
    q_static = (phi.T @ fe.f) / omega ** 2
    at = (probe @ phi)[0]
    u_static = float((probe @ u_static_all)[0])
    return u_static - (at * q_static) @ np.cos(np.outer(omega, t)), 2 * math.pi / float(omega[0]), u_static


# -- one run ---------------------------------------------------------------------------------

def frame_scene(setting, t_end):
    """The elastic frame with ``setting`` (regridded over the case's domain, no output)."""
    from studies.accuracy import frame_scene as regrid
    scene = regrid(setting.cell, setting.shape, setting.scheme, setting.ppc, t_end, cfl=setting.cfl)
    solver = dataclasses.replace(scene.solver, transfer=setting.transfer, xpic_order=setting.xpic_order)
    scene = dataclasses.replace(scene, solver=solver)
    if setting.time_step <= 0:
        return scene
    scene = implicit_scene(scene, setting.time_step)
    if setting.edge_mass_ratio:
        implicit = dict(scene.solver.implicit, edge_mass_ratio=setting.edge_mass_ratio)
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, implicit=implicit))
    return scene


def implicit_scene(scene, time_step):
    """``scene`` under the implicit integrator at ``time_step``, without the outputs the implicit
    step does not carry yet (section cuts, hysteresis, support reactions: docs/implicit.md); the
    response (the tracked joint) is the same scene's."""
    boundary = tuple(dataclasses.replace(b, reaction=False) for b in scene.boundaries)
    output = dataclasses.replace(scene.output, sections=(), hysteresis=None, checkpoint_interval=None)
    solver = dataclasses.replace(scene.solver, integrator="implicit", scheme="newmark",
                                 time_step=float(time_step))
    return dataclasses.replace(scene, boundaries=boundary, output=output, solver=solver)


def run_setting(setting, t_end=T_END):
    """Run one setting: the joint's ux every SAMPLE, the energies at the end and the cost."""
    from mpi4py import MPI
    from studies.accuracy import _timed_steps
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    scene = frame_scene(setting, t_end)
    s = build_solver(scene, MPI.COMM_SELF)
    tracker = Tracker([tr for tr in scene.output.track if tr.name == TRACK], s)
    t, u, work = [0.0], [0.0], [0.0]
    nxt = [SAMPLE]

    def sample(s):
        if s.t < nxt[0] - 1e-12:
            return
        t.append(s.t)
        u.append(float(tracker.sample()[0, 0]))
        work.append(s.energies()["external_work"])
        while nxt[0] <= s.t + 1e-12:
            nxt[0] += SAMPLE

    status = "ok"
    try:
        wall, cpu = _timed_steps(s, t_end, sample)
    except Exception as exc:   # a diverging setting is a result, not a crash of the study
        return {"setting": setting, "status": f"failed: {exc}"[:120]}
    e = s.energies()
    return {"setting": setting, "status": status, "t": np.array(t), "u": np.array(u), "work": np.array(work),
            "energies": e, "wall_s": wall, "cpu_s": cpu, "steps": int(s.step_count), "particles": int(s.n_total),
            "load": float(scene.loads.forces[0].force[0])}


# -- the analysis ----------------------------------------------------------------------------

def cycle_peaks(t, u, period, n):
    """Largest u in each window [k T, (k + 1) T), k < n, refined by a parabola; NaN for a window
    the record does not cover."""
    out = []
    for k in range(n):
        w = np.nonzero((t >= k * period) & (t < (k + 1) * period))[0]
        if len(w) < 3 or t[-1] < (k + 1) * period - 1e-9:
            out.append(math.nan)
            continue
        i = w[int(np.argmax(u[w]))]
        if 0 < i < len(u) - 1:
            a, b, c = u[i - 1], u[i], u[i + 1]
            den = a - 2 * b + c
            out.append(float(b - 0.125 * (a - c) ** 2 / den) if den < 0 else float(b))
        else:
            out.append(float(u[i]))
    return np.array(out)


def crossing_period(t, u):
    """Mean spacing of the upward crossings of the record's mean (NaN with fewer than two)."""
    d = u - u.mean()
    k = np.nonzero((d[:-1] < 0) & (d[1:] >= 0))[0]
    if len(k) < 2:
        return math.nan
    tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
    return float((tc[-1] - tc[0]) / (len(tc) - 1))


def analyse(run, fe_u, fe_period, u_static, cycles):
    """The row of one run: peak errors, period error, numerical damping, cost."""
    s = run["setting"]
    row = {"cell": s.cell, "shape": s.shape, "ppc": s.ppc, "scheme": s.scheme, "cfl": s.cfl,
           "transfer": s.transfer if s.transfer != "xpic" else f"xpic({s.xpic_order})", "label": s.label,
           "status": run["status"]}
    if run["status"] != "ok":
        return row
    t, u = run["t"], run["u"]
    peaks = cycle_peaks(t, u, fe_period, cycles)
    fe_peaks = cycle_peaks(t, fe_u, fe_period, cycles)
    err = (peaks - fe_peaks) / fe_peaks
    e = run["energies"]
    t_end = t[-1]
    n_cycles = t_end / fe_period
    # the sway's energy about the static state: half the load's mean work over whole cycles
    whole = t <= math.floor(n_cycles) * fe_period if n_cycles >= 1 else t <= t_end
    e_osc = 0.5 * float(np.mean(run["work"][whole]))
    loss = float(e["numerical_loss"])
    period = crossing_period(t, u)
    fe_period_est = crossing_period(t, fe_u)
    row.update({
        "particles": run["particles"], "steps": run["steps"], "wall_s": run["wall_s"], "cpu_s": run["cpu_s"],
        "peaks_mm": [float(p) * 1e3 for p in peaks], "fe_peaks_mm": [float(p) * 1e3 for p in fe_peaks],
        "peak_errors": [float(x) for x in err],
        "worst_peak_error": float(np.nanmax(np.abs(err))) if np.isfinite(err).any() else math.nan,
        "last_peak_error": float(err[np.isfinite(err)][-1]) if np.isfinite(err).any() else math.nan,
        "period_ms": period * 1e3, "fe_period_ms": fe_period_est * 1e3,
        "period_error": (period - fe_period_est) / fe_period_est,
        "loss_J": loss, "loss_of_energy": loss / (2 * e_osc) if e_osc > 0 else math.nan,
        # a viscous oscillator keeps e^(-4 pi zeta n) of its sway energy after n cycles
        "zeta": (-math.log(1 - loss / e_osc) / (4 * math.pi * n_cycles)
                 if e_osc > 0 and loss < e_osc else math.nan),
    })
    return row


# -- output ----------------------------------------------------------------------------------

COLUMNS = ("label", "status", "particles", "steps", "wall_s", "cpu_s", "zeta", "loss_of_energy",
           "worst_peak_error", "last_peak_error", "period_error", "peaks_mm", "fe_peaks_mm")


def markdown(rows):
    lines = ["| setting | wall (s) | CPU (s) | numerical damping zeta (% of critical) | energy lost (% of the energy in play) "
             "| worst peak error | last peak error | period error | peaks, cycles 1 ... (mm) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['label']} | | | | | | | | {r['status']} |")
            continue
        peaks = ", ".join(f"{p:.2f}" for p in r["peaks_mm"] if p is not None and math.isfinite(p))
        zeta = f"{100 * r['zeta']:.4f}" if r["zeta"] is not None and math.isfinite(r["zeta"]) else "(more than the sway's energy lost)"
        lines.append(f"| {r['label']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {zeta} | {100 * r['loss_of_energy']:.3f} "
                     f"| {100 * r['worst_peak_error']:.2f}% | {100 * r['last_peak_error']:+.2f}% "
                     f"| {100 * r['period_error']:+.2f}% | {peaks} |")
    # each row is compared with the FE at its own tracked particle; the FE's peaks differ by
    # the particle (up to 0.2% between 0.05 and 0.025 m cells): one line per particle
    seen = set()
    for r in rows:
        if r["status"] != "ok" or (r["cell"], r["ppc"]) in seen:
            continue
        seen.add((r["cell"], r["ppc"]))
        lines.append(f"| continuum FE (reference) at the particle of {r['cell']:g} m, {r['ppc']:g}x{r['ppc']:g} | | | 0 | 0 | | | | "
                     f"{', '.join(f'{p:.2f}' for p in r['fe_peaks_mm'] if p is not None and math.isfinite(p))} |")
    return "\n".join(lines)


def write_csv(rows, path):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([json.dumps(r.get(c)) if isinstance(r.get(c), list) else r.get(c, "") for c in COLUMNS])


def write_plot(rows, path):
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    for r in rows:
        if r["status"] != "ok" or not r["zeta"] > 0:
            continue
        marker = {"flip": "o", "apic": "s"}.get(r["transfer"], "^")
        ax.loglog(r["cpu_s"], 100 * r["zeta"], marker, ms=8, label=r["label"])
    # CPU time: on a shared machine the steadier of the two clocks (both are in the table)
    ax.set_xlabel("CPU time of the stepping, one core (s)")
    ax.set_ylabel("numerical damping (% of critical)")
    ax.set_title("elastic portal frame, 0.25 s: energy lost per cycle against cost")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    fig.savefig(path, dpi=110)


def _jsonable(x):
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def study(settings, t_end, fe_level, outdir, log=sys.stderr):
    """Run ``settings`` and write the table, the CSV and the plot; returns the rows."""
    from studies.accuracy import warm_up
    os.makedirs(outdir, exist_ok=True)
    warm_up({("frame", s.shape, s.scheme) for s in settings}, log)
    cycles = max(1, int(round(t_end / 0.0405)))
    rows, refs = [], {}
    for k, s in enumerate(settings):
        t0 = time.perf_counter()
        run = run_setting(s, t_end)
        # the reference on the run's own sampling (an implicit run samples every step)
        key = (s.cell, s.ppc, len(run["t"]), float(run["t"][-1])) if run["status"] == "ok" else None
        if key not in refs and run["status"] == "ok":
            refs[key] = fe_reference(run["t"], s.cell, s.ppc, fe_level)
        if run["status"] == "ok":
            fe_u, fe_period, u_static = refs[key]
            cycles = int(math.floor(t_end / fe_period + 1e-9)) or 1
            row = analyse(run, fe_u, fe_period, u_static, cycles)
        else:
            row = analyse(run, None, None, None, cycles)
        rows.append(row)
        print(f"[response] {k + 1}/{len(settings)} {s.label}: {row['status']}"
              + (f", zeta {100 * row['zeta']:.4f}%, lost {100 * row['loss_of_energy']:.3f}%, worst peak "
                 f"{100 * row['worst_peak_error']:.2f}%, wall {row['wall_s']:.1f} s" if row["status"] == "ok" else "")
              + f" ({time.perf_counter() - t0:.0f} s)", file=log, flush=True)
        # after every run: a study cut short keeps what it measured
        write_csv(rows, os.path.join(outdir, "response.csv"))
        with open(os.path.join(outdir, "response.md"), "w") as f:
            f.write(markdown(rows) + "\n")
    write_plot(rows, os.path.join(outdir, "response.png"))
    return rows


def main(argv=None, out=None):
    out = out or sys.stdout   # looked up at the call: a caller's redirect_stdout holds
    ap = argparse.ArgumentParser(prog="python -m studies.accuracy_response", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI test's reduced study (0.1 m, 0.05 s)")
    ap.add_argument("--implicit", action="store_true",
                    help="the implicit integrator's rows instead: time steps T1/20 ... T1/400 at 0.05 m")
    ap.add_argument("--outdir", default="accuracy_results", help="folder of response.{md,csv,png}")
    ap.add_argument("--only", type=int, nargs="+", metavar="K", help="run only these of the settings (0-based)")
    ap.add_argument("--end", type=float, help="end time (s), default 0.25 (quick: 0.05)")
    ap.add_argument("--list", action="store_true", help="list the settings and exit")
    ap.add_argument("--edge-mass-ratio", type=float, default=0.0,
                    help="the implicit rows with [solver.implicit] edge_mass_ratio (pmpm.core.implicit.edges)")
    args = ap.parse_args(argv)
    settings = QUICK if args.quick else IMPLICIT if args.implicit else FULL
    if args.list:
        for k, s in enumerate(settings):
            print(k, s.label, file=out)
        return 0
    if args.only:
        settings = tuple(settings[k] for k in args.only)
    if args.edge_mass_ratio:
        settings = tuple(dataclasses.replace(s, edge_mass_ratio=args.edge_mass_ratio) if s.time_step > 0 else s
                         for s in settings)
    t_end = args.end or (QUICK_T_END if args.quick else T_END)
    rows = study(settings, t_end, QUICK_FE_LEVEL if args.quick else FE_LEVEL, args.outdir)
    print(markdown(rows), file=out)
    print(json.dumps(_jsonable({"study": "response", "t_end": t_end, "quick": args.quick,
                                "rows": [{k: v for k, v in r.items()} for r in rows]})), file=out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
