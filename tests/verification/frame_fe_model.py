"""Independent plane-stress finite-element model of the portal frame's strips (issue 11, item 1).

The MPM run (``cases/portal_frame.toml``) models each member as a plane-stress strip of depth d
whose out-of-plane thickness is the flange width bf in the flanges and the web thickness tw in the
web, scaled so the strip's area and second moment equal the W shape's A and I. This module models
the SAME continuum with quadratic finite elements (scikit-fem, 9-node Lagrange quadrilaterals,
exact Gauss quadrature), so the MPM can be checked against a model that shares no code with it:
it reads the scene TOML for the data (bodies, material of the ``elastic`` variant, fixed boxes,
load box, tracked point) and imports nothing from pmpm.

What the model is, and how it mirrors the scene
------------------------------------------------
- Domain: the union of the members' rectangles (axis-aligned strips start -> end of width
  ``depth``). The columns run from y = 0 to the beam's top; the beam spans between the column
  faces, so the joint panel is column material. The strips are one connected body: in the MPM
  they share one grid, so they are bonded where they touch.
- Thickness per element (constant inside an element; element edges lie on the flange/web lines):
  a tw in the web, b bf in the flanges, with (a, b) solving the two conditions
  ``int t dA / L = A`` and ``int t eta^2 dA / L = I`` exactly (the MPM solves the same two
  conditions with its point quadrature, ``pmpm/scene/bodies.py``; both tend to the same (a, b) as
  the particle rows refine).
- Supports: every node on y = 0 inside a ``type = "fixed"`` box is fixed in x and y (the MPM
  fixes the grid nodes of the ground line there).
- Load: the scene's force box is a set of particles sharing the total force by mass; here the
  elements whose centre lies in the box carry the same total force as a body force per unit mass
  (uniform density, so shared by volume rho t dA). For the frame this is the left column's joint
  panel, d_c by d_b.
- Material: linear elastic plane stress, E, nu, rho of the scene's ``elastic`` variant.
- Output point: the scene's tracked point ``upper_left_joint`` is followed in the MPM by the
  particle nearest to it (initial position); :func:`mpm_track_point` reproduces that particle's
  position for a given MPM grid, and the FE displacement is interpolated there.

Analyses
--------
- static: K u = f, drift = ux at the output point (lateral stiffness P / drift);
- modes: K phi = omega^2 M phi with the consistent mass (shift-invert Lanczos, scipy);
- step response: the mode-acceleration form of modal superposition,
  u(t) = u_static - sum_i phi_i (phi_i^T f / omega_i^2) cos(omega_i t) (mass-normalised phi_i),
  which is exact at t = 0 and at the static limit whatever the number of modes kept (the static
  correction carries the truncated modes quasi-statically); undamped.

Refinement: a tensor-product mesh whose cells between consecutive break lines (member edges,
flange lines, column axes, the output point) are split into ``n_i * 2**level`` equal parts, so the
meshes are nested and Richardson extrapolation applies (:func:`refinement_study`).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm, ElementQuad2, ElementVector, LinearForm, MeshQuad, asm
from skfem.helpers import ddot, dot, sym_grad, trace

__all__ = ["FrameData", "read_scene", "build_mesh", "FrameFE", "frame_fe", "step_response",
           "first_peak", "peak_and_period", "richardson", "refinement_study", "mpm_track_point",
           "Member", "SCENE"]

SCENE = Path(__file__).resolve().parents[2] / "cases" / "portal_frame.toml"
#: the cell size of the MPM runs the tests compare with (frame_runs.TEST_CELL); the probe sits
#: at the particle their tracker follows
TEST_CELL = 0.05


@dataclass(frozen=True)
class Member:
    """One axis-aligned I-section strip of the scene."""
    name: str
    start: tuple
    end: tuple
    depth: float
    bf: float
    tf: float
    tw: float
    area: float
    inertia: float

    @property
    def vertical(self):
        return abs(self.end[0] - self.start[0]) < 1e-12

    @property
    def box(self):
        """(x0, x1, y0, y1) of the strip's rectangle."""
        (xa, ya), (xb, yb), h = self.start, self.end, self.depth / 2
        if self.vertical:
            return (xa - h, xa + h, min(ya, yb), max(ya, yb))
        return (min(xa, xb), max(xa, xb), ya - h, ya + h)

    @property
    def axis(self):
        """Coordinate of the centre line across the strip (x of a column, y of a beam)."""
        return self.start[0] if self.vertical else self.start[1]

    def scale_factors(self):
        """(a, b): web and flange thickness factors giving the strip exactly A and I."""
        d, tf = self.depth, self.tf
        hw = d - 2 * tf
        area = np.array([self.tw * hw, 2 * self.bf * tf])
        second = np.array([self.tw * hw ** 3 / 12, self.bf * (d ** 3 - hw ** 3) / 12])
        return tuple(np.linalg.solve(np.array([area, second]), [self.area, self.inertia]))

    def thickness(self, across):
        """Out-of-plane thickness at signed distance ``across`` from the centre line."""
        a, b = self.scale_factors()
        in_flange = np.abs(across) > self.depth / 2 - self.tf
        return np.where(in_flange, b * self.bf, a * self.tw)


