"""Time to solution, implicit against explicit (issue 37): ``pmpm bench implicit --scenes portal
frame3-step frame3-record`` runs each scene with the implicit integrator and with the explicit
one (MUSL) to the same end time on the ranks it is given and prints, per scene, the steps, wall
and CPU time of each, the ratio explicit / implicit, the implicit run's Newton statistics and how
far its drift history is from the explicit run's; then one JSON line with everything.

The scenes:

* ``portal``: the main job's portal frame (cases/portal_frame.toml, ``--variant``, default
  elastic) under its step load, the upper-left joint's drift (pmpm.benchmarks.implicit.portal_scene);
* ``frame3-step``: the three-storey frame (cases/frame_3storey.toml, the same ``--variant``)
  under its lateral step loads, the roof's drift (the left roof joint);
* ``frame3-record``: the three-storey frame's ``northridge_implicit`` variant (the Northridge
  record at the supports, gravity brought to equilibrium statically first) WITHOUT its 2 %
  Rayleigh damping (implicit_frame.undamped: its stiffness-proportional part bounds the explicit
  step at 7.1e-7 s at 0.1 m cells, 4.3 million steps for 3 s; undamped the CFL step is 1.7e-5
  s); the record stays elastic over its first 4 s, where the damping is what differs most. The
  explicit twin starts from the implicit run's static equilibrium (implicit_frame.static_start,
  left out of its time); the roof's drift relative to the ground.

The accuracy figure: the RMS over the implicit run's samples in [0, end] of the implicit drift
minus the explicit drift (interpolated linearly at the implicit sample times from the explicit
run's, sampled ten times as often), as a percentage of the explicit run's largest |drift| over
the same span: the explicit run is the reference here, not a converged solution.

Times: wall time (perf_counter on rank 0, around the stepping loop; building the solver is left
out) and CPU time (time.process_time of the loop summed over the ranks: Open MPI's blocking calls
spin, so a rank's wait counts as CPU). ``--repeat N`` runs N interleaved rounds (each round every
scene, implicit then explicit) and quotes the medians; the histories and Newton statistics are
the last round's (the runs are deterministic). Without ``--scenes``, ``pmpm bench implicit`` is
the portal driver of pmpm.benchmarks.implicit (its options: ``--cell --dt --t-end --static ...``).
"""
import argparse
import dataclasses
import json
import sys

import numpy as np
from mpi4py import MPI

from pmpm.benchmarks import implicit as portal_driver
from pmpm.benchmarks.implicit_frame import JOINTS, drift_history, explicit_twin, frame3_scene, static_start, undamped

__all__ = ["SCENES", "DEFAULTS", "drift_difference", "compare", "report", "main"]

SCENES = ("portal", "frame3-step", "frame3-record")
#: per scene: cell size (m), implicit step (s), end time (s); the portal's are the main job's
#: cells and docs/implicit.md's T1/40, the frame's the northridge_implicit variant's step (the
#: record's sampling, T1/92) at the cells studies/northridge_implicit.py runs by default
DEFAULTS = {"portal": {"cell": 0.05, "dt": 1e-3, "t_end": 0.25},
            "frame3-step": {"cell": 0.1, "dt": 0.01, "t_end": 2.0},
            "frame3-record": {"cell": 0.1, "dt": 0.01, "t_end": 3.0}}
#: the drift compared: the portal's upper-left joint, the frame's roof (left roof joint)
PORTAL_JOINT = "upper_left_joint"
ROOF = JOINTS[-1]
#: the main job's CFL number (cases/portal_frame.toml); the frame's case names its own (0.9)
PORTAL_CFL = 0.9
#: explicit samples per implicit step (the interpolation's error then stays far below the
#: differences compared: a tenth of the step squared times the drift's curvature)
EXPLICIT_SAMPLES_PER_STEP = 10


