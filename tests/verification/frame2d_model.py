"""An independent plane-frame model of any scene's ``[frame]`` table (issue 22), NumPy only.

It reads the frame's data (nodes, members, sections, supports, nodal loads and masses; the
material of the chosen variant) from the scene's TOML and shares no code with pmpm: the AISC W
shapes are read from the same CSV file with the standard library. It models what the MPM strips
are, as an engineer's frame program would:

* **members**: Timoshenko beam-columns (axial EA, bending EI, shear G A_s with A_s = d t_w, the
  web), A and I those of the strip (``area`` / ``inertia``, or the table's A and I_x), G =
  E / (2 (1 + nu)) (the plane-stress continuum's in-plane shear modulus), ``elements`` per
  member, consistent mass;
* **joints**, where beams meet a column; three idealisations (``joints=``):

  - ``"continuous"`` (the default): the column runs through the joint as what the strip is, a
    Timoshenko beam-column of its own section up to the panel's top face (the top of the deepest
    beam there, where the strips' column ends at a roof), split at the node and at the two beam
    flange levels y_n +- d_b / 2. A beam ends at the column face x_n +- d_c / 2; its end section
    is tied to the column: its horizontal displacement is the mean of the column's at the two
    flange levels, its rotation the rotation of the column's face chord between them
    (-(u_top - u_bottom) / d_b: the beam's flange forces act there), its vertical displacement
    the column's at the node plus the column section's rotation times the face offset. The
    panel's shear is then the column's own shear between the flange levels, and the column
    keeps bending inside the panel, as the continuum does (in the plane-stress strips the
    column's flanges carry its bending through the joint; Krawinkler's scissors, below, makes
    the column rigid there). The nodal mass is density over the panel's column length (as the
    MPM's panel strip), a nodal load is shared 1/4, 1/2, 1/4 by the flange-level and node
    points (the MPM shares it by mass over the panel).
  - ``"scissors"`` (Krawinkler's panel, as OpenSees users model it): the columns' flexible
    length ends at the panel's top and bottom faces and the beams' at its side faces, each tied
    to the node by a rigid offset; the beams' offsets hang on a panel rotation, tied to the
    columns' rotation by a rotational spring K_p = G d_c t_w,c d_b (the column web over the
    beam depth); the rigid parts' mass (panel, roof stub) lumped at the node.
  - ``"rigid"``: the scissors without the spring (rigid joint panels).

  For cases/frame_3storey.toml the continuous joint agrees with the plane-stress continuum of
  the same strips (frame3_fe_model.py) within 0.7% in T1 and T2 and 1% in the step response
  over 1.5 s; the scissors is 2.7% long in T1, 4.5% short in T2 and 6.5% high in the peak: one
  rotational spring does not stand for a panel whose column bends through it
  (docs/portal_frame.md section 11);
* **supports**: ``fixed`` (ux, uy, rotation), ``pinned`` (ux, uy), ``roller`` (the direction
  across the free one), at the node.

Results: natural periods (generalized eigenproblem), static drift, and the undamped response to
step loads by modal superposition (exact in time for a step: u = sum phi_i phi_i^T F (1 - cos
omega_i t) / omega_i^2 with mass-normalised modes; no time-integration error).
"""
import csv
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FrameModel", "from_scene", "w_shape", "JOINTS"]

#: the joint idealisations of from_scene
JOINTS = ("continuous", "scissors", "rigid")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
W_SHAPES = os.path.join(ROOT, "pmpm", "scene", "data", "aisc_w_shapes_v16.csv")
INCH = 0.0254


def w_shape(name):
    """d, bf, tf, tw (m), A (m^2), Ix, Iy (m^4) of an AISC W shape, from the CSV (in -> m)."""
    with open(W_SHAPES, newline="") as fh:
        for row in csv.DictReader(fh):
            if row["shape"].upper() == name.upper():
                f = {k: float(row[k]) for k in ("d", "bf", "tf", "tw", "area", "Ix", "Iy")}
                return {"d": f["d"] * INCH, "bf": f["bf"] * INCH, "tf": f["tf"] * INCH, "tw": f["tw"] * INCH,
                        "A": f["area"] * INCH ** 2, "I": f["Ix"] * INCH ** 4, "Iy": f["Iy"] * INCH ** 4}
    raise KeyError(name)