@dataclass(frozen=True)
class FrameData:
    """What the FE model takes from the scene."""
    members: tuple
    E: float
    nu: float
    rho: float
    fixed_boxes: tuple                 # ((x0, y0), (x1, y1)) per fixed boundary
    load_box: tuple                    # ((x0, y0), (x1, y1))
    load: tuple                        # (Fx, Fy), a step at t = 0
    track: tuple                       # the tracked point (x, y)
    cell_size: float                   # the MPM grid's cell size and particles per cell
    ppc: int


def read_scene(path=SCENE, variant="elastic", track="upper_left_joint"):
    """Read the frame's data from a scene TOML (data only: nothing in it is evaluated).

    Parameters
    ----------
    path : path-like
        The scene file (default ``cases/portal_frame.toml``).
    variant : str
        The variant whose ``materials.steel`` replaces the base material.
    track : str
        Name of the ``[[output.track]]`` point where the drift is read.

    Returns
    -------
    FrameData
    """
    with open(path, "rb") as fh:
        s = tomllib.load(fh)
    # written as a frame: read the strips pmpm's expansion generates (geometry only, no solver
    # code; test_frame_frontend.py checks that they are the hand-written scene's strips)
    if "frame" in s:
        from pmpm.scene.frame import expand_frame
        s = expand_frame(s)
    mat = dict(s["materials"]["steel"])
    mat.update(s.get("variants", {}).get(variant, {}).get("materials.steel", {}))
    if mat["type"] != "linear_elastic":
        raise ValueError(f"{path}: the FE model is linear elastic, variant {variant!r} is {mat['type']}")
    members = tuple(Member(b["name"], tuple(b["start"]), tuple(b["end"]), b["depth"],
                           b["flange_width"], b["flange_thickness"], b["web_thickness"],
                           b["area"], b["inertia"]) for b in s["bodies"])
    for m in members:
        if not (m.vertical or abs(m.end[1] - m.start[1]) < 1e-12):
            raise ValueError(f"{path}: {m.name}: only axis-aligned members are modelled")
    fixed = tuple((tuple(b["lower"]), tuple(b["upper"])) for b in s["boundary"] if b["type"] == "fixed")
    (force,) = s["loads"]["forces"]
    if force.get("time_function", {}).get("type") != "step":
        raise ValueError(f"{path}: the FE step response needs a step load")
    point = next(t["point"] for t in s["output"]["track"] if t["name"] == track)
    return FrameData(members, float(mat["E"]), float(mat["nu"]), float(mat["density"]), fixed,
                     (tuple(force["lower"]), tuple(force["upper"])), tuple(force["force"]),
                     tuple(point), float(s["grid"]["cell_size"]), int(s.get("particles_per_cell", 2)))


