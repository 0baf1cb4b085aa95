"""The three-storey frame under the Northridge record with the implicit integrator (issue 37).

``mpirun -n 2 python -m studies.northridge_implicit [--cell 0.1] [--t-end 15] [--explicit 3]``
runs the ``northridge_implicit`` variant of cases/frame_3storey.toml (elastoplastic smooth von
Mises, gravity brought to static equilibrium first, 2 % Rayleigh damping at T1 and T2, the real
record RSN 953 at the supports, steps of 0.01 s) on the ranks it is given, without the frame's
support reactions and section cuts (the implicit integrator carries them since issue 37's
statics landed; the study reads drifts and leaves them out to save their cost), and prints:

* the wall time and the implicit statistics (steps, Newton iterations, halvings);
* the roof and floor drifts (the left joints' ux minus the ground's displacement, the
  absolute formulation's supports: pmpm.physics.groundmotion): peaks with their times, and
  the residual drifts (mean over the last second of the run);
* the peak and residual inter-storey drift ratios;
* where and when the steel first yields (the first particle with plastic strain: its
  position and member);
* with ``--explicit T``: the explicit integrator on the same scene to T s, started from the
  implicit run's static equilibrium (the explicit integrator has no static stage; gravity
  switched on at t = 0 would leave the frame oscillating about its sagged shape:
  pmpm.benchmarks.implicit_frame.static_start), the roof drift's RMS difference over the
  implicit samples in (0, T] as a percentage of the implicit run's peak there, and its wall
  time. With the variant's Rayleigh damping the explicit step is 7e-7 s at 0.1 m: the
  comparison needs ``--undamped`` (both runs without it).

The machine these figures come from is shared (2 cores, several jobs): wall times are
inflated. The last line printed is one JSON object.
"""
import argparse
import dataclasses
import json
import sys
import time

import numpy as np

from pmpm.benchmarks.implicit import _implicit_keys
from pmpm.benchmarks.implicit_frame import (adopt_state, explicit_twin, static_stage, static_start,
                                            strip_explicit_only, undamped)
from studies.frame_3storey import JOINTS, scene_at

__all__ = ["run", "main"]

VARIANT = "northridge_implicit"
STOREY = 3.96
#: "yielded": a plastic strain of a tenth of the yield strain (397 MPa / 200 GPa); the smooth
#: von Mises model has some plastic flow at any stress, so any threshold is a choice
YIELDED = 0.1 * 397e6 / 200e9


def run(scene, comm, every=1, progress=True, start=None):
    """Step ``scene`` to its end on ``comm``: times, joint drifts (n, 3), first yield, wall.
    ``start``: particle fields to start from (implicit_frame.static_start), the drifts still
    measured from the positions before it. A run with a static stage records from its first
    step on (its state at t = 0 is the equilibrium that step computes first)."""
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    s = build_solver(scene, comm)
    names = [t.name for t in scene.output.track if t.name in JOINTS]
    tracker = Tracker([t for t in scene.output.track if t.name in JOINTS], s)
    order = [names.index(n) for n in JOINTS]
    ground = s.effect("ground_motion")
    x0 = tracker.sample()[order, 0].copy()
    if start is not None:
        adopt_state(s, start, comm)
    t, drift = ([], []) if static_stage(scene) else ([0.0], [tracker.sample()[order, 0] - x0])
    first_yield = None
    bodies = [b.name for b in scene.bodies]
    members = _members(bodies)
    yielded = {}   # member -> (t, x, y, eps_p_eq) when its steel first yields
    start, cpu = time.perf_counter(), time.process_time()
    shown = 0.0
    end = scene.solver.end_time
    while s.t < end * (1 - 1e-12):
        s.step()
        if s.step_count % every:
            continue
        t.append(s.t)
        drift.append(tracker.sample()[order, 0] - x0 - ground.displacement(s.t))
        if first_yield is None and "eps_p_eq" in s.particles.fields:
            first_yield = _first_yield(s, comm, bodies)
        if "eps_p_eq" in s.particles.fields and len(yielded) < len(set(members)):
            _yielding_members(s, comm, members, yielded)
        if progress and comm.rank == 0 and s.t >= shown:
            print(f"\r  t = {s.t:.2f} / {end:g} s, {s.step_count} steps, {time.perf_counter() - start:.0f} s wall",
                  end="", file=sys.stderr, flush=True)
            shown += end / 100
    if progress and comm.rank == 0:
        print(file=sys.stderr)
    sequence = sorted(({"member": m, "t": v[0], "x": v[1], "y": v[2]} for m, v in yielded.items()),
                      key=lambda r: r["t"])
    return {"t": np.array(t), "drift": np.array(drift), "first_yield": first_yield, "yield_sequence": sequence,
            "wall_s": time.perf_counter() - start, "cpu_s": time.process_time() - cpu, "steps": s.step_count,
            "stats": dict(getattr(s.scheme, "stats", {}))}


