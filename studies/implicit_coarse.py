"""Why the implicit portal is softer than the explicit one on coarse grids (issue 37): both
integrators against continuum models of the strips each grid's points carry.

``python -m studies.implicit_coarse [--cells 0.1 0.05] [--t-end 0.03]`` prints, per cell size,
the static drift and the first peak of the upper-left joint of the elastic portal
(cases/portal_frame.toml) from

* the continuum FE model of the W shapes' strips (tests/verification/frame_fe_model.py, the
  reference of docs/portal_frame.md section 8; it does not depend on the cell size);
* the same FE model of the strips *the points of that grid carry*: pmpm gives each row of points
  across a member one thickness, a mix of web and flange scaled so that the rows' area and second
  moment are the W shape's (docs/portal_frame.md section 1; at 0.1 m the web is 0.28 tw). Here
  each row's band [eta - dy/2, eta + dy/2] of the strip gets that thickness in the FE model
  (computed here from the rule, not read from pmpm); this is the continuum a converged
  discretisation of that grid's points would reach;
* the implicit integrator (one static step; a dynamic run at ``--dt``) and the explicit one
  (MUSL, the case's CFL, FLIP), read at the particle the tracker follows (the FE probe is put
  at that particle's initial position).

A Galerkin solution with exact quadrature is stiffer than its continuum; the implicit static
solve is that Galerkin solution over the B-spline space with the points as the quadrature,
so a static drift above the banded FE model's means that the quadrature (4 points a cell
for bicubic shape functions) is too weak for the strip, not a wrong operator. The last line
printed is one JSON object.
"""
import argparse
import dataclasses
import json
import time

import numpy as np

__all__ = ["banded_members", "banded_fe", "main"]

TRACK = "upper_left_joint"


@dataclasses.dataclass(frozen=True)
class _Bands:
    edges: tuple        # band edges across the strip (from -d/2 to d/2)
    thickness: tuple    # per band


def row_thicknesses(member, spacing):
    """(band edges, thickness per band) of the point rows across ``member`` (a frame_fe_model
    Member) at a point spacing close to ``spacing``: the rule of docs/portal_frame.md section 1
    (a web part a tw and a flange part b bf per row, by the fraction of the row's band in each;
    (a, b) so that the rows' area and second moment are the section's A and I)."""
    n = max(1, int(round(member.depth / spacing)))
    dy = member.depth / n
    eta = -member.depth / 2 + (np.arange(n) + 0.5) * dy
    web_half = member.depth / 2 - member.tf
    in_web = np.clip(np.minimum(eta + dy / 2, web_half) - np.maximum(eta - dy / 2, -web_half), 0, None) / dy
    w_web, w_fl = in_web * member.tw, (1 - in_web) * member.bf
    M = np.array([[w_web.sum(), w_fl.sum()], [(w_web * eta ** 2).sum(), (w_fl * eta ** 2).sum()]]) * dy
    a, b = np.linalg.solve(M, [member.area, member.inertia])
    edges = -member.depth / 2 + np.arange(n + 1) * dy
    return edges, a * w_web + b * w_fl


def banded_fe(fem, cell, ppc=2, h0=0.05, level=1):
    """The FE model whose strips carry the point rows' thicknesses of a grid of ``cell``."""
    data = fem.read_scene()
    bands = {m.name: row_thicknesses(m, cell / ppc) for m in data.members}

    class BandedMember(fem.Member):
        def thickness(self, across):
            edges, t = bands[self.name]
            k = np.clip(np.searchsorted(edges, across) - 1, 0, len(t) - 1)
            return t[k]

    members = tuple(BandedMember(*dataclasses.astuple(m)) for m in data.members)
    data = dataclasses.replace(data, members=members)
    plain_breaks = fem._breaks

    def breaks(d):   # the band edges are element edges: one thickness per element
        xs, ys = plain_breaks(d)
        xs, ys = set(xs), set(ys)
        for m in d.members:
            across = (xs if m.vertical else ys)
            across |= {m.axis + e for e in bands[m.name][0]}
        merge = lambda v: np.array(sorted(v))[np.r_[True, np.diff(sorted(v)) > 1e-9]]  # noqa: E731
        return merge(xs), merge(ys)

    fem._breaks = breaks
    try:
        fe = fem.FrameFE(data, h0, level)
    finally:
        fem._breaks = plain_breaks
    return fe, bands