def mpm_track_point(data, cell_size=None):
    """Initial position of the MPM particle the Tracker follows (nearest to the track point).

    Reproduces the I-section lattice of ``pmpm/scene/bodies.py`` (cell-centred, spacing close to
    h / ppc along and across each strip) without importing it, so the FE displacement can be read
    at the very point the MPM reports.
    """
    h = (cell_size or data.cell_size) / data.ppc
    best, point = np.inf, None
    for m in data.members:
        length = math.dist(m.start, m.end)
        n_along, n_across = max(1, round(length / h)), max(1, round(m.depth / h))
        s = (np.arange(n_along) + 0.5) * length / n_along
        e = -m.depth / 2 + (np.arange(n_across) + 0.5) * m.depth / n_across
        S, Eta = np.meshgrid(s, e, indexing="ij")
        d = (np.subtract(m.end, m.start)) / length
        nrm = np.array([-d[1], d[0]])
        pts = np.asarray(m.start) + S.ravel()[:, None] * d + Eta.ravel()[:, None] * nrm
        k = np.argmin(np.sum((pts - data.track) ** 2, axis=1))
        dist = np.sum((pts[k] - data.track) ** 2)
        if dist < best:
            best, point = dist, pts[k]
    return tuple(point)


def _breaks(data):
    """Sorted break lines in x and y: member edges, flange lines, centre lines, the track point."""
    xs, ys = set(), set()
    for m in data.members:
        x0, x1, y0, y1 = m.box
        xs |= {x0, x1}
        ys |= {y0, y1}
        across = xs if m.vertical else ys
        across |= {m.axis, m.axis - m.depth / 2 + m.tf, m.axis + m.depth / 2 - m.tf}
    xs.add(data.track[0])
    ys.add(data.track[1])
    merge = lambda v: np.array(sorted(v))[np.r_[True, np.diff(sorted(v)) > 1e-9]]  # noqa: E731
    return merge(xs), merge(ys)


def _subdivide(breaks, h0, level):
    """Each interval cut into ceil(length / h0) * 2**level equal parts (nested in level)."""
    out = [breaks[:1]]
    for a, b in zip(breaks[:-1], breaks[1:]):
        n = max(1, math.ceil((b - a) / h0 - 1e-9)) * 2 ** level
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


def build_mesh(data, h0=0.1, level=0):
    """Quadrilateral mesh of the strips and each element's thickness.

    Parameters
    ----------
    data : FrameData
    h0 : float
        Largest element edge at level 0.
    level : int
        Uniform refinements (each halves every element edge).

    Returns
    -------
    mesh : skfem.MeshQuad
    thickness : numpy.ndarray
        Per element.
    """
    bx, by = _breaks(data)
    x, y = _subdivide(bx, h0, level), _subdivide(by, h0, level)
    mesh = MeshQuad.init_tensor(x, y)
    c = mesh.p[:, mesh.t].mean(axis=1)                       # element centres (2, nelems)
    owner = np.full(c.shape[1], -1)
    for k, m in enumerate(data.members):
        x0, x1, y0, y1 = m.box
        inside = (c[0] > x0) & (c[0] < x1) & (c[1] > y0) & (c[1] < y1)
        if np.any(inside & (owner >= 0)):
            raise ValueError(f"{m.name} overlaps another member (the MPM would double its mass)")
        owner[inside] = k
    keep = owner >= 0
    mesh = mesh.remove_elements(np.nonzero(~keep)[0])
    c, owner = c[:, keep], owner[keep]
    thickness = np.empty(len(owner))
    for k, m in enumerate(data.members):
        sel = owner == k
        across = (c[0, sel] if m.vertical else c[1, sel]) - m.axis
        thickness[sel] = m.thickness(across)
    return mesh, thickness