def _first_yield(s, comm, bodies):
    """(time, x, y, member) of the particle with the largest plastic strain once it exceeds
    YIELDED, else None."""
    e = s.particles["eps_p_eq"]
    k = int(np.argmax(e)) if len(e) else -1
    best = (float(e[k]), tuple(map(float, s.particles["x"][k])), int(s.particles["body"][k])) if k >= 0 \
        else (0.0, (0.0, 0.0), -1)
    eps, x, body = max(comm.allgather(best))
    if eps < YIELDED:
        return None
    return {"t": float(s.t), "x": x[0], "y": x[1], "member": bodies[body], "eps_p_eq": eps}


def _members(bodies):
    """The member each body belongs to: a frame's joint panel (``<column>_panel_<joint>``)
    counts as its column's."""
    return [b.split("_panel_")[0] for b in bodies]


def _yielding_members(s, comm, members, yielded):
    """Add to ``yielded`` the members whose largest plastic strain first passes YIELDED now:
    member -> (time, x, y of that particle)."""
    e, body, x = s.particles["eps_p_eq"], s.particles["body"], s.particles["x"]
    names = sorted(set(members))
    local = []
    for name in names:
        if name in yielded:
            continue
        ids = [k for k, m in enumerate(members) if m == name]
        mine = np.isin(body, ids) & (e >= YIELDED)
        if np.any(mine):
            k = int(np.flatnonzero(mine)[np.argmax(e[mine])])
            local.append((name, float(e[k]), float(x[k, 0]), float(x[k, 1])))
    best = {}
    for rows in comm.allgather(local):
        for name, eps, px, py in rows:
            if name not in best or eps > best[name][0]:
                best[name] = (eps, px, py)
    for name, (eps, px, py) in best.items():
        yielded[name] = (float(s.t), px, py, eps)


def summary(result):
    t, d = result["t"], result["drift"]
    last = t >= t[-1] - 1.0
    storey = np.diff(np.concatenate([np.zeros((len(t), 1)), d], axis=1), axis=1) / STOREY
    out = {"peak_drift_m": [float(np.abs(d[:, k]).max()) for k in range(3)],
           "peak_drift_time_s": [float(t[np.argmax(np.abs(d[:, k]))]) for k in range(3)],
           "residual_drift_m": [float(d[last, k].mean()) for k in range(3)],
           "peak_storey_drift_ratio": [float(np.abs(storey[:, k]).max()) for k in range(3)],
           "residual_storey_drift_ratio": [float(storey[last, k].mean()) for k in range(3)]}
    return out


