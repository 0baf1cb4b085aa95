"""Why the implicit portal is soft at 2 x 2 points a cell (issue 37, docs/implicit.md, "The points
as the quadrature of the strips"): the Galerkin stiffness the implicit step assembles, with the
material points as its quadrature, against the same cubic B-spline space integrated (nearly)
exactly, on one member strip at a time.

    python -m studies.implicit_quadrature [--cell 0.05] [--ppc 2] [--sub 8] [--modes]

Each member of the portal (cases/portal_pushover.toml: W12x120 columns, W16x36 beam) is set up as
a clamped cantilever strip 3.7 m long with its own points (pmpm.scene.bodies' I-section rows and
thicknesses), its axis at the offset from a grid line that the portal's member has (left column
0, right column -0.004 m, beam +0.008 m at 0.05 m cells; ``--offsets`` for others), linear
elastic plane stress (E = 207 GPa, nu = 0.3), pushed sideways by 100 kN spread over the points
of its top cell row. Printed per strip: the top's drift with

* the points as the quadrature (what the implicit step assembles: sum_p V_p B_p^T D B_p with the
  cubic B-splines of pmpm.core.kernels.reference, the nodes of the mass-cutoff rule);
* every point's band split into ``--sub`` rows across the strip (same thickness, same total
  volume: the band continuum the points stand for, integrated nearly exactly across the depth);
* the same split along the strip instead (``--sub`` columns);
* the points again, with the outermost node columns (fill below ``--fill``: the sum of a node's
  weights at the points over the points a full cell holds) slaved to their two inward neighbours
  by linear extrapolation, u_o = 2 u_(o+e) - u_(o+2e) (an extended B-spline of degree one, as
  pmpm's own boundary modification at the grid's edges), and the exact-across rule in that space.

``--modes`` also solves K_points phi = lambda K_exact phi on a 1 m strip and prints where the
softest modes live (share of their energy by node column, and that column's fill).
Prints a table and one JSON line. NumPy and SciPy only (no numba, no PETSc): a few seconds a strip.
"""
import argparse
import json

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

from pmpm.core.kernels.reference import bspline_1d
from pmpm.scene.bodies import _i_section

__all__ = ["SECTIONS", "Strip", "point_stiffness", "strip_drift", "split_points", "edge_extension", "main"]

E, NU = 207e9, 0.3
D = E / (1 - NU ** 2) * np.array([[1.0, NU, 0.0], [NU, 1.0, 0.0], [0.0, 0.0, (1 - NU) / 2]])
#: the portal's members (cases/portal_pushover.toml) and their axes' offsets from the nearest
#: grid line at 0.05 m cells (grid origin x = -0.5: left column 0.0, right column 6.096; beam
#: axis y = 3.658)
SECTIONS = {
    "left column": (dict(depth=0.33325, flange_width=0.31293, flange_thickness=0.028067, web_thickness=0.018034,
                         area=0.022774, inertia=4.4537e-4), 0.0),
    "right column": (dict(depth=0.33325, flange_width=0.31293, flange_thickness=0.028067, web_thickness=0.018034,
                          area=0.022774, inertia=4.4537e-4), -0.004),
    "beam": (dict(depth=0.40284, flange_width=0.17742, flange_thickness=0.010922, web_thickness=0.007493,
                  area=0.0068387, inertia=1.8647e-4), 0.008),
}
LOAD = 1e5
MASS_CUTOFF = 1e-8   # solver.mass_cutoff's default, times the largest point's share


class _Grid:
    def __init__(self, h, cells, origin=(-0.5, 0.0)):
        self.h, self.cells, self.origin = h, tuple(cells), np.asarray(origin, float)
        self.shape = (cells[0] + 1, cells[1] + 1)
        self.nodes = self.shape[0] * self.shape[1]


class Strip:
    """A clamped vertical strip of ``section`` with its axis at x = ``offset`` (grid origin -0.5 m,
    so a grid line passes through x = 0), ``length`` high, base on the grid's lower edge."""

    def __init__(self, section, offset, h=0.05, ppc=2, length=3.7):
        self.grid = _Grid(h, (int(round(1.0 / h)), int(round((length + 0.5) / h))))
        geo = dict(section, start=[offset, 0.0], end=[offset, length])
        self.x, area, thickness = _i_section(geo, self.grid, ppc, "strip")
        self.vol = area * thickness
        self.rows = len(np.unique(np.round(self.x[:, 0], 9)))
        self.spacing = (section["depth"] / self.rows, length / len(np.unique(np.round(self.x[:, 1], 9))))
        self.ppc, self.length = ppc, length
        self.top = self.x[:, 1] > self.x[:, 1].max() - 0.999 * h

    def fill(self):
        """Per node: the sum of its weights at the points over ppc^2 (about 1 inside the body)."""
        return nodal(self.grid, self.x, np.full(len(self.x), 1.0 / self.ppc ** 2))


