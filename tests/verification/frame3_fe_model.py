"""Plane-stress continuum FE model of the strips of ``cases/frame_3storey.toml`` (multi-bay, nodal
masses, several loads), reusing frame_fe_model.py (portal) for the mesh, thickness rule and solvers.

How it mirrors the MPM scene
----------------------------
- Variant first, then expansion: like ``pmpm.scene.config`` (variant overrides, then
  ``parse_scene`` expands the ``[frame]``), the variant's ``materials.steel`` replaces the base
  material BEFORE ``pmpm.scene.frame.expand_frame`` runs, so the derived panel materials
  (``"steel+<node>"``) are copies of the elastic steel. expand_frame is used for geometry only.
- Bodies: every expanded i_section body, including the joint-panel strips that
  ``_nodal_masses`` splits off the column under each massed node (column depth by beam depth,
  from the panel's bottom to the column body's end). The expansion makes the bodies touch
  without overlapping (columns stop at the panel, beams at the column faces);
  frame_fe_model.build_mesh refuses an overlap, as the MPM's check_overlaps does.
- Nodal masses: as the MPM, density of the panel strip: rho_panel = rho (1 + m / (A L rho)),
  read from the expanded materials; the consistent mass matrix integrates rho_e t dA per
  element, so each panel carries exactly A L rho + m (the MPM's points carry the same total,
  their thickness rule matching A exactly).
- Supports: the expanded ``type = "fixed"`` boundary boxes, every FE node on y = 0 inside them.
- Loads: each ``loads.forces`` box (a joint panel) carries its total force shared by MASS among
  the elements whose centre lies in it (loads.assign shares by particle mass), i.e. a body
  force per unit mass; several boxes superpose. Loads are steps.
- Output points: the tracked nodes c0_f1, c0_f2, c0_f3, read at the MPM particle the tracker
  follows at ``track_cell`` (frame_fe_model.mpm_track_point, default 0.2 m cells).
- Material: linear elastic plane stress (E, nu of the variant), thickness per element from the
  W shape's A and I (frame_fe_model.Member.thickness).

Run: ``python tests/verification/frame3_fe_model.py`` (levels 0, 1, 2 at h0 = 0.2 m; prints the
periods table against frame2d_model, Richardson extrapolation, and the step responses).
"""
from __future__ import annotations

import math
import os
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from skfem import Basis, BilinearForm, ElementQuad2, ElementVector, LinearForm, asm
from skfem.helpers import ddot, dot, sym_grad, trace

sys.path.insert(0, os.path.dirname(__file__))
import frame_fe_model as fem  # noqa: E402

__all__ = ["Frame3Data", "read_scene3", "Frame3FE", "responses", "study", "SCENE3",
           "MODE2_PATTERN", "JOINTS"]

SCENE3 = Path(__file__).resolve().parents[2] / "cases" / "frame_3storey.toml"
JOINTS = ("c0_f1", "c0_f2", "c0_f3")
#: horizontal forces (N) at JOINTS orthogonal to frame2d_model's modes 1 and 3 there (continuous
#: joints; studies.frame_3storey.mode_pattern(frame_model(), 1))
MODE2_PATTERN = (-600000.0, -550564.21, 529176.39)


@dataclass(frozen=True)
class Frame3Data:
    """What the model takes from the expanded scene (``track``: the roof joint, a mesh break)."""
    members: tuple
    rho: tuple                 # density per member (body)
    E: float
    nu: float
    fixed_boxes: tuple
    loads: tuple               # ((lower, upper), (Fx, Fy), name) per force box
    tracks: dict               # node name -> (x, y)
    track: tuple
    cell_size: float
    ppc: int


def read_scene3(path=SCENE3, variant="elastic"):
    """Expanded scene data of a ``[frame]`` scene with masses and several loads (see module doc)."""
    from pmpm.scene.frame import expand_frame
    with open(path, "rb") as fh:
        s = tomllib.load(fh)
    over = s.get("variants", {}).get(variant, {})
    if "materials.steel" in over:          # dotted-key override replaces the table, as pmpm does
        s["materials"]["steel"] = dict(over["materials.steel"])
    s = expand_frame(s)
    mats = s["materials"]
    bodies = [b for b in s["bodies"] if b["shape"] == "i_section"]
    if len(bodies) != len(s["bodies"]):
        raise ValueError(f"{path}: only i_section bodies are modelled")
    for b in bodies:
        m = mats[b["material"]]
        if m["type"] != "linear_elastic":
            raise ValueError(f"{path}: {b['name']}: material {b['material']} is {m['type']}")
    E = {float(mats[b["material"]]["E"]) for b in bodies}
    nu = {float(mats[b["material"]]["nu"]) for b in bodies}
    if len(E) != 1 or len(nu) != 1:
        raise ValueError(f"{path}: one E and nu expected")
    members = tuple(fem.Member(b["name"], tuple(b["start"]), tuple(b["end"]), b["depth"],
                               b["flange_width"], b["flange_thickness"], b["web_thickness"],
                               b["area"], b["inertia"]) for b in bodies)
    rho = tuple(float(mats[b["material"]]["density"]) for b in bodies)
    fixed = tuple((tuple(b["lower"]), tuple(b["upper"])) for b in s["boundary"] if b["type"] == "fixed")
    loads = []
    for f in s.get("loads", {}).get("forces", []):
        if f.get("time_function", {}).get("type") != "step":
            raise ValueError(f"{path}: {f['name']}: the step response needs step loads")
        loads.append(((tuple(f["lower"]), tuple(f["upper"])), tuple(f["force"]), f["name"]))
    tracks = {t["name"]: tuple(t["point"]) for t in s["output"]["track"]}
    return Frame3Data(members, rho, E.pop(), nu.pop(), fixed, tuple(loads), tracks,
                      tracks[JOINTS[-1]], float(s["grid"]["cell_size"]), int(s.get("particles_per_cell", 2)))