def main(argv=None):
    from mpi4py import MPI
    ap = argparse.ArgumentParser(prog="python -m studies.northridge_implicit", description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.1)
    ap.add_argument("--ppc", type=int, default=2)
    ap.add_argument("--t-end", type=float, default=15.0)
    ap.add_argument("--dt", type=float, default=None, help="the implicit step (default the variant's 0.01 s)")
    ap.add_argument("--explicit", type=float, default=0.0, metavar="T", help="also the explicit run to T s")
    ap.add_argument("--implicit", nargs="*", default=[], metavar="KEY=VALUE",
                    help="[solver.implicit] keys over the variant's, e.g. newton=modified")
    ap.add_argument("--petsc", nargs="*", default=[], metavar="NAME=VALUE", help="[solver.petsc] options")
    ap.add_argument("--undamped", action="store_true",
                    help="without the variant's Rayleigh damping (both runs): the explicit twin's step with the "
                         "stiffness-proportional viscous stress is bound by it (7e-7 s at 0.1 m: 4.3 million steps "
                         "for 3 s), so the integrators are compared on the undamped frame")
    ap.add_argument("--save", metavar="FILE.npz", help="write the drift histories (both runs) here")
    ap.add_argument("--plot", metavar="FILE.png", help="draw the drift histories here")
    a = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    scene = strip_explicit_only(scene_at(a.cell, a.ppc, VARIANT))
    solver = dataclasses.replace(scene.solver, end_time=float(a.t_end),
                                 time_step=float(a.dt or scene.solver.time_step),
                                 implicit={**scene.solver.implicit, **_implicit_keys(a.implicit)},
                                 petsc={**scene.solver.petsc, **_implicit_keys(a.petsc)})
    scene = dataclasses.replace(scene, solver=solver)
    if a.undamped:
        scene = undamped(scene)
    res = run(scene, comm)
    out = {"study": "northridge_implicit", "cell": a.cell, "ppc": a.ppc, "ranks": comm.size, "t_end": a.t_end,
           "time_step": scene.solver.time_step, "wall_s": res["wall_s"], "cpu_s_rank0": res["cpu_s"],
           "steps": res["steps"],
           "stats": res["stats"], "first_yield": res["first_yield"], "yield_sequence": res["yield_sequence"],
           "implicit_options": a.implicit, "petsc_options": a.petsc, "undamped": a.undamped, **summary(res)}
    if comm.rank == 0:
        _report(out, res, a)   # before the explicit run: a long twin cut short loses nothing
        if a.save:
            np.savez(a.save, t=res["t"], drift=res["drift"])
    ex = None
    if a.explicit > 0:
        ex = run(explicit_twin(scene, a.explicit), comm, every=20, start=static_start(scene, comm))
        ti, ri = res["t"], res["drift"][:, 2]
        within = ti <= a.explicit + 1e-9
        re = np.interp(ti[within], ex["t"], ex["drift"][:, 2])
        rms = float(np.sqrt(np.mean((re - ri[within]) ** 2)))
        out["explicit"] = {"t_end": a.explicit, "wall_s": ex["wall_s"], "steps": ex["steps"],
                           "roof_rms_difference_of_peak": rms / float(np.abs(ri[within]).max())}
    if comm.rank == 0:
        if "explicit" in out:
            e = out["explicit"]
            print(f"  explicit over the first {e['t_end']:g} s: {e['steps']} steps, {e['wall_s']:.0f} s wall; roof drift "
                  f"RMS difference {100 * e['roof_rms_difference_of_peak']:.2f} % of the implicit peak")
        if a.save and ex is not None:
            np.savez(a.save, t=res["t"], drift=res["drift"], explicit_t=ex["t"], explicit_drift=ex["drift"])
        if a.plot:
            _plot(a.plot, res, ex, a.cell)
        print(json.dumps(out))


def _report(out, res, a):
    """The implicit run's figures (rank 0)."""
    print(f"implicit, {a.cell:g} m cells, {out['ranks']} rank(s), {a.t_end:g} s of the record: {out['steps']} steps of "
          f"{out['time_step']:g} s, {res['stats'].get('newton_iterations')} Newton iterations, "
          f"{res['stats'].get('factorisations')} factorisations, "
          f"{res['stats'].get('halvings')} halvings, {out['wall_s']:.0f} s wall (shared machine), "
          f"{out['cpu_s_rank0']:.0f} s CPU on rank 0")
    for k, name in enumerate(("floor 2", "floor 3", "roof")):
        print(f"  {name}: peak drift {1e3 * out['peak_drift_m'][k]:.3f} mm at {out['peak_drift_time_s'][k]:.2f} s, "
              f"residual {1e3 * out['residual_drift_m'][k]:+.3f} mm; storey {k + 1}: peak drift ratio "
              f"{100 * out['peak_storey_drift_ratio'][k]:.2f} %, residual {100 * out['residual_storey_drift_ratio'][k]:+.3f} %")
    fy = out["first_yield"]
    print("  first yield: " + ("none" if fy is None else
                               f"t = {fy['t']:.2f} s at ({fy['x']:.2f}, {fy['y']:.2f}) m ({fy['member']})"))
    for row in out["yield_sequence"]:
        print(f"    {row['member']} yields at t = {row['t']:.2f} s, at ({row['x']:.2f}, {row['y']:.2f}) m")
    print(json.dumps({k: v for k, v in out.items() if k != "explicit"}), flush=True)


def _plot(path, res, ex, cell):
    """The floors' and the roof's drift histories (the explicit run's over its span)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for k, ax in enumerate(axes):
        j = 2 - k   # the roof on top
        ax.plot(res["t"], 1e3 * res["drift"][:, j], lw=0.8, label="implicit (Newmark, 0.01 s)")
        if ex is not None:
            ax.plot(ex["t"], 1e3 * ex["drift"][:, j], lw=0.8, ls="--", label="explicit (MUSL, CFL 0.9)")
        ax.set_ylabel(f"{('roof', 'floor 3', 'floor 2')[k]} drift (mm)")
        ax.axhline(0.0, color="0.7", lw=0.5)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title(f"Three-storey frame, Northridge RSN 953, {cell:g} m cells: drifts relative to the ground")
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