def _stencils(grid, x):
    """(nodes (P, 16), N (P, 16), dN/dx, dN/dy) of the cubic B-splines (pmpm.core.kernels.reference)."""
    s = (x - grid.origin) / grid.h
    out = []
    for axis in (0, 1):
        w, g = bspline_1d(3, s[:, axis], grid.cells[axis])
        first = np.clip(np.argmax((w != 0) | (g != 0), axis=1), 0, grid.cells[axis] - 3)
        idx = first[:, None] + np.arange(4)
        out.append((idx, np.take_along_axis(w, idx, 1), np.take_along_axis(g, idx, 1) / grid.h))
    (ix, wx, gx), (iy, wy, gy) = out
    nodes = (ix[:, :, None] * grid.shape[1] + iy[:, None, :]).reshape(len(x), 16)
    N = (wx[:, :, None] * wy[:, None, :]).reshape(len(x), 16)
    dX = (gx[:, :, None] * wy[:, None, :]).reshape(len(x), 16)
    dY = (wx[:, :, None] * gy[:, None, :]).reshape(len(x), 16)
    return nodes, N, dX, dY


def nodal(grid, x, values):
    """sum_p N_I(x_p) values_p on every node (flattened, node = i ny + j)."""
    nodes, N, _, _ = _stencils(grid, x)
    out = np.zeros(grid.nodes)
    np.add.at(out, nodes.ravel(), (N * values[:, None]).ravel())
    return out


def point_stiffness(grid, x, vol, chunk=4000):
    """sum_p V_p B_p^T D B_p (small strain: the implicit tangent at f = I, S = 0), sparse, dof 2 node + a."""
    K = sp.csr_matrix((2 * grid.nodes, 2 * grid.nodes))
    for a in range(0, len(x), chunk):
        nodes, _, dX, dY = _stencils(grid, x[a:a + chunk])
        P = len(nodes)
        B = np.zeros((P, 3, 32))
        B[:, 0, 0::2], B[:, 1, 1::2], B[:, 2, 0::2], B[:, 2, 1::2] = dX, dY, dY, dX
        k = np.einsum("p,pra,rs,psb->pab", vol[a:a + chunk], B, D, B)
        dof = np.empty((P, 32), np.int64)
        dof[:, 0::2], dof[:, 1::2] = 2 * nodes, 2 * nodes + 1
        rows = np.broadcast_to(dof[:, :, None], k.shape)
        cols = np.broadcast_to(dof[:, None, :], k.shape)
        K = K + sp.csr_matrix((k.ravel(), (rows.ravel(), cols.ravel())), shape=K.shape)
    return K


def split_points(strip, sub, across=True):
    """Each point's band split into ``sub`` equal parts across (or along) the strip."""
    o = ((np.arange(sub) + 0.5) / sub - 0.5) * strip.spacing[0 if across else 1]
    off = np.zeros((sub, 2))
    off[:, 0 if across else 1] = o
    return (strip.x[:, None, :] + off[None]).reshape(-1, 2), np.repeat(strip.vol / sub, sub)


def edge_extension(strip, active, fill_below):
    """The map T (all dofs x all dofs) slaving every active node with fill below ``fill_below``
    to its two inward neighbours across the strip (u_o = 2 u_(o+e) - u_(o+2e)), where both
    have more; identity elsewhere. Returns (T, number of slaved nodes)."""
    g, phi = strip.grid, strip.fill()
    ny = g.shape[1]
    target = np.arange(g.nodes)
    slaved = []
    for n in np.nonzero(active & (phi < fill_below))[0]:
        for e in (1, -1):
            a, b = n + e * ny, n + 2 * e * ny
            if 0 <= min(a, b) and max(a, b) < g.nodes and phi[a] >= fill_below and phi[b] >= fill_below:
                slaved.append((n, a, b))
                break
    rows, cols, vals = [], [], []
    slaved_set = {n for n, _, _ in slaved}
    for n in target[~np.isin(target, list(slaved_set))]:
        rows += [2 * n, 2 * n + 1]
        cols += [2 * n, 2 * n + 1]
        vals += [1.0, 1.0]
    for n, a, b in slaved:
        for c in range(2):
            rows += [2 * n + c, 2 * n + c]
            cols += [2 * a + c, 2 * b + c]
            vals += [2.0, -1.0]
    return sp.csr_matrix((vals, (rows, cols)), shape=(2 * g.nodes, 2 * g.nodes)), len(slaved)


def _active(strip, x, vol):
    return nodal(strip.grid, x, vol) > MASS_CUTOFF * vol.max()


def strip_drift(strip, K, active, T=None):
    """The top points' mean sideways drift under the load (dense solve; base row clamped)."""
    g = strip.grid
    free = np.repeat(active & (np.arange(g.nodes) % g.shape[1] > 0), 2)
    f = np.zeros(2 * g.nodes)
    f[0::2] = nodal(g, strip.x[strip.top], np.full(strip.top.sum(), LOAD / strip.top.sum()))
    T = sp.identity(2 * g.nodes, format="csr") if T is None else T
    cols = np.nonzero(free & (np.asarray(abs(T).sum(axis=0)).ravel() > 0))[0]
    Tc = T[:, cols]
    u = Tc @ np.linalg.solve((Tc.T @ K @ Tc).toarray(), Tc.T @ f)
    nodes, N, _, _ = _stencils(g, strip.x[strip.top])
    return float((N * u[2 * nodes]).sum(axis=1).mean())