def _section(frame, name):
    explicit = frame.get("sections", {}).get(name)
    if explicit is None:
        return w_shape(name)
    d, bf, tf, tw = (explicit[k] for k in ("depth", "flange_width", "flange_thickness", "web_thickness"))
    area = explicit.get("area", 2 * bf * tf + (d - 2 * tf) * tw)
    inertia = explicit.get("inertia", (bf * d ** 3 - (bf - tw) * (d - 2 * tf) ** 3) / 12)
    return {"d": d, "bf": bf, "tf": tf, "tw": tw, "A": area, "I": inertia}


def timoshenko_stiffness(E, G, A, I, As, L):
    """Local 6x6 stiffness (u1, v1, t1, u2, v2, t2) of a Timoshenko beam-column."""
    phi = 12 * E * I / (G * As * L * L)
    b = E * I / ((1 + phi) * L ** 3)
    a = E * A / L
    return np.array([
        [a, 0, 0, -a, 0, 0],
        [0, 12 * b, 6 * L * b, 0, -12 * b, 6 * L * b],
        [0, 6 * L * b, (4 + phi) * L * L * b, 0, -6 * L * b, (2 - phi) * L * L * b],
        [-a, 0, 0, a, 0, 0],
        [0, -12 * b, -6 * L * b, 0, 12 * b, -6 * L * b],
        [0, 6 * L * b, (2 - phi) * L * L * b, 0, -6 * L * b, (4 + phi) * L * L * b]])