class Frame3FE(fem.FrameFE):
    """Assembled model at one mesh; ``f`` is the scene's load (change with :meth:`set_forces`).

    Inherits static/modes/periods from frame_fe_model.FrameFE; ``probe`` is the roof joint's."""

    def __init__(self, data, h0=0.2, level=0, track_cell=0.2):
        self.data = data
        self.mesh, self.thickness = fem.build_mesh(data, h0, level)
        c = self.mesh.p[:, self.mesh.t].mean(axis=1)
        rho_e = np.full(c.shape[1], np.nan)
        for m, r in zip(data.members, data.rho):
            x0, x1, y0, y1 = m.box
            rho_e[(c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1)] = r
        assert np.all(np.isfinite(rho_e))
        self.basis = Basis(self.mesh, ElementVector(ElementQuad2()), intorder=4)
        nqp = self.basis.X.shape[1]
        t = np.repeat(self.thickness[:, None], nqp, axis=1)
        rq = np.repeat(rho_e[:, None], nqp, axis=1)
        E, nu = data.E, data.nu
        mu, lam = E / (2 * (1 + nu)), E * nu / (1 - nu ** 2)   # plane-stress Lame pair

        @BilinearForm
        def stiffness(u, v, w):
            eu, ev = sym_grad(u), sym_grad(v)
            return w["t"] * (2 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev))

        @BilinearForm
        def mass(u, v, w):
            return w["t"] * w["rho"] * dot(u, v)

        self.K = asm(stiffness, self.basis, t=t)
        self.M = asm(mass, self.basis, t=t, rho=rq)
        # per force box: the vectors of a unit total force in x and in y, shared by mass
        self.unit = []
        for (lo, hi), _, _ in data.loads:
            box = ((c[0] >= lo[0]) & (c[0] <= hi[0]) & (c[1] >= lo[1]) & (c[1] <= hi[1])).astype(float)
            wb = np.repeat(box[:, None], nqp, axis=1)
            mbox = float(np.sum(t * rq * wb * self.basis.dx))

            @LinearForm
            def fx(v, w):
                return w["t"] * w["rho"] * w["box"] * v[0] / mbox

            @LinearForm
            def fy(v, w):
                return w["t"] * w["rho"] * w["box"] * v[1] / mbox

            self.unit.append((asm(fx, self.basis, t=t, rho=rq, box=wb),
                              asm(fy, self.basis, t=t, rho=rq, box=wb)))
        self.set_forces([f for _, f, _ in data.loads])
        self.fixed = self._fixed_dofs()
        self.free = np.setdiff1d(np.arange(self.basis.N), self.fixed)
        pts = np.array([fem.mpm_track_point(_at(data, n), track_cell) for n in JOINTS]).T
        import scipy.sparse as sp
        self.probes = sp.vstack([self.basis.probes(pts[:, k:k + 1]).tocsr()[0] for k in range(pts.shape[1])]).tocsr()
        self.probe = self.basis.probes(pts[:, -1:])          # the roof (FrameFE.static reads it)
        self._modes = None

    def set_forces(self, forces):
        """Total (Fx, Fy) per force box, in the scene's order."""
        self.f = sum(fx * gx + fy * gy for (gx, gy), (fx, fy) in zip(self.unit, forces))


def _at(data, node):
    """The data with ``track`` moved to ``node`` (mpm_track_point reads data.track)."""
    import dataclasses
    return dataclasses.replace(data, track=data.tracks[node])


def responses(fe, t, n_modes=40):
    """Undamped step response of ux at JOINTS (rows), mode-acceleration form (see frame_fe_model)."""
    u = np.zeros(fe.basis.N)
    K = fe.K[fe.free][:, fe.free].tocsc()
    import scipy.sparse.linalg as spla
    u[fe.free] = spla.spsolve(K, fe.f[fe.free])
    omega, phi = fe.modes(n_modes)
    q = (phi.T @ fe.f) / omega ** 2
    at = fe.probes @ phi                                   # (3, n_modes)
    return (fe.probes @ u)[:, None] - (at * q) @ np.cos(np.outer(omega, t)), fe.probes @ u, at * q


