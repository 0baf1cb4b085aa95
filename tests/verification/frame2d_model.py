"""An independent plane-frame model of any scene's ``[frame]`` table (issue 22), NumPy only.

It reads the frame's data (nodes, members, sections, supports, nodal loads; the material of
the chosen variant) from the scene's TOML and shares no code with pmpm: the AISC W shapes are
read from the same CSV file with the standard library. It models what the MPM strips are, as
an engineer's frame program would:

* **members**: Timoshenko beam-columns (axial EA, bending EI, shear G A_s with A_s = d t_w, the
  web), A and I those of the strip (``area`` / ``inertia``, or the table's A and I_x), G =
  E / (2 (1 + nu)) (the plane-stress continuum's in-plane shear modulus), ``elements`` per
  member, consistent mass of the flexible length;
* **joints** (Krawinkler's "scissors" panel): where beams and columns meet, the columns' flexible
  length ends at the panel's top and bottom faces and the beams' at its side faces, each tied
  to the node by a rigid offset (half the other member's depth, as the MPM's column runs through
  the joint and its beams end at the column faces); the beams' offsets hang on a panel
  rotation, tied to the columns' rotation by a rotational spring K_p = G d_c t_w,c d_b, the
  elastic shear stiffness of the panel (the column web over the beam depth);
* **masses**: the rigid parts (the panel, and the column stub above a roof beam up to its top,
  which the MPM's column carries) lumped at the node, translation only;
* **supports**: ``fixed`` (ux, uy, rotation), ``pinned`` (ux, uy), ``roller`` (the direction
  across the free one).

Results: natural periods (generalized eigenproblem), static drift, and the undamped response to
step loads by modal superposition (exact in time for a step: u = sum phi_i phi_i^T F (1 - cos
omega_i t) / omega_i^2 with mass-normalised modes; no time-integration error).
"""
import csv
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FrameModel", "from_scene", "w_shape"]

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


