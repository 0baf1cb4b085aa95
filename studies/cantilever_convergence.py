"""Convergence study of the large-rotation cantilever (cases/hard/cantilever_large_rotation.toml),
against the published finite-element curve of its lower free corner
(cases/hard/data/cantilever_fe_corner.csv).

Each variant ``<material>_h<cell size>`` runs serially in-process to its end time; per run the
study reports the largest drop of the lower free corner (the FE curve's point; FE: 3.28 m), the
RMS gap of the corner's uy to the FE curve over the curve's samples up to the run's end (the
run's history interpolated at the curve's times), the RMS gap to the independent FE model on a
converged mesh (tests/verification/cantilever_fe_model.py, every 5 ms: the digitised curve
matches a coarse FE mesh, not a converged one; docs/hard_cases.md), the largest tip drop (the minimum of the
``tip`` track's uy) and its time, the energy balance counted both ways: the largest excess
(gain) and the largest deficit (loss) of kinetic + internal work against the initial energy
plus the external work, relative to the largest energy in play, with pmpm's external work
and with the exact work of gravity, sum_p m_p g . (x_p - x0_p) (this scene conserves energy, so
a loss is a defect as much as a gain), the largest
distance between particles that started as lattice neighbours, in cells (``separation``: a torn
or fractured beam opens gaps of several cells; a whole one stays below 1), particle count, steps
and wall time. Per material it reports the successive differences of the largest drop.

Run::

    python -m studies.cantilever_convergence                  # the neo-Hookean variants
    python -m studies.cantilever_convergence --variants neo_hookean_h0.25 \
        --histories /tmp/cantilever.npz --plot docs/cantilever_convergence.png

It prints one Markdown table row per run as it finishes, then the differences, then one JSON
line; ``--histories`` saves the histories (t, tip ux, tip uy, corner uy per variant), ``--plot`` overlays them.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

from studies import verification_models

CASE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cases", "hard",
                    "cantilever_large_rotation.toml")
MATERIALS = ("neo_hookean", "linear_elastic")
CELL_SIZES = ("0.25", "0.125", "0.0625")
FE_CURVE = os.path.join(os.path.dirname(CASE), "data", "cantilever_fe_corner.csv")
#: the published finite-element reference (Sadeghirad, Brannon & Burghardt 2011, IJNME 86,
#: 1435-1456): the largest drop of the beam's lower free corner, 3.28 m at t ~ 1.05 s, as
#: digitised (FE_CURVE)
FEM_LARGEST_DROP = 3.28


def fe_curve():
    """(t, uy) of the FE curve's samples (s, m), by time."""
    with open(FE_CURVE) as f:
        rows = [line.split(",") for line in f if line.strip() and line[0].isdigit()]
    data = np.array(rows, dtype=float)
    return data[:, 0], data[:, 1]


#: elements through the depth of the independent FE model's reference run (9-node
#: quadrilaterals; tests/verification/cantilever_fe_model.py): 7 is the finest mesh whose
#: solution stays on the smooth branch (at 8 the compressed root creases at t ~ 1.45 s,
#: docs/hard_cases.md); 6 and 7 differ by 0.003 m RMS
REFERENCE_DEPTH = 7
_reference_cache = {}


def reference_history(depth=REFERENCE_DEPTH):
    """(t, uy) of the lower free corner from the independent FE model (converged mesh),
    computed once per process (about 15 s at 7 elements through the depth)."""
    if depth not in _reference_cache:
        cantilever_fe_model = verification_models.load("cantilever_fe_model")
        t, uy, _, _ = cantilever_fe_model.corner_history(depth)
        _reference_cache[depth] = (t, uy)
    return _reference_cache[depth]


def rms_gap_to_reference(t, uy, depth=REFERENCE_DEPTH):
    """RMS of (run - converged FE model) over the model's samples (every 5 ms) to the run's end."""
    rt, ru = reference_history(depth)
    keep = rt <= t[-1] + 1e-12
    run = np.interp(rt[keep], np.concatenate([[0.0], t]), np.concatenate([[0.0], uy]))
    return float(np.sqrt(np.mean((run - ru[keep]) ** 2)))