def fe_figures(fem, fe, cell, ppc=2, n_modes=40):
    """(static drift, first peak, its time) of ``fe`` at the particle a grid of ``cell`` tracks."""
    data = dataclasses.replace(fe.data, ppc=ppc)
    px, py = fem.mpm_track_point(data, cell)
    fe.probe = fe.basis.probes(np.array([[px], [py]]))
    _, static = fe.static()
    peak, at = fem.first_peak(fe, n_modes)
    return static, peak, at


def mpm_runs(cell, dt, t_end, ppc=2, dynamic=True):
    """Implicit static drift, implicit and explicit first peaks (and their wall times)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker
    from studies.accuracy_response import BASE, frame_scene, implicit_scene
    out = {}
    base = frame_scene(dataclasses.replace(BASE, cell=cell, ppc=ppc), t_end)
    static = implicit_scene(base, 1.0)
    static = dataclasses.replace(static, solver=dataclasses.replace(static.solver, analysis="static", end_time=1.0))
    runs = (("implicit_static", static),) + ((("implicit", implicit_scene(base, dt)), ("explicit", base))
                                             if dynamic else ())
    for name, scene in runs:
        s = build_solver(scene, MPI.COMM_SELF)
        tr = Tracker([t for t in scene.output.track if t.name == TRACK], s)
        u, t0 = [0.0], time.perf_counter()
        while s.t < scene.solver.end_time * (1 - 1e-12):
            s.step()
            u.append(float(tr.sample()[0, 0]))
        out[name] = {"drift_m": max(u), "wall_s": time.perf_counter() - t0, "steps": s.step_count}
    return out


def main(argv=None):
    from studies.frame_fe import fe_module
    ap = argparse.ArgumentParser(prog="python -m studies.implicit_coarse", description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=float, nargs="+", default=[0.1, 0.05])
    ap.add_argument("--dt", type=float, default=2.5e-4, help="the implicit run's step (s)")
    ap.add_argument("--t-end", type=float, default=0.03, help="past the first peak (s)")
    ap.add_argument("--ppc", type=int, default=2, help="particles per cell (each way)")
    ap.add_argument("--static-only", action="store_true", help="no dynamic runs")
    a = ap.parse_args(argv)
    fem = fe_module()
    rows = []
    w_fe = fem.frame_fe(0.05, 1)   # the W shapes' strips (cell-independent)
    for cell in a.cells:
        fe, bands = banded_fe(fem, cell, a.ppc)
        row = {"cell": cell, "ppc": a.ppc, "web_factor_column": float(bands["left_column"][1][len(bands["left_column"][1]) // 2]
                                                         / fe.data.members[0].tw)}
        row["fe_w_static_m"], row["fe_w_peak_m"], _ = fe_figures(fem, w_fe, cell, a.ppc)
        row["fe_rows_static_m"], row["fe_rows_peak_m"], _ = fe_figures(fem, fe, cell, a.ppc)
        runs = mpm_runs(cell, a.dt, a.t_end, a.ppc, not a.static_only)
        row.update({f"{k}_{q}": v[q] for k, v in runs.items() for q in ("drift_m", "wall_s")})
        rows.append(row)
        dyn = (f"  implicit first peak {1e3 * row['implicit_drift_m']:.2f} mm (dt {a.dt:g} s), explicit MUSL "
               f"{1e3 * row['explicit_drift_m']:.2f} mm\n" if not a.static_only else "")
        print(f"{cell:g} m cells, {a.ppc}x{a.ppc} points (column web {row['web_factor_column']:.2f} tw):\n"
              f"  FE, W-shape strips:        static {1e3 * row['fe_w_static_m']:.2f} mm, first peak {1e3 * row['fe_w_peak_m']:.2f} mm\n"
              f"  FE, this grid's point rows: static {1e3 * row['fe_rows_static_m']:.2f} mm, first peak {1e3 * row['fe_rows_peak_m']:.2f} mm\n"
              f"  implicit static {1e3 * row['implicit_static_drift_m']:.2f} mm\n" + dyn, end="", flush=True)
    print(json.dumps({"study": "implicit_coarse", "dt": a.dt, "t_end": a.t_end, "rows": rows}))


if __name__ == "__main__":
    main()