def drift_difference(t_implicit, u_implicit, t_explicit, u_explicit):
    """RMS of u_implicit - u_explicit over the implicit samples within the explicit run's span,
    the explicit history interpolated linearly at those times, divided by the explicit run's
    largest |u| there. Returns (rms, peak, rms / peak)."""
    t_implicit, u_implicit = np.asarray(t_implicit, float), np.asarray(u_implicit, float)
    t_explicit, u_explicit = np.asarray(t_explicit, float), np.asarray(u_explicit, float)
    within = t_implicit <= t_explicit[-1] * (1 + 1e-12)
    reference = np.interp(t_implicit[within], t_explicit, u_explicit)
    rms = float(np.sqrt(np.mean((u_implicit[within] - reference) ** 2)))
    peak = float(np.abs(u_explicit[t_explicit <= t_implicit[within][-1] * (1 + 1e-12)]).max())
    return rms, peak, (rms / peak if peak > 0 else float("nan"))


def _scenes(name, o):
    """(implicit scene, explicit scene, joint compared) of scene ``name`` with options ``o``."""
    cell, dt, t_end = o.cell[name], o.dt[name], o.t_end[name]
    if name == "portal":
        implicit = dataclasses.replace(portal_driver.portal_scene(cell, dt, t_end, root=portal_driver.CHECKOUT,
                                                                  petsc=o.petsc, variant=o.variant,
                                                                  implicit=o.implicit), variant=o.variant)
        return implicit, explicit_twin(implicit, cfl=PORTAL_CFL), PORTAL_JOINT
    if name == "frame3-step":
        implicit = frame3_scene(cell, o.variant, ppc=o.ppc, time_step=dt, end_time=t_end, implicit=o.implicit,
                                petsc=o.petsc)
    else:   # the record's twin that both integrators can run: without the variant's Rayleigh damping
        implicit = undamped(frame3_scene(cell, "northridge_implicit", ppc=o.ppc, time_step=dt, end_time=t_end,
                                         implicit=o.implicit, petsc=o.petsc))
    return implicit, explicit_twin(implicit), ROOF


def _progress(label):
    def show(t, steps, wall):
        print(f"\r  {label}: t = {t:.4f} s, {steps} steps, {wall:.0f} s wall", end="", file=sys.stderr, flush=True)
    return show


def compare(o, comm=MPI.COMM_WORLD, progress=False):
    """Run every scene of ``o.scenes`` with both integrators, ``o.repeat`` interleaved rounds.
    Returns {scene: {"implicit": [run, ...], "explicit": [run, ...], "joint": name, "cell": ...}}
    with the runs of drift_history, rounds in order."""
    runs = {}
    for name in o.scenes:
        implicit, explicit, joint = _scenes(name, o)
        runs[name] = {"scenes": (implicit, explicit), "joint": joint, "implicit": [], "explicit": [],
                      "start": static_start(implicit, comm)}   # None unless a static stage comes first
    for round_ in range(o.repeat):
        for name in o.scenes:
            r = runs[name]
            implicit, explicit = r["scenes"]
            for kind, scene, interval, start in (
                    ("implicit", implicit, 0.0, None),
                    ("explicit", explicit, o.dt[name] / EXPLICIT_SAMPLES_PER_STEP, r["start"])):
                show = _progress(f"{name} {kind} (round {round_ + 1})") if progress else None
                r[kind].append(drift_history(scene, comm, (r["joint"],), interval, show, start=start))
                if show is not None and comm.rank == 0:
                    print(file=sys.stderr)
    return runs