def consistent_mass(rho, A, L):
    """Local 6x6 consistent mass (axial linear, bending cubic Hermite)."""
    m = rho * A * L
    ax = m / 6 * np.array([[2, 1], [1, 2]])
    bz = m / 420 * np.array([[156, 22 * L, 54, -13 * L], [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                             [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
    M = np.zeros((6, 6))
    M[np.ix_([0, 3], [0, 3])] = ax
    M[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = bz
    return M


@dataclass
class FrameModel:
    """Degrees of freedom, matrices and loads of a plane frame."""
    ndof: int = 0
    K: np.ndarray = None
    M: np.ndarray = None
    F: np.ndarray = None
    fixed: set = field(default_factory=set)
    node_dofs: dict = field(default_factory=dict)   # frame node -> (ux, uy, theta_column)
    entries: list = field(default_factory=list)     # (dofs, K, M) per element or spring, global
    load_shares: dict = field(default_factory=dict)  # frame node -> [(dofs, share)] of a nodal load

    def add_nodal_force(self, node, force):
        """Add ``force`` (Fx, Fy) at frame node ``node`` to F, shared as the model shares it."""
        for dofs, share in self.load_shares.get(node, [(self.node_dofs[node], 1.0)]):
            self.F[dofs[0]] += share * force[0]
            self.F[dofs[1]] += share * force[1]

    def new_point(self, count=3):
        """New dofs: (ux, uy, theta) of a point of the model, or ``count`` of them."""
        self.ndof += count
        return list(range(self.ndof - count, self.ndof))

    def chain(self, p0, d0, t0, p1, d1, t1, count, E, G, section, As, line_mass):
        """``count`` Timoshenko elements from p0 to p1 (mass ``line_mass`` per length); their end
        sections (ux, uy, theta) are ``t0 @ u[d0]`` and ``t1 @ u[d1]`` (``None``: the dofs
        themselves), interior points get their own dofs."""
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        length = float(np.linalg.norm(p1 - p0))
        c, s = (p1 - p0) / length
        R = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        ends = ([(list(d0), np.eye(3) if t0 is None else np.asarray(t0, float))]
                + [(self.new_point(), np.eye(3)) for _ in range(count - 1)]
                + [(list(d1), np.eye(3) if t1 is None else np.asarray(t1, float))])
        L = length / count
        k = timoshenko_stiffness(E, G, section["A"], section["I"], As, L)
        m = consistent_mass(line_mass / section["A"], section["A"], L)
        for (di, ti), (dj, tj) in zip(ends[:-1], ends[1:]):
            T = np.zeros((6, len(di) + len(dj)))
            T[:3, :len(di)], T[3:, len(di):] = R @ ti, R @ tj
            self.entries.append((di + dj, T.T @ k @ T, T.T @ m @ T))

    def spring(self, a, b, k):
        """A spring of stiffness ``k`` between dofs a and b."""
        self.entries.append(([a, b], k * np.array([[1.0, -1.0], [-1.0, 1.0]]), np.zeros((2, 2))))

    def lumped(self, dofs, mass):
        """A point mass on the translations of ``dofs``."""
        self.entries.append((list(dofs[:2]), np.zeros((2, 2)), mass * np.eye(2)))

    def assemble(self):
        """K and M from the entries; a rotation with no inertia at all (a bare node's or the
        scissors' panel rotation) gets a tiny one, else M would be singular."""
        self.K = np.zeros((self.ndof, self.ndof))
        self.M = np.zeros((self.ndof, self.ndof))
        for d, k, m in self.entries:
            self.K[np.ix_(d, d)] += k
            self.M[np.ix_(d, d)] += m
        bare = self.M.diagonal() <= 0
        self.M[bare, bare] = 1e-9 * max(1.0, self.M.diagonal().max())

    def free(self):
        return np.array([d for d in range(self.ndof) if d not in self.fixed])

    def modes(self, count=3):
        """Periods (s) and mass-normalised mode shapes (full dof vectors) of the lowest modes."""
        f = self.free()
        K, M = self.K[np.ix_(f, f)], self.M[np.ix_(f, f)]
        L = np.linalg.cholesky(M)
        Li = np.linalg.inv(L)
        w2, y = np.linalg.eigh(Li @ K @ Li.T)
        phi = Li.T @ y
        full = np.zeros((self.ndof, len(w2)))
        full[f] = phi
        return 2 * np.pi / np.sqrt(w2[:count]), full[:, :count], w2, full

    def static(self):
        f = self.free()
        u = np.zeros(self.ndof)
        u[f] = np.linalg.solve(self.K[np.ix_(f, f)], self.F[f])
        return u

    def step_response(self, t, dof):
        """Undamped response of ``dof`` to the loads F applied as a step at t = 0 (all modes)."""
        _, _, w2, phi = self.modes()
        q = (phi.T @ self.F) / w2
        return (phi[dof] * q) @ (1 - np.cos(np.sqrt(w2)[:, None] * np.asarray(t)[None, :]))


def _material(data, label, variant):
    mat = dict(data["materials"][label])
    over = data.get("variants", {}).get(variant, {}) if variant else {}
    mat.update(over.get(f"materials.{label}", {}))
    return float(mat["E"]), float(mat["nu"]), float(mat["density"])


def from_scene(path, variant="elastic", elements=8, joints="continuous", shear=True, load_scale=1.0,
               supports=None, panels=None):
    """The frame model of the ``[frame]`` table of the scene file ``path``.

    Parameters
    ----------
    path : str
        Scene TOML with a ``[frame]`` table (read as data).
    variant : str or None
        Variant whose ``materials.<label>`` replaces the base material.
    elements : int
        Elements per member (the column inside a joint gets two per half).
    joints : {"continuous", "scissors", "rigid"}
        The joint idealisation (see the module's docstring).
    shear : bool
        Model the members' shear deformation.
    load_scale : float
        Factor on the nodal loads.
    supports : str or None
        Replace every support's type (``"fixed"``, ``"pinned"``).
    panels : bool or None
        Former switch, kept for callers: False means ``joints="rigid"``, True ``"scissors"``.
    """
    if panels is not None:
        joints = "scissors" if panels else "rigid"
    if joints not in JOINTS:
        raise ValueError(f"joints: {joints!r} is not continuous, scissors or rigid")
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    frame = data["frame"]
    nodes = {n["name"]: np.array(n["at"], float) for n in frame["nodes"]}
    members = []
    for m in frame["members"]:
        (xa, ya), (xb, yb) = nodes[m["from"]], nodes[m["to"]]
        vertical = abs(xa - xb) < 1e-9
        lo, hi = (m["from"], m["to"]) if ((ya < yb) if vertical else (xa < xb)) else (m["to"], m["from"])
        E, nu, rho = _material(data, m.get("material", frame.get("material")), variant)
        members.append(dict(lo=lo, hi=hi, vertical=vertical, sec=_section(frame, m["section"]), E=E, nu=nu, rho=rho))
    cols = {n: [m for m in members if m["vertical"] and n in (m["lo"], m["hi"])] for n in nodes}
    beams = {n: [m for m in members if not m["vertical"] and n in (m["lo"], m["hi"])] for n in nodes}
    d_col = {n: max([m["sec"]["d"] for m in cols[n]], default=0.0) for n in nodes}
    d_beam = {n: max([m["sec"]["d"] for m in beams[n]], default=0.0) for n in nodes}
    masses = {n: 0.0 for n in nodes}
    for extra in frame.get("masses", []):
        masses[extra["node"]] += extra["mass"]
    model = FrameModel()
    model.node_dofs = {n: model.new_point() for n in nodes}
    joint = {n for n in nodes if cols[n] and beams[n]}
    build = _continuous_joints if joints == "continuous" else _scissors_joints
    spread = build(model, nodes, members, cols, joint, d_col, d_beam, masses, elements, shear,
                   panel_spring=(joints == "scissors"))
    model.assemble()
    for s in frame.get("supports", []):
        kind = supports or s["type"]
        ux, uy, th = model.node_dofs[s["node"]]
        held = {"fixed": (ux, uy, th), "pinned": (ux, uy),
                "roller": (uy,) if s.get("direction", "x") == "x" else (ux,)}[kind]
        model.fixed.update(held)
    model.F = np.zeros(model.ndof)
    model.load_shares = spread
    for f in frame.get("loads", []):
        model.add_nodal_force(f["node"], [load_scale * c for c in f["force"]])
    return model


def _member_constants(m, shear):
    s, E, nu = m["sec"], m["E"], m["nu"]
    G = E / (2 * (1 + nu))
    As = s["d"] * s["tw"] if shear else 1e6 * s["A"]
    return s, E, G, As


def _continuous_joints(model, nodes, members, cols, joint, d_col, d_beam, masses, elements, shear,
                       panel_spring=False):
    """Columns through the joints, beam end sections tied to the column's face chord (module doc)."""
    flange = {}                     # joint -> (dofs at y - d_b/2, dofs at y + d_b/2)
    spread = {}
    for n in sorted(joint):
        below = [m for m in cols[n] if m["hi"] == n]
        m = (below or cols[n])[0]   # the panel is the column's under it (the front end's rule)
        s, E, G, As = _member_constants(m, shear)
        half = d_beam[n] / 2
        bottom, top = model.new_point(), model.new_point()
        flange[n] = (bottom, top)
        # the nodal mass is density over the panel's column length, as in the MPM's panel strip
        line = m["rho"] * s["A"] + masses[n] / d_beam[n]
        x, y = nodes[n]
        model.chain((x, y - half), bottom, None, nodes[n], model.node_dofs[n], None, 2, E, G, s, As, line)
        model.chain(nodes[n], model.node_dofs[n], None, (x, y + half), top, None, 2, E, G, s, As, line)
        spread[n] = [(bottom, 0.25), (model.node_dofs[n], 0.5), (top, 0.25)]
    for m in members:
        s, E, G, As = _member_constants(m, shear)
        line = m["rho"] * s["A"]
        lo, hi = m["lo"], m["hi"]
        if m["vertical"]:
            p0, d0 = ((nodes[lo] + (0, d_beam[lo] / 2), flange[lo][1]) if lo in flange
                      else (nodes[lo], model.node_dofs[lo]))
            p1, d1 = ((nodes[hi] - (0, d_beam[hi] / 2), flange[hi][0]) if hi in flange
                      else (nodes[hi], model.node_dofs[hi]))
            model.chain(p0, d0, None, p1, d1, None, elements, E, G, s, As, line)
            continue
        ends = []
        for n, side in ((lo, 1.0), (hi, -1.0)):
            face = side * d_col[n] / 2
            if n in flange:
                bottom, top = flange[n]
                dofs = bottom + model.node_dofs[n] + top
                tie = np.zeros((3, 9))
                tie[0, 0] = tie[0, 6] = 0.5                        # ux: mean at the flange levels
                tie[1, 4], tie[1, 5] = 1.0, face                   # uy: node's + rotation x offset
                tie[2, 0], tie[2, 6] = 1.0 / d_beam[n], -1.0 / d_beam[n]   # the face chord's rotation
            else:                                                  # a beam on a bare node
                dofs = model.node_dofs[n]
                tie = np.array([[1, 0, 0], [0, 1, face], [0, 0, 1.0]])
            ends.append((nodes[n] + (face, 0.0), dofs, tie))
        (p0, d0, t0), (p1, d1, t1) = ends
        model.chain(p0, d0, t0, p1, d1, t1, elements, E, G, s, As, line)
    for n, mass in masses.items():
        if n not in flange:
            model.lumped(model.node_dofs[n], mass)
    return spread


def _scissors_joints(model, nodes, members, cols, joint, d_col, d_beam, masses, elements, shear,
                     panel_spring=True):
    """Krawinkler's scissors panel, or rigid panels without ``panel_spring`` (module doc)."""
    above = {n: any(m["vertical"] and m["lo"] == n for m in members) for n in nodes}
    panel = {n: model.new_point(1) for n in sorted(joint)} if panel_spring else {}
    lumped = dict(masses)
    for m in members:
        s, E, G, As = _member_constants(m, shear)
        lo, hi = m["lo"], m["hi"]
        dlo, dhi = model.node_dofs[lo], model.node_dofs[hi]
        if m["vertical"]:
            e_lo = (0.0, d_beam[lo] / 2 if (above[lo] and d_beam[lo]) else 0.0)
            e_hi = (0.0, -d_beam[hi] / 2)
            th_lo, th_hi = dlo[2], dhi[2]
            # the rigid parts' mass: the panel halves, and the stub above a roof beam
            lumped[lo] += m["rho"] * s["A"] * abs(e_lo[1])
            lumped[hi] += m["rho"] * s["A"] * abs(e_hi[1]) * (1 if above[hi] else 2)
        else:
            e_lo, e_hi = (d_col[lo] / 2, 0.0), (-d_col[hi] / 2, 0.0)
            th_lo = panel[lo][0] if lo in panel else dlo[2]
            th_hi = panel[hi][0] if hi in panel else dhi[2]
        p0, p1 = nodes[lo] + e_lo, nodes[hi] + e_hi

        def offset(e):   # a rigid offset e from the node: (ux, uy, theta) at its end
            return np.array([[1, 0, -e[1]], [0, 1, e[0]], [0, 0, 1.0]])
        model.chain(p0, [dlo[0], dlo[1], th_lo], offset(e_lo), p1, [dhi[0], dhi[1], th_hi], offset(e_hi),
                    elements, E, G, s, As, m["rho"] * s["A"])
    for n, (p,) in panel.items():   # the panel's shear spring between column and beam rotations
        E, nu = cols[n][0]["E"], cols[n][0]["nu"]
        t_w = max(m["sec"]["tw"] for m in cols[n])
        model.spring(model.node_dofs[n][2], p, E / (2 * (1 + nu)) * d_col[n] * t_w * d_beam[n])
    for n, mass in lumped.items():
        model.lumped(model.node_dofs[n], mass)
    return {}