class FrameFE:
    """Assembled plane-stress model of the frame at one mesh.

    Parameters
    ----------
    data : FrameData
    h0, level : float, int
        Mesh (see :func:`build_mesh`).
    """

    def __init__(self, data, h0=0.1, level=0):
        self.data = data
        self.mesh, self.thickness = build_mesh(data, h0, level)
        self.basis = Basis(self.mesh, ElementVector(ElementQuad2()), intorder=4)
        nqp = self.basis.X.shape[1]
        t = np.repeat(self.thickness[:, None], nqp, axis=1)
        E, nu, rho = data.E, data.nu, data.rho
        mu, lam = E / (2 * (1 + nu)), E * nu / (1 - nu ** 2)    # plane-stress Lame pair

        @BilinearForm
        def stiffness(u, v, w):
            eu, ev = sym_grad(u), sym_grad(v)
            return w["t"] * (2 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev))

        @BilinearForm
        def mass(u, v, w):
            return w["t"] * rho * dot(u, v)

        self.K = asm(stiffness, self.basis, t=t)
        self.M = asm(mass, self.basis, t=t)
        self.f = self._load_vector(t)
        self.fixed = self._fixed_dofs()
        self.free = np.setdiff1d(np.arange(self.basis.N), self.fixed)
        # the particle the frame tests' runs track (their cell size, frame_runs.TEST_CELL)
        px, py = mpm_track_point(data, TEST_CELL)
        self.probe = self.basis.probes(np.array([[px], [py]]))  # rows: ux, uy at the point
        self._modes = None

    @property
    def ndofs(self):
        return len(self.free)

    def _load_vector(self, t):
        (x0, y0), (x1, y1) = self.data.load_box
        c = self.mesh.p[:, self.mesh.t].mean(axis=1)
        in_box = ((c[0] >= x0) & (c[0] <= x1) & (c[1] >= y0) & (c[1] <= y1)).astype(float)
        w_box = np.repeat(in_box[:, None], t.shape[1], axis=1)
        volume = float(np.sum(t * w_box * self.basis.dx))   # int over the box of t dA (m^3)
        fx, fy = self.data.load
        self.load_volume = volume

        @LinearForm
        def body_force(v, w):
            return w["t"] * w["box"] * (fx * v[0] + fy * v[1]) / volume

        return asm(body_force, self.basis, t=t, box=w_box)

    def _fixed_dofs(self):
        dofs = []
        for (x0, y0), (x1, y1) in self.data.fixed_boxes:
            if (x0, y0) == (x1, y1):
                # a point (a pin, pmpm's frame front end: the grid node nearest the member
                # axis): the mesh vertex nearest to it, which lies on the member's axis
                p = self.basis.mesh.p
                k = int(np.argmin((p[0] - x0) ** 2 + (p[1] - y0) ** 2))
                dofs.append(self.basis.nodal_dofs[:, k])
                continue
            d = self.basis.get_dofs(lambda x: (x[0] >= x0 - 1e-9) & (x[0] <= x1 + 1e-9)
                                    & (x[1] >= y0 - 1e-9) & (x[1] <= y1 + 1e-9))
            dofs.append(d.all())
        return np.unique(np.concatenate(dofs))

    def total_mass(self):
        """Mass of the model (kg) from the consistent mass matrix: e^T M e for a unit x translation."""
        e = self.basis.project(lambda x: np.array([np.ones_like(x[0]), np.zeros_like(x[0])]))
        return float(e @ (self.M @ e))

    def static(self):
        """Static displacement under the full load; returns (u, ux at the output point)."""
        u = np.zeros(self.basis.N)
        K, f = self.K[self.free][:, self.free].tocsc(), self.f[self.free]
        u[self.free] = spla.spsolve(K, f)
        return u, float((self.probe @ u)[0])

    def modes(self, n=40):
        """First ``n`` circular frequencies (rad/s) and mass-normalised modes (full dof vectors)."""
        if self._modes is None or self._modes[0].size < n:
            K = self.K[self.free][:, self.free].tocsc()
            M = self.M[self.free][:, self.free].tocsc()
            lam, phi = spla.eigsh(K, k=n, M=M, sigma=0.0, which="LM")
            order = np.argsort(lam)
            lam, phi = lam[order], phi[:, order]
            phi /= np.sqrt(np.einsum("ij,ij->j", phi, M @ phi))
            full = np.zeros((self.basis.N, n))
            full[self.free] = phi
            self._modes = (np.sqrt(lam), full)
        omega, phi = self._modes
        return omega[:n], phi[:, :n]

    def periods(self, n=2):
        """First ``n`` eigenperiods (s)."""
        return 2 * np.pi / self.modes(max(n, 2))[0][:n]


def step_response(fe, t, n_modes=40):
    """Undamped response of the output point's ux to the step load (mode-acceleration method).

    Parameters
    ----------
    fe : FrameFE
    t : numpy.ndarray
        Times (s).
    n_modes : int
        Modes kept in the dynamic part; the rest respond quasi-statically.

    Returns
    -------
    numpy.ndarray
        ux(t) at the output point.
    """
    _, u_static = fe.static()
    omega, phi = fe.modes(n_modes)
    q_static = (phi.T @ fe.f) / omega ** 2            # modal static amplitudes
    at_point = (fe.probe @ phi)[0]                     # each mode's ux at the point
    return u_static - (at_point * q_static) @ np.cos(np.outer(omega, t))