def summary(name, r, o, ranks):
    """The figures of one scene (medians over the rounds) as a JSON-ready dict."""
    last_i, last_e = r["implicit"][-1], r["explicit"][-1]
    rms, peak, rel = drift_difference(last_i["t"], last_i["drift"][:, 0], last_e["t"], last_e["drift"][:, 0])
    med = {f"{kind}_{what}": float(np.median([run[what] for run in r[kind]]))
           for kind in ("implicit", "explicit") for what in ("wall_s", "cpu_s")}
    stats = last_i["stats"]
    return {"scene": name, "variant": r["scenes"][0].variant,
            "rayleigh_damping": r["scenes"][0].loads.rayleigh is not None,
            "start_from_static": r["start"] is not None, "cell_size": o.cell[name], "time_step": o.dt[name],
            "end_time": o.t_end[name], "ranks": ranks, "rounds": len(r["implicit"]), "joint": r["joint"],
            "implicit_steps": last_i["steps"], "explicit_steps": last_e["steps"], **med,
            "implicit_wall_s_rounds": [run["wall_s"] for run in r["implicit"]],
            "explicit_wall_s_rounds": [run["wall_s"] for run in r["explicit"]],
            "implicit_cpu_s_rounds": [run["cpu_s"] for run in r["implicit"]],
            "explicit_cpu_s_rounds": [run["cpu_s"] for run in r["explicit"]],
            "wall_ratio_explicit_over_implicit": med["explicit_wall_s"] / med["implicit_wall_s"],
            "cpu_ratio_explicit_over_implicit": med["explicit_cpu_s"] / med["implicit_cpu_s"],
            "newton_iterations": stats.get("newton_iterations"), "factorisations": stats.get("factorisations"),
            "halvings": stats.get("halvings"),
            "drift_rms_difference_m": rms, "explicit_peak_drift_m": peak, "drift_rms_difference_of_peak": rel,
            "implicit_peak_drift_m": float(np.abs(last_i["drift"][:, 0]).max())}


def report(runs, o, comm=MPI.COMM_WORLD, out=sys.stdout):
    """Print the table (rank 0) and the final JSON line; return the JSON object."""
    rows = [summary(name, runs[name], o, comm.size) for name in o.scenes]
    # a figure that could not be formed (no drift at all: NaN) is null in the JSON line
    rows = [{k: (None if isinstance(v, float) and v != v else v) for k, v in r.items()} for r in rows]
    result = {"benchmark": "implicit_time_to_solution", "ranks": comm.size, "repeat": o.repeat,
              "cpu": "time.process_time of the stepping loop summed over the ranks",
              "wall": "perf_counter on rank 0 around the stepping loop (solver set-up left out)",
              "accuracy": "RMS of implicit - explicit drift over the implicit samples, / explicit peak |drift|",
              "implicit_options": o.implicit_pairs, "petsc_options": o.petsc_pairs, "scenes": rows}
    if comm.rank == 0:
        print(f"implicit against explicit, {comm.size} rank(s), medians of {o.repeat} interleaved round(s); "
              f"CPU = process time summed over the ranks", file=out)
        print("| scene | cells (m) | end (s) | implicit steps (dt) | Newton it. / factorisations / halvings | "
              "explicit steps | implicit wall / CPU (s) | explicit wall / CPU (s) | explicit/implicit wall | "
              "explicit/implicit CPU | drift RMS diff. (% of peak) |", file=out)
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|", file=out)
        for r in rows:
            print(f"| {r['scene']} ({r['variant']}{'' if r['rayleigh_damping'] else ', no Rayleigh'}"
                  f"{', explicit from the static state' if r['start_from_static'] else ''}) | {r['cell_size']:g} | {r['end_time']:g} | "
                  f"{r['implicit_steps']} ({r['time_step']:g} s) | {r['newton_iterations']} / {r['factorisations']} / "
                  f"{r['halvings']} | {r['explicit_steps']:,} | {r['implicit_wall_s']:.1f} / {r['implicit_cpu_s']:.1f} | "
                  f"{r['explicit_wall_s']:.1f} / {r['explicit_cpu_s']:.1f} | "
                  f"{r['wall_ratio_explicit_over_implicit']:.2f} | {r['cpu_ratio_explicit_over_implicit']:.2f} | "
                  f"{100 * (r['drift_rms_difference_of_peak'] or float('nan')):.3f} (peak {1e3 * r['explicit_peak_drift_m']:.3f} mm) |",
                  file=out)
        print(json.dumps(result), file=out, flush=True)
    return result