def strip_row(name, section, offset, h, ppc, sub, fill_below):
    s = Strip(section, offset, h, ppc)
    act = _active(s, s.x, s.vol)
    K = point_stiffness(s.grid, s.x, s.vol)
    xa, va = split_points(s, sub, across=True)
    act_a = _active(s, xa, va)       # the band continuum reaches nodes the points do not
    K_across = point_stiffness(s.grid, xa, va)
    xl, vl = split_points(s, sub, across=False)
    K_along = point_stiffness(s.grid, xl, vl)
    T, slaved = edge_extension(s, act, fill_below)
    d = {"points": strip_drift(s, K, act), "exact_across": strip_drift(s, K_across, act_a),
         "exact_along": strip_drift(s, K_along, _active(s, xl, vl)),
         "points_extended": strip_drift(s, K, act, T), "exact_across_extended": strip_drift(s, K_across, act_a, T)}
    EI = E * section["inertia"]
    d["euler_bernoulli"] = LOAD * (s.length - h / 2) ** 3 / (3 * EI)
    return {"member": name, "offset": offset, "cell": h, "ppc": ppc, "rows": s.rows, "slaved_nodes": slaved,
            "drift_mm": {k: 1e3 * v for k, v in d.items()},
            "points_over_exact": d["points"] / d["exact_across"],
            "extended_over_exact": d["points_extended"] / d["exact_across"],
            "extended_space_over_exact": d["exact_across_extended"] / d["exact_across"]}


def soft_modes(section, offset, h, ppc, sub, count=6):
    """The softest modes of K_points against K_exact-across on a 1 m strip: (lambda, {node
    column: share of the mode's exact energy}), and the fill of every node column at mid-height."""
    s = Strip(section, offset, h, ppc, length=1.0)
    g = s.grid
    ny = g.shape[1]
    xa, va = split_points(s, sub)
    act = _active(s, s.x, s.vol)
    free = np.nonzero(np.repeat(act & (np.arange(g.nodes) % ny > 0), 2))[0]
    K1 = point_stiffness(g, s.x, s.vol)[free][:, free].toarray()
    K8 = point_stiffness(g, xa, va)[free][:, free].toarray()
    lam, phi = sl.eigh(K1, K8)
    column = (free // 2) // ny
    modes = []
    for k in range(count):
        e = phi[:, k] * (K8 @ phi[:, k])
        share = np.bincount(column, weights=e, minlength=g.shape[0]) / e.sum()
        modes.append((float(lam[k]), {int(c): round(float(share[c]), 2) for c in np.nonzero(np.abs(share) > 0.05)[0]}))
    fill = s.fill().reshape(g.shape)[:, ny // 2]
    return {"lambda_below_half": int(np.sum(lam < 0.5)), "dofs": len(lam), "modes": modes,
            "fill": {int(c): round(float(fill[c]), 5) for c in np.nonzero(fill > 0)[0]}}


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.implicit_quadrature", description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--ppc", type=int, default=2)
    ap.add_argument("--sub", type=int, default=8, help="parts each point's band is split into")
    ap.add_argument("--fill", type=float, default=0.01, help="slave the node columns whose fill is below this")
    ap.add_argument("--offsets", type=float, nargs="*", default=None,
                    help="the column's offsets from a grid line (m) instead of the portal's three members")
    ap.add_argument("--modes", action="store_true")
    a = ap.parse_args(argv)
    cases = [(n, sec, off) for n, (sec, off) in SECTIONS.items()] if a.offsets is None else \
        [(f"column at {o:+g} m", SECTIONS["left column"][0], o) for o in a.offsets]
    rows = []
    print("| member | offset (m) | rows | drift, points (mm) | exact across | exact along | points / exact | "
          "points, edge nodes slaved / exact | slaved nodes | slaved space, exact / exact |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, sec, off in cases:
        r = strip_row(name, sec, off, a.cell, a.ppc, a.sub, a.fill)
        d = r["drift_mm"]
        print(f"| {name} | {off:+.4f} | {r['rows']} | {d['points']:.3f} | {d['exact_across']:.3f} | "
              f"{d['exact_along']:.3f} | {r['points_over_exact']:.4f} | {r['extended_over_exact']:.4f} | "
              f"{r['slaved_nodes']} | {r['extended_space_over_exact']:.4f} |", flush=True)
        if a.modes:
            r["soft_modes"] = soft_modes(sec, off, a.cell, a.ppc, a.sub)
            m = r["soft_modes"]
            print(f"    softest modes (lambda = points / exact energy; {m['lambda_below_half']} of {m['dofs']} "
                  f"below 0.5): " + "; ".join(f"{lam:.2g} at columns {cols}" for lam, cols in m["modes"][:4])
                  + f"; fill by node column {m['fill']}", flush=True)
        rows.append(r)
    print(json.dumps({"study": "implicit_quadrature", "cell": a.cell, "ppc": a.ppc, "sub": a.sub, "rows": rows}))


if __name__ == "__main__":
    main()