def from_scene(path, variant="elastic", elements=8, panels=True, shear=True, load_scale=1.0, supports=None):
    """The frame model of the ``[frame]`` table of the scene file ``path``.

    Parameters
    ----------
    path : str
        Scene TOML with a ``[frame]`` table (read as data).
    variant : str or None
        Variant whose ``materials.<label>`` replaces the base material.
    elements : int
        Elements per member.
    panels, shear : bool
        Model the joint panels' shear flexibility / the members' shear deformation.
    load_scale : float
        Factor on the nodal loads.
    supports : str or None
        Replace every support's type (``"fixed"``, ``"pinned"``).
    """
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    frame = data["frame"]
    nodes = {n["name"]: tuple(n["at"]) for n in frame["nodes"]}
    members = []
    for m in frame["members"]:
        (xa, ya), (xb, yb) = nodes[m["from"]], nodes[m["to"]]
        vertical = abs(xa - xb) < 1e-9
        lo, hi = (m["from"], m["to"]) if ((ya < yb) if vertical else (xa < xb)) else (m["to"], m["from"])
        E, nu, rho = _material(data, m.get("material", frame.get("material")), variant)
        members.append(dict(lo=lo, hi=hi, vertical=vertical, sec=_section(frame, m["section"]), E=E, nu=nu, rho=rho))
    col = {n: max([m["sec"]["d"] for m in members if m["vertical"] and n in (m["lo"], m["hi"])], default=0.0) for n in nodes}
    beam = {n: max([m["sec"]["d"] for m in members if not m["vertical"] and n in (m["lo"], m["hi"])], default=0.0) for n in nodes}
    tw_col = {n: max([m["sec"]["tw"] for m in members if m["vertical"] and n in (m["lo"], m["hi"])], default=0.0) for n in nodes}
    above = {n: any(m["vertical"] and m["lo"] == n for m in members) for n in nodes}
    model = FrameModel()
    dof = {}
    for n in nodes:
        dof[n] = [model.ndof, model.ndof + 1, model.ndof + 2]
        model.ndof += 3
    panel = {}
    for n in nodes:
        if panels and col[n] > 0 and beam[n] > 0:
            panel[n] = model.ndof
            model.ndof += 1
    lumped = {n: 0.0 for n in nodes}
    entries = []   # (dof list of 6, K local-global 6x6, M 6x6)
    for m in members:
        s, E, nu, rho = m["sec"], m["E"], m["nu"], m["rho"]
        G = E / (2 * (1 + nu))
        As = s["d"] * s["tw"] if shear else 1e6 * s["A"]
        if m["vertical"]:
            e_lo = (0.0, beam[m["lo"]] / 2 if (above[m["lo"]] and beam[m["lo"]]) else 0.0)
            e_hi = (0.0, -beam[m["hi"]] / 2)
            th_lo, th_hi = dof[m["lo"]][2], dof[m["hi"]][2]
            # the rigid parts' mass: the panel halves, and the stub above a roof beam
            lumped[m["lo"]] += rho * s["A"] * abs(e_lo[1])
            lumped[m["hi"]] += rho * s["A"] * abs(e_hi[1]) * (1 if above[m["hi"]] else 2)
        else:
            e_lo, e_hi = (col[m["lo"]] / 2, 0.0), (-col[m["hi"]] / 2, 0.0)
            th_lo, th_hi = panel.get(m["lo"], dof[m["lo"]][2]), panel.get(m["hi"], dof[m["hi"]][2])
        p0 = np.add(nodes[m["lo"]], e_lo)
        p1 = np.add(nodes[m["hi"]], e_hi)
        length = float(np.linalg.norm(p1 - p0))
        c, sn = (p1 - p0) / length
        R = np.array([[c, sn, 0], [-sn, c, 0], [0, 0, 1]])
        # element chain: interior nodes get their own dofs
        chain = [None] + [model.ndof + 3 * k for k in range(elements - 1)] + [None]
        model.ndof += 3 * (elements - 1)
        Le = length / elements
        for k in range(elements):
            def end(j, e, n, th):
                if chain[j] is None:  # tied to the frame node by a rigid offset
                    T = np.array([[1, 0, -e[1]], [0, 1, e[0]], [0, 0, 1.0]])
                    return [dof[n][0], dof[n][1], th], T
                return [chain[j], chain[j] + 1, chain[j] + 2], np.eye(3)
            di, Ti = end(k, e_lo, m["lo"], th_lo) if k == 0 else end(k, None, None, None)
            dj, Tj = end(k + 1, e_hi, m["hi"], th_hi) if k == elements - 1 else end(k + 1, None, None, None)
            T = np.zeros((6, 6))
            T[:3, :3], T[3:, 3:] = R @ Ti, R @ Tj
            entries.append((di + dj, T.T @ timoshenko_stiffness(E, G, s["A"], s["I"], As, Le) @ T,
                            T.T @ consistent_mass(rho, s["A"], Le) @ T))
    model.K = np.zeros((model.ndof, model.ndof))
    model.M = np.zeros((model.ndof, model.ndof))
    for d, k, mm in entries:
        model.K[np.ix_(d, d)] += k
        model.M[np.ix_(d, d)] += mm
    for n, p in panel.items():  # the panel's shear spring between column and beam rotations
        E, nu = members[0]["E"], members[0]["nu"]
        kp = E / (2 * (1 + nu)) * col[n] * tw_col[n] * beam[n]
        a, b = dof[n][2], p
        model.K[np.ix_([a, b], [a, b])] += kp * np.array([[1, -1], [-1, 1]])
    for n, mass in lumped.items():
        model.M[dof[n][0], dof[n][0]] += mass
        model.M[dof[n][1], dof[n][1]] += mass
    for extra in frame.get("masses", []):
        n = extra["node"]
        model.M[dof[n][0], dof[n][0]] += extra["mass"]
        model.M[dof[n][1], dof[n][1]] += extra["mass"]
    # rotational dofs with no stiffness at all (none here) would make M singular: all carry mass
    # via the elements except the panel and node rotations, given a tiny rotary inertia
    for d in list(panel.values()) + [dof[n][2] for n in nodes]:
        model.M[d, d] += 1e-9 * max(1.0, model.M.diagonal().max())
    for s in frame.get("supports", []):
        kind = supports or s["type"]
        ux, uy, th = dof[s["node"]]
        held = {"fixed": (ux, uy, th), "pinned": (ux, uy),
                "roller": (uy,) if s.get("direction", "x") == "x" else (ux,)}[kind]
        model.fixed.update(held)
    model.F = np.zeros(model.ndof)
    for f in frame.get("loads", []):
        ux, uy, _ = dof[f["node"]]
        model.F[ux] += load_scale * f["force"][0]
        model.F[uy] += load_scale * f["force"][1]
    model.node_dofs = dof
    return model