def _frame_model(path, pattern=None):
    import frame2d_model as f2d
    fm = f2d.from_scene(str(path))
    T, _, _, _ = fm.modes(3)
    if pattern is not None:
        fm.F[:] = 0
        for n, F in zip(JOINTS, pattern):
            fm.add_nodal_force(n, (F, 0.0))
    return fm, T


def study(levels=(0, 1, 2), h0=0.2, n_modes=40, path=SCENE3, t_end=1.5, dt=5e-4):
    """Periods per level with Richardson extrapolation, and the step responses; prints a table."""
    data = read_scene3(path)
    fm, Tf = _frame_model(path)
    print(f"frame2d_model: T1 {Tf[0]:.4f}  T2 {Tf[1]:.4f}  T3 {Tf[2]:.4f} s")
    print(f"{'level':>5} {'h':>6} {'dofs':>8} {'T1':>8} {'T2':>8} {'T3':>8} "
          f"{'T1/Tf':>7} {'T2/Tf':>7} {'T3/Tf':>7} {'s':>5}")
    rows, fes = [], []
    for lev in levels:
        t0 = time.time()
        fe = Frame3FE(data, h0, lev)
        T = fe.periods(3)
        rows.append(T)
        fes.append(fe)
        print(f"{lev:>5} {h0 / 2 ** lev:>6.3f} {fe.ndofs:>8} {T[0]:>8.4f} {T[1]:>8.4f} {T[2]:>8.4f} "
              f"{T[0] / Tf[0]:>7.4f} {T[1] / Tf[1]:>7.4f} {T[2] / Tf[2]:>7.4f} {time.time() - t0:>5.0f}")
    rows = np.array(rows)
    rich = [fem.richardson(rows[:, k]) for k in range(3)]
    print("Richardson " + "  ".join(f"T{k + 1} {v:.4f} (p {p:.2f}, err {e:.1e}, /Tf {v / Tf[k]:.4f})"
                                    for k, (v, p, e) in enumerate(rich)))
    fe = fes[-1]
    print(f"total mass FE {fe.total_mass():.4e} kg")
    t = np.arange(0.0, t_end + dt / 2, dt)
    for label, pattern in (("case loads", None), ("mode-2 pattern", MODE2_PATTERN)):
        if pattern is not None:
            fe.set_forces([(F, 0.0) for F in pattern])
            fm, _ = _frame_model(path, pattern)
        u, us, part = responses(fe, t, n_modes)
        roof = u[-1]
        ff = np.array([fm.step_response(t, fm.node_dofs[n][0]) for n in JOINTS])
        early = t < 0.66
        print(f"-- {label}: static ux at {JOINTS}: FE {np.round(us, 5)}, frame {np.round(fm.static()[[fm.node_dofs[n][0] for n in JOINTS]], 5)}")
        print(f"   roof first peak (t < 0.66 s): FE {roof[early].max():.5f} m at {t[early][roof[early].argmax()]:.3f} s; "
              f"frame {ff[-1][early].max():.5f} m at {t[early][ff[-1][early].argmax()]:.3f} s")
        print(f"   roof largest over {t_end} s: FE {np.abs(roof).max():.5f} m, frame {np.abs(ff[-1]).max():.5f} m")
        share = np.abs(part[-1, :3]) / np.abs(part[-1]).sum()
        print(f"   roof's dynamic amplitude share of FE modes 1-3: {np.round(share, 4)}")
    fe.set_forces([f for _, f, _ in data.loads])
    return {"levels": list(levels), "periods": rows, "richardson": rich, "frame": Tf}


def stiff_panel_periods(data, h0=0.2, level=1, factor=100.0, n=3):
    """Periods with the joint-panel strips' stiffness multiplied by ``factor`` (a diagnostic:
    near-rigid panels, to compare with frame2d_model's ``joints="rigid"``)."""
    fe = Frame3FE(data, h0, level)
    c = fe.mesh.p[:, fe.mesh.t].mean(axis=1)
    stiff = np.zeros(c.shape[1], bool)
    for m in data.members:
        if "_panel_" in m.name:
            x0, x1, y0, y1 = m.box
            stiff |= (c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1)
    nqp = fe.basis.X.shape[1]
    t = np.repeat((fe.thickness * np.where(stiff, factor, 1.0))[:, None], nqp, axis=1)
    mu, lam = data.E / (2 * (1 + data.nu)), data.E * data.nu / (1 - data.nu ** 2)

    @BilinearForm
    def stiffness(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return w["t"] * (2 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev))

    fe.K = asm(stiffness, fe.basis, t=t)   # the mass matrix keeps the true thickness
    fe._modes = None
    return fe.periods(n)


if __name__ == "__main__":
    study()
    import frame2d_model as f2d
    print("panels x100 stiffer, level 1:", np.round(stiff_panel_periods(read_scene3()), 4),
          "| frame2d_model joints='rigid':", np.round(f2d.from_scene(str(SCENE3), joints="rigid").modes(3)[0], 4))