def rms_gap(t, uy, t_end=None):
    """RMS of (run - FE) at the FE curve's sample times up to ``t_end`` (default: the run's
    last time), the run's corner uy (``t``, ``uy``) interpolated linearly there."""
    ft, fu = fe_curve()
    t_end = t[-1] if t_end is None else t_end
    keep = ft <= t_end + 1e-12
    # the run's samples start after the first step; uy = 0 at t = 0
    run = np.interp(ft[keep], np.concatenate([[0.0], t]), np.concatenate([[0.0], uy]))
    return float(np.sqrt(np.mean((run - fu[keep]) ** 2)))


class LatticeNeighbours:
    """Pairs of particles that started as right/up neighbours on a body's fill lattice (the
    bodies of this case are rectangles filled on a regular lattice)."""

    def __init__(self, particles, spacing):
        x0 = particles["x0"]
        ij = np.rint((x0 - x0.min(axis=0)) / spacing).astype(np.int64)
        n = ij.max(axis=0) + 2
        index = np.full((n[0], n[1]), -1, dtype=np.int64)
        index[ij[:, 0], ij[:, 1]] = np.arange(len(x0))
        pairs = []
        for di, dj in ((1, 0), (0, 1)):
            q = index[ij[:, 0] + di, ij[:, 1] + dj]
            ok = q >= 0
            pairs.append(np.stack([np.nonzero(ok)[0], q[ok]], axis=1))
        self.pairs = np.concatenate(pairs)
        self.ids = particles["id"].copy()

    def largest_distance(self, particles):
        """Largest current distance of a neighbour pair (particles may have been reordered)."""
        order = np.argsort(particles["id"])
        pos = np.empty_like(particles["x"])
        pos[particles["id"][order]] = particles["x"][order]
        where = pos[self.ids]
        d = where[self.pairs[:, 0]] - where[self.pairs[:, 1]]
        return float(np.sqrt((d * d).sum(axis=1)).max())