def _per_scene(values, key, scenes, name):
    """``--cell 0.1`` (every scene) or ``--cell frame3-step=0.1 portal=0.05`` as {scene: value}."""
    out = {s: DEFAULTS[s][key] for s in scenes}
    for value in values:
        target, _, number = value.rpartition("=")
        try:
            number = float(number)
        except ValueError:
            raise SystemExit(f"pmpm: error: {name}: {value!r} is not a number or SCENE=NUMBER") from None
        if not (number > 0 and np.isfinite(number)):
            raise SystemExit(f"pmpm: error: {name}: {value!r} must be positive")
        if target and target not in SCENES:
            raise SystemExit(f"pmpm: error: {name}: unknown scene {target!r} (one of {', '.join(SCENES)})")
        for s in ([target] if target else scenes):
            if s in out:
                out[s] = number
    return out


def parser():
    ap = argparse.ArgumentParser(prog="pmpm bench implicit", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", choices=SCENES, required=True,
                    help="scenes to run (portal frame3-step frame3-record)")
    per = "one value for every scene, or SCENE=VALUE pairs"
    ap.add_argument("--cell", nargs="+", default=[], help=f"cell size, m ({per}; default portal 0.05, frames 0.1)")
    ap.add_argument("--dt", nargs="+", default=[], help=f"implicit time step, s ({per}; default portal 1e-3, frames 0.01)")
    ap.add_argument("--t-end", nargs="+", default=[],
                    help=f"end time, s ({per}; default portal 0.25, frame3-step 2, frame3-record 3)")
    ap.add_argument("--variant", default="elastic", choices=("elastic", "elastoplastic"),
                    help="variant of the step-load scenes (portal, frame3-step); default elastic")
    ap.add_argument("--ppc", type=int, default=None,
                    help="particles per cell of the frame (default the case's, 2; 3 at 0.2 m cells)")
    ap.add_argument("--implicit", nargs="*", default=[], metavar="KEY=VALUE",
                    help="[solver.implicit] keys of the implicit runs, e.g. newton=modified")
    ap.add_argument("--petsc", nargs="*", default=[], metavar="NAME=VALUE",
                    help="[solver.petsc] options of the implicit runs, e.g. pc_type=cholesky")
    ap.add_argument("--repeat", type=int, default=1, help="interleaved rounds; medians quoted (default 1)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    return ap


def options(argv):
    """The parsed options with per-scene dicts ``cell``, ``dt``, ``t_end`` and the pass-through
    dicts ``implicit`` and ``petsc``."""
    o = parser().parse_args(argv)
    o.scenes = list(dict.fromkeys(o.scenes))
    if o.repeat < 1:
        raise SystemExit("pmpm: error: --repeat: must be at least 1")
    o.cell = _per_scene(o.cell, "cell", o.scenes, "--cell")
    o.dt = _per_scene(o.dt, "dt", o.scenes, "--dt")
    o.t_end = _per_scene(o.t_end, "t_end", o.scenes, "--t-end")
    o.implicit_pairs, o.petsc_pairs = o.implicit, o.petsc
    o.implicit = portal_driver._implicit_keys(o.implicit)
    o.petsc = portal_driver._implicit_keys(o.petsc)
    return o


def main(argv=None):
    """``pmpm bench implicit``: with ``--scenes``, this benchmark; without, the portal driver
    (pmpm.benchmarks.implicit.main, its own options)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--scenes" not in argv:
        return portal_driver.main(argv)
    o = options(argv)
    runs = compare(o, MPI.COMM_WORLD, progress=not o.quiet)
    report(runs, o)
    return 0


if __name__ == "__main__":
    sys.exit(main())
