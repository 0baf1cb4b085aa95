"""Why the large-rotation cantilever's finest grid drifted: the time step (issue 20, item 3).

Runs one variant of a cantilever scene (cases/hard/cantilever_large_rotation.toml by default)
serially with the given overrides and prints, against the published FE curve of the beam's lower
free corner: the corner's largest drop, the RMS gap to the curve over the run (the run's corner
history interpolated at the curve's points up to its end time), the corner at 2.6 s, the
energy lost and gained (kinetic + internal work against the initial energy plus the exact work
of gravity, relative to the largest energy in play; both are defects, the scene conserves
energy), and over time the *noise*: the particles' kinetic energy the grid does not carry,
sum_p m_p |v_p - v(x_p)|^2 / 2, v(x_p) the particle's interpolated grid velocity of the
momentum-conserving projection of the particle velocities (FLIP keeps this part; a time step that
is unstable somewhere feeds it), with the share held by the particles within two cells of the
clamped face's line (x = the body's smallest initial x).

Run::

    python -m studies.cantilever_time_step --variant neo_hookean_h0.0625
    python -m studies.cantilever_time_step --variant neo_hookean_h0.0625 \
        --set solver.cfl=0.125

The last line is one JSON object.
"""
import argparse
import json
import os
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASE = os.path.join(ROOT, "cases", "hard", "cantilever_large_rotation.toml")
FE_CURVE = os.path.join(ROOT, "cases", "hard", "data", "cantilever_fe_corner.csv")
NOISE_TIMES = (1.0, 1.3, 1.6, 1.9, 2.2, 2.5)


def _grid_velocity_at_particles(s):
    """v(x_p): the particles' momenta projected on the grid (m v w_ip summed, over the nodal
    mass), interpolated back with the same weights; no boundary conditions."""
    from pmpm.core import kernels as K
    p, w, g = s.particles, s.window, s.grid
    G = np.zeros_like(w.G)
    K.p2g(p["x"], p["m"], p["v"], p["vol"], None, None, None, None, None,
          G, w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape)
    mass = G[..., 0]
    held = mass > 0
    V = np.zeros_like(w.G)
    V[..., 1:3][held] = G[..., 1:3][held] / mass[held][:, None]
    vg = np.zeros_like(p["v"])
    K.g2p_velocity(p["x"], p["m"], vg, 1.0, V, w.ox, w.oy, g.origin, g.inv_h, g.cells[0],
                   g.cells[1], s.shape, False, np.empty_like(vg), 0.0)
    return vg


def run(case, variant, overrides, fe_path, sample_every=10):
    """Run one variant; returns the summary dict (see the module docstring)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    from pmpm.scene.config import load_scene

    scene = load_scene(case, variant, overrides=overrides or None)[0]
    s = build_solver(scene, MPI.COMM_SELF)
    tracker = Tracker(scene.output.track, s)
    corner = [t.name for t in scene.output.track].index("corner")
    gravity = np.asarray(scene.loads.gravity)
    face = float(s.particles["x0"][:, 0].min())
    fe = np.loadtxt(fe_path, delimiter=",", comments="#", skiprows=1)
    fe = fe[np.argsort(fe[:, 0])]
    hist, energy, noise = [], [], []
    pending = list(NOISE_TIMES)
    end = scene.solver.end_time
    t0 = time.perf_counter()
    while s.t < end - 1e-12 * end:
        s.step()
        if s.step_count % sample_every == 0:
            p = s.particles
            e = s.energies()
            exact = float(np.sum(p["m"][:, None] * gravity * (p["x"] - p["x0"])))
            energy.append([e["kinetic"], e["internal_work"], e["total"], exact])
            hist.append([s.t, tracker.sample()[corner][1]])
        if pending and s.t >= pending[0]:
            p = s.particles
            vg = _grid_velocity_at_particles(s)
            part = 0.5 * p["m"] * ((p["v"] - vg) ** 2).sum(axis=1)
            near = p["x"][:, 0] < face + 2 * s.grid.h
            noise.append({"t": round(s.t, 3), "noise_J": float(part.sum()),
                          "near_clamp_share": float(part[near].sum() / max(part.sum(), 1e-300)),
                          "near_clamp_particles": float(near.mean())})
            pending.pop(0)
    wall = time.perf_counter() - t0
    H, E = np.array(hist), np.array(energy)
    e0 = s.initial_energy
    scale = max(np.abs(E[:, 0]).max(), np.abs(E[:, 1]).max(), (abs(e0) + np.abs(E[:, 3])).max())
    balance = (E[:, 2] - (e0 + E[:, 3])) / scale
    on = fe[:, 0] <= H[-1, 0]
    gap = np.interp(fe[on, 0], H[:, 0], H[:, 1]) - fe[on, 1]
    return {"variant": variant, "overrides": overrides, "cell_size": s.grid.h, "steps": s.step_count,
            "t_end": s.t, "wall_s": wall, "corner_largest_drop": float(-H[:, 1].min()),
            "rms_gap_m": float(np.sqrt(np.mean(gap ** 2))),
            "corner_at_2.6s": float(np.interp(2.6, H[:, 0], H[:, 1])),
            "energy_lost": float(max(-balance.min(), 0.0)), "energy_gained": float(max(balance.max(), 0.0)),
            "noise": noise}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", default=CASE)
    ap.add_argument("--variant", default="neo_hookean_h0.0625")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a dotted-key override, the value as JSON (e.g. solver.cfl=0.125)")
    ap.add_argument("--fe", default=FE_CURVE, help="the FE curve (CSV: t_s, uy_m)")
    args = ap.parse_args(argv)
    overrides = {}
    for kv in args.set:
        key, value = kv.split("=", 1)
        overrides[key] = json.loads(value)
    r = run(args.case, args.variant, overrides, args.fe)
    print(f"{r['variant']} {overrides or ''}: {r['steps']} steps, {r['wall_s']:.0f} s wall; corner's "
          f"largest drop {r['corner_largest_drop']:.3f} m, RMS gap to the FE curve {r['rms_gap_m']:.3f} m, "
          f"corner at 2.6 s {r['corner_at_2.6s']:+.2f} m, energy lost {100 * r['energy_lost']:.2f}% / "
          f"gained {100 * r['energy_gained']:.2f}%")
    for n in r["noise"]:
        print(f"  t = {n['t']:.2f} s: noise {n['noise_J']:8.1f} J, {100 * n['near_clamp_share']:4.0f}% of it "
              f"in the {100 * n['near_clamp_particles']:.1f}% of particles within 2 cells of the clamp's line")
    print(json.dumps(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