def run_variant(variant, sample_every=5, log=None):
    """Run one variant serially; returns (summary dict, history (samples, 4): t, tip ux, tip uy,
    corner uy)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    from pmpm.scene.config import load_scene

    scene = load_scene(CASE, variant)[0]
    s = build_solver(scene, MPI.COMM_SELF)
    tracker = Tracker(scene.output.track, s)
    names = [t.name for t in scene.output.track]
    ppc = scene.bodies[0].particles_per_cell
    neighbours = LatticeNeighbours(s.particles, s.grid.h / ppc)
    gravity = np.asarray(scene.loads.gravity)
    rows, energy, gaps = [], [], []
    end = scene.solver.end_time
    error = None
    t0 = time.perf_counter()
    try:
        while s.t < end - 1e-12 * end:
            s.step()
            if s.step_count % sample_every == 0 or s.t >= end - 1e-12 * end:
                e = s.energies()
                p = s.particles
                exact = float(np.sum(p["m"][:, None] * gravity * (p["x"] - p["x0"])))
                energy.append([e["kinetic"], e["internal_work"], e["external_work"], e["total"], exact])
                sample = tracker.sample()
                tip, corner = sample[names.index("tip")], sample[names.index("corner")]
                rows.append([s.t, tip[0], tip[1], corner[1]])
                gaps.append(neighbours.largest_distance(p) / s.grid.h)
    except Exception as exc:  # a run that stops is reported, not raised
        error = f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    hist = np.array(rows)
    E = np.array(energy)
    e0 = s.initial_energy
    out = {"variant": variant, "cell_size": s.grid.h, "particles": s.n_total, "steps": s.step_count,
           "t_end": s.t, "wall_s": wall, "error": error}
    if len(hist):
        k = int(np.argmin(hist[:, 2]))
        for key, ext in (("excess", E[:, 2]), ("excess_exact", E[:, 4])):
            scale = max(np.abs(E[:, 0]).max(), np.abs(E[:, 1]).max(), (abs(e0) + np.abs(ext)).max())
            balance = (E[:, 3] - (e0 + ext)) / scale
            out[key] = float(balance.max())                       # the largest gain
            out[key.replace("excess", "loss")] = float(-balance.min())   # the largest loss
        out.update(largest_drop=float(-hist[k, 2]), t_largest_drop=float(hist[k, 0]),
                   rebound=float(hist[k:, 2].max()), separation=float(max(gaps)),
                   corner_largest_drop=float(-hist[:, 3].min()),
                   rms_gap_fe=rms_gap(hist[:, 0], hist[:, 3]),
                   rms_gap_reference=rms_gap_to_reference(hist[:, 0], hist[:, 3]))
    if log is not None:
        print(_row(out), file=log, flush=True)
    return out, hist


def _row(r):
    if "largest_drop" not in r:
        return f"| {r['variant']} | stopped: {r['error']} |"
    return (f"| `{r['variant']}` | {r['cell_size']:g} m | {r['particles']} | {r['steps']} | {r['t_end']:.2f} | "
            f"{r['corner_largest_drop']:.3f} m | {r['rms_gap_fe']:.3f} m | {r['rms_gap_reference']:.3f} m | "
            f"{r['largest_drop']:.3f} m at {r['t_largest_drop']:.2f} s | {r['rebound']:.2f} m | "
            f"{100 * r['loss']:.2f}% / {100 * r['excess']:.2f}% | "
            f"{100 * r['loss_exact']:.2f}% / {100 * r['excess_exact']:.2f}% | {r['separation']:.2f} | "
            f"{r['wall_s']:.0f} s |" + ("" if r["error"] is None else f" stopped: {r['error']}"))


HEADER = ("| variant | cell | particles | steps | end (s) | corner's largest drop (FE 3.28 m) | RMS gap to FE | "
          "RMS gap to converged FE model | "
          "largest tip drop | tip highest after | energy lost / gained | lost / gained (exact work) | "
          "largest neighbour gap (cells) | wall |\n"
          "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |")


def differences(results):
    """Per material: the corner's largest drops by cell size (coarse to fine) and their
    successive relative differences |d_k - d_{k+1}| / d_{k+1}."""
    out = {}
    for mat in MATERIALS:
        drops = [r["corner_largest_drop"] for h in CELL_SIZES for r in results
                 if r["variant"] == f"{mat}_h{h}" and "largest_drop" in r]
        out[mat] = {"drops": drops,
                    "relative_differences": [abs(a - b) / b for a, b in zip(drops, drops[1:])]}
    return out


def plot(histories, path):
    """Tip (mid-depth) and lower-corner uy histories of every variant, with the reference's
    largest corner drop."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    styles = {"0.25": ":", "0.125": "--", "0.0625": "-"}
    colours = {"neo_hookean": "tab:blue", "linear_elastic": "tab:red"}
    for variant, h in histories.items():
        mat, cell = variant.rsplit("_h", 1)
        for ax, col in zip(axes, (2, 3)):
            ax.plot(h[:, 0], h[:, col], styles.get(cell, "-"), color=colours.get(mat, "k"), label=variant)
    ft, fu = fe_curve()
    axes[1].plot(ft, fu, "k.", ms=3, label="FE (Sadeghirad et al. 2011, digitised)")
    rt, ru = reference_history()
    axes[1].plot(rt, ru, "-", color="0.4", lw=0.8, label=f"FE model, Q9 x {REFERENCE_DEPTH} deep (converged)")
    for ax, title in zip(axes, ("tip (free end, mid-depth)", "lower free corner")):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    axes[0].set_ylabel("uy (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+",
                    default=[f"neo_hookean_h{h}" for h in CELL_SIZES])
    ap.add_argument("--histories", help="save the tip histories here (.npz)")
    ap.add_argument("--plot", help="overlay the tip histories in this image")
    args = ap.parse_args(argv)
    print(HEADER, flush=True)
    results, hist = [], {}
    for v in args.variants:
        r, h = run_variant(v, log=sys.stdout)
        results.append(r)
        hist[v] = h
        if args.histories:
            np.savez(args.histories, **hist)
    diffs = differences(results)
    for mat, d in diffs.items():
        if d["drops"]:
            print(f"{mat}: corner's largest drops {', '.join(f'{x:.3f}' for x in d['drops'])} m; successive "
                  f"differences {', '.join(f'{100 * x:.2f}%' for x in d['relative_differences'])}")
    if args.plot:
        plot(hist, args.plot)
    print(json.dumps({"runs": results, "differences": diffs}))


if __name__ == "__main__":
    main()