def first_peak(fe, n_modes=40, t_max=0.03, dt=1e-6):
    """First maximum of the step response before ``t_max``: (peak ux, time), refined to ``dt``
    by a parabola through the sampled maximum and its neighbours."""
    t = np.arange(0.0, t_max, dt)
    u = step_response(fe, t, n_modes)
    i = int(np.argmax(u))
    i = min(max(i, 1), len(t) - 2)
    a, b, c = u[i - 1], u[i], u[i + 1]
    den = a - 2 * b + c
    s = 0.5 * (a - c) / den if den != 0 else 0.0
    return float(b - 0.25 * (a - c) * s), float(t[i] + s * dt)


def peak_and_period(t, u, t_first=0.03):
    """The frame tests' estimator (test_portal_frame.py): first maximum before ``t_first`` and
    the sway period as twice the median spacing of the crossings of half that maximum."""
    i = int(np.argmax(u[t < t_first]))
    d = u - 0.5 * u[i]
    k = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
    return float(u[i]), float(t[i]), 2 * float(np.median(np.diff(tc)))


def richardson(values, ratio=2.0):
    """Richardson extrapolation of the last three values of a sequence on meshes refined by
    ``ratio``: (extrapolated value, observed order p, error estimate of the finest value).

    With fewer than three values, or no monotone convergence, p is nan and the error estimate is
    the last difference (a conservative stand-in)."""
    v = np.asarray(values, dtype=float)
    if len(v) < 3:
        return float(v[-1]), math.nan, float(abs(v[-1] - v[-2])) if len(v) > 1 else math.nan
    d1, d2 = v[-2] - v[-3], v[-1] - v[-2]
    if d1 == 0 or d2 == 0 or d2 / d1 <= 0 or abs(d2) >= abs(d1):
        return float(v[-1]), math.nan, float(abs(d2))
    p = math.log(abs(d1 / d2)) / math.log(ratio)
    err = d2 / (ratio ** p - 1)
    return float(v[-1] + err), p, float(abs(err))


@lru_cache(maxsize=None)
def frame_fe(h0=0.1, level=0, path=str(SCENE)):
    """The scene's frame at one mesh (cached per process)."""
    return FrameFE(read_scene(path), h0, level)


def refinement_study(levels=(0, 1, 2), h0=0.2, n_modes=40, path=str(SCENE), record=(0.1, 9.3e-5)):
    """Static drift, first two periods and the first step peak on nested meshes.

    ``record`` = (duration, sampling interval) of the step response given to the frame tests'
    period estimator (:func:`peak_and_period`), as the MPM test samples its run (0.1 s, every 20
    steps of about 4.64e-6 s); the result is ``period_est``, to compare like with like.

    Returns
    -------
    dict
        ``rows``: per level (h, elements, dofs, drift, k, T1, T2, peak, t_peak, period_est);
        ``richardson``: per quantity (extrapolated, order, error of the finest level).
    """
    rows = []
    for lev in levels:
        fe = frame_fe(h0, lev, path)
        fe.modes(n_modes)                                  # one eigen-solve serves all below
        _, drift = fe.static()
        T1, T2 = fe.periods(2)
        peak, t_peak = first_peak(fe, n_modes)
        t = np.arange(1, int(record[0] / record[1]) + 1) * record[1]
        period_est = peak_and_period(t, step_response(fe, t, n_modes))[2]
        rows.append(dict(level=lev, h=h0 / 2 ** lev, elements=fe.mesh.t.shape[1], dofs=fe.ndofs,
                         drift=drift, k=fe.data.load[0] / drift, T1=float(T1), T2=float(T2),
                         peak=peak, t_peak=t_peak, period_est=period_est))
    keys = ("drift", "k", "T1", "T2", "peak", "t_peak", "period_est")
    rich = {q: dict(zip(("value", "order", "error"), richardson([r[q] for r in rows]))) for q in keys}
    return {"rows": rows, "richardson": rich}
