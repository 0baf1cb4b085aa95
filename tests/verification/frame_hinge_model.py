"""Independent plastic-hinge model of the portal frame (NumPy only; shares no code with pmpm).

The elastic Euler-Bernoulli frame of frame_beam_model.py (its elements, consistent masses,
"clear" geometry: columns flexible up to the beam centre line, the beam between the column
faces tied to the joints by rigid links) with elastic-perfectly-plastic hinges (concentrated
plasticity) where a sway mechanism forms them: at both column bases, in both columns at the
beam's bottom flange (y = h - d_b/2) and in the beam at both column faces. A hinge is a
zero-length link between two coincident nodes: a stiff penalty on their relative translation
and a rotational spring whose moment is capped at Mp (return mapping; its elastic stiffness
50 times the member's 4EI/L makes it nearly rigid until it yields). Extra nodes sit at the places
where the MPM case cuts its members (0.2 m above the bases, y = 3.35 m, 0.15 m from the beam
ends) so their moments can be compared directly.

Time integration: Newmark (no physical damping, as the paper's run) with gamma = 0.6 (beta =
0.3025), whose numerical damping removes the ringing of the stiff hinge links that a step load
excites (with the average-acceleration rule it makes the hinges chatter between +Mp and -Mp from
the first step), with Newton iterations on the hinges at every step. Axial force does not reduce Mp (N/Np stays below about
5% in the frame) and there is no hardening: this model says when and in what order the
mechanism's hinges form, not how far past Mp a hardening section goes.
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import frame_beam_model as fbm  # noqa: E402

__all__ = ["HingeFrame", "portal_hinge_frame", "hinge_response", "HINGES", "CUTS"]

#: hinge locations and the cuts of cases/portal_frame.toml, by name
HINGES = ("left_base", "right_base", "left_column_top", "right_column_top", "beam_left_end", "beam_right_end")
CUTS = ("left_column_left_base", "right_column_right_base", "left_column_upper_left_joint",
        "right_column_upper_right_joint", "beam_upper_left_joint", "beam_upper_right_joint")
RIGID = 1e3   # stiffness factor of rigid links and of the hinges' translational ties
#: elastic stiffness of a hinge's rotational spring in units of its member's 4 EI / L: stiff
#: enough to add only about 2% to a member's end flexibility, soft enough for Newton to find
#: the yield point (at 1e3 it steps across the spring's elastic range, 1e-8 rad, and cycles)
HINGE_STIFFNESS = 50.0
#: Newmark gamma: 0.6 damps the spurious modes the step load excites in the stiff hinge links
#: (periods far below dt) and lengthens the 35 ms sway period by about (w dt)^2 / 12, nothing
GAMMA = 0.6
MAX_NEWTON = 30


class HingeFrame:
    """A FrameModel plus hinge links; ``step`` advances Newmark with Newton on the hinges."""

    def __init__(self, model, hinges, load_dof, cut_elements):
        self.model = model
        self.hinges = hinges              # dicts: name, a, b (nodes), k, Mp
        K, M = model.assemble()
        self.free = model.free
        self.K_lin = K
        self.M = M[np.ix_(self.free, self.free)]
        # the face nodes between a massless rigid link and a hinge carry no mass: a token one
        # (1e-9 of the largest diagonal entry) keeps M invertible for the initial acceleration
        empty = np.diag(self.M) <= 0
        self.M[empty, empty] = 1e-9 * np.diag(self.M).max()
        for h in hinges:
            kt = RIGID * h["k"] / h["length"] ** 2  # a force per unit relative translation
            for d in range(2):  # the penalty on relative translation is linear
                i, j = 3 * h["a"] + d, 3 * h["b"] + d
                self.K_lin[np.ix_([i, j], [i, j])] += kt * np.array([[1.0, -1.0], [-1.0, 1.0]])
        self.K_lin = self.K_lin[np.ix_(self.free, self.free)]
        self.index = {dof: k for k, dof in enumerate(self.free)}
        self.rot = [(self.index.get(3 * h["a"] + 2), self.index.get(3 * h["b"] + 2)) for h in hinges]
        self.theta_p = np.zeros(len(hinges))
        self.load = np.zeros(len(self.free))
        self.load[self.index[load_dof]] = 1.0
        self.cut_elements = cut_elements  # name -> (element index, end 0/1)

    def _spring(self, u, theta_p):
        """Moments, tangents and trial plastic rotations of the hinges at displacement u."""
        m, kt, tp = np.zeros(len(self.hinges)), np.zeros(len(self.hinges)), theta_p.copy()
        for k, (h, (ia, ib)) in enumerate(zip(self.hinges, self.rot)):
            rel = (u[ib] if ib is not None else 0.0) - (u[ia] if ia is not None else 0.0)
            ks = HINGE_STIFFNESS * h["k"]
            trial = ks * (rel - theta_p[k])
            if abs(trial) > h["Mp"]:
                m[k] = math.copysign(h["Mp"], trial)
                tp[k] = rel - m[k] / ks
            else:
                m[k], kt[k] = trial, ks
        return m, kt, tp

    def _internal(self, u, theta_p):
        f = self.K_lin @ u
        K = self.K_lin.copy()
        m, kt, tp = self._spring(u, theta_p)
        for k, (ia, ib) in enumerate(self.rot):
            for sign, i in ((-1.0, ia), (1.0, ib)):
                if i is None:
                    continue
                f[i] += sign * m[k]
                for sign2, j in ((-1.0, ia), (1.0, ib)):
                    if j is not None:
                        K[i, j] += sign * sign2 * kt[k]
        return f, K, tp

    def run(self, load, dt, t_end, sample_every=5, gamma=GAMMA, ramp=0.0):
        """Response to a step load (``ramp`` > 0: rising linearly to ``load`` over ``ramp`` s);
        returns t, hinge moments, cut moments, drift.

        Newmark with gamma >= 1/2 and beta = (gamma + 1/2)^2 / 4, with Newton iterations on the
        hinges; gamma > 1/2 damps the modes far above 1/dt and leaves the sway mode alone."""
        beta = (gamma + 0.5) ** 2 / 4
        n = len(self.free)
        u, v = np.zeros(n), np.zeros(n)
        F0 = load * self.load
        F = F0 if ramp <= 0 else 0.0 * F0
        a = np.linalg.solve(self.M, F)
        out_t, out_h, out_c, out_u = [0.0], [np.zeros(len(self.hinges))], [self.cut_moments(u)], [0.0]
        nsteps = int(round(t_end / dt))
        c0 = 1.0 / (beta * dt * dt)
        for step in range(1, nsteps + 1):
            if ramp > 0:
                F = min(step * dt / ramp, 1.0) * F0
            base = u + dt * v + (0.5 - beta) * dt * dt * a   # u_new = base + beta dt^2 a_new
            u_new = u + dt * v
            for _ in range(MAX_NEWTON):
                a_new = c0 * (u_new - base)
                f, K, _ = self._internal(u_new, self.theta_p)
                r = F - f - self.M @ a_new
                if np.abs(r).max() <= 1e-9 * load:
                    break
                u_new = u_new + np.linalg.solve(K + c0 * self.M, r)
            else:
                raise RuntimeError(f"Newton did not converge at t = {step * dt:.4g} s")
            a_new = c0 * (u_new - base)
            v = v + dt * ((1 - gamma) * a + gamma * a_new)
            u, a = u_new, a_new
            _, _, self.theta_p = self._internal(u, self.theta_p)
            if step % sample_every == 0:
                out_t.append(step * dt)
                out_h.append(self._spring(u, self.theta_p)[0])
                out_c.append(self.cut_moments(u))
                out_u.append(u[self.index[self.load_dof]])
        return np.array(out_t), np.array(out_h), np.array(out_c), np.array(out_u)

    def cut_moments(self, u):
        """Bending moment at each cut (the element end moment there; inertia of the element
        itself neglected), magnitudes with the element's sign convention."""
        full = np.zeros(self.model.ndof)
        full[self.free] = u
        out = []
        for name, (e, end) in self.cut_elements.items():
            el = self.model.elements[e]
            k, _ = self.model._element_global(el)
            dofs = np.r_[3 * el["i"] + np.arange(3), 3 * el["j"] + np.arange(3)]
            out.append((k @ full[dofs])[2 + 3 * end])
        return np.array(out)


def _chain(model, ids_at, pts, A, I, rho=fbm.RHO_STEEL, E=fbm.E_STEEL):
    """Elements through the points ``pts`` (new nodes except where ``ids_at`` gives one)."""
    ids = [ids_at.get(k, None) for k in range(len(pts))]
    ids = [i if i is not None else model.add_node(*p) for i, p in zip(ids, pts)]
    first = len(model.elements)
    for a, b in zip(ids[:-1], ids[1:]):
        model.add_element(a, b, E, A, I, rho)
    return ids, first


def _column(model, x, base, col, beam, n):
    """Column at x: fixed base node, hinge pair, cut at 0.2, n elements, cut at 3.35, hinge pair
    at the beam's underside, a stub to the joint. Returns nodes and element indices."""
    h, yf = fbm.HEIGHT, fbm.HEIGHT - beam["d"] / 2
    ys = [0.0, 0.2] + list(np.linspace(0.2, 3.35, n + 1)[1:]) + [yf]
    ids, first = _chain(model, {}, [(x, y) for y in ys], col["A"], col["I"])
    top_lo = ids[-1]
    top_hi = model.add_node(x, yf)
    joint = model.add_node(x, h)
    model.add_element(top_hi, joint, fbm.E_STEEL, col["A"], col["I"], fbm.RHO_STEEL)
    return {"base_fixed": base, "base": ids[0], "cut_base_el": first + 1, "cut_top_el": first + n,
            "top_lo": top_lo, "top_hi": top_hi, "joint": joint}


def portal_hinge_frame(n=8, sections=None, stub_mass=True):
    """The portal frame with hinges (see the module docstring); returns a HingeFrame whose
    ``load_dof`` is the upper-left joint's ux."""
    col, beam = dict(fbm._SECTIONS["column"]), dict(fbm._SECTIONS["beam"])
    if sections:
        col.update(sections.get("column", {}))
        beam.update(sections.get("beam", {}))
    model = fbm.FrameModel()
    L, h, e = fbm.SPAN, fbm.HEIGHT, col["d"] / 2
    cols = []
    for x in (0.0, L):
        base = model.add_node(x, 0.0)
        model.fix_node(base)
        cols.append(_column(model, x, base, col, beam, n))
    # the beam: rigid massless links from the joints to the faces, hinge pairs at the faces
    face_l, face_r = model.add_node(e, h), model.add_node(L - e, h)
    model.add_element(cols[0]["joint"], face_l, RIGID * fbm.E_STEEL, beam["A"], beam["I"], 0.0)
    model.add_element(face_r, cols[1]["joint"], RIGID * fbm.E_STEEL, beam["A"], beam["I"], 0.0)
    xs = [e, e + 0.15] + list(np.linspace(e + 0.15, L - e - 0.15, n + 1)[1:]) + [L - e]
    bids, bfirst = _chain(model, {}, [(x, h) for x in xs], beam["A"], beam["I"])
    if stub_mass:  # the column above the beam centre line, which the MPM strips carry
        for c in cols:
            model.add_point_mass(c["joint"], fbm.RHO_STEEL * col["A"] * beam["d"] / 2)
    kc, kb = 4 * fbm.E_STEEL * col["I"] / h, 4 * fbm.E_STEEL * beam["I"] / (L - 2 * e)
    mp_c, mp_b = fbm.SIGMA_Y * col["Z"], fbm.SIGMA_Y * beam["Z"]
    Lb = L - 2 * e
    hinges = [dict(name="left_base", a=cols[0]["base_fixed"], b=cols[0]["base"], k=kc, Mp=mp_c, length=h),
              dict(name="right_base", a=cols[1]["base_fixed"], b=cols[1]["base"], k=kc, Mp=mp_c, length=h),
              dict(name="left_column_top", a=cols[0]["top_lo"], b=cols[0]["top_hi"], k=kc, Mp=mp_c, length=h),
              dict(name="right_column_top", a=cols[1]["top_lo"], b=cols[1]["top_hi"], k=kc, Mp=mp_c, length=h),
              dict(name="beam_left_end", a=face_l, b=bids[0], k=kb, Mp=mp_b, length=Lb),
              dict(name="beam_right_end", a=bids[-1], b=face_r, k=kb, Mp=mp_b, length=Lb)]
    # the fixed base nodes: their rotation is fixed, the hinge spring ties the column to them
    cuts = {"left_column_left_base": (cols[0]["cut_base_el"], 0), "right_column_right_base": (cols[1]["cut_base_el"], 0),
            "left_column_upper_left_joint": (cols[0]["cut_top_el"], 1), "right_column_upper_right_joint": (cols[1]["cut_top_el"], 1),
            "beam_upper_left_joint": (bfirst + 1, 0), "beam_upper_right_joint": (bfirst + n, 1)}
    frame = HingeFrame(model, hinges, 3 * cols[0]["joint"], cuts)
    frame.load_dof = 3 * cols[0]["joint"]
    return frame


def hinge_response(factor, t_end=0.25, dt=2e-5, n=8, sections=None):
    """Hinge formation under ``factor`` times the paper's step load.

    Returns
    -------
    dict with ``t``, ``hinge_moments`` (S, 6), ``cut_moments`` (S, 6), ``drift`` (S,),
    ``first_mp`` {hinge: time it first reaches Mp (NaN: never)}, ``order`` (hinges by that time)
    and ``mp`` {hinge: Mp}.
    """
    frame = portal_hinge_frame(n, sections)
    t, mh, mc, drift = frame.run(factor * fbm.LOAD, dt, t_end)
    first = {}
    for k, h in enumerate(frame.hinges):
        hit = np.flatnonzero(np.abs(mh[:, k]) >= h["Mp"] * (1 - 1e-9))
        first[h["name"]] = float(t[hit[0]]) if len(hit) else math.nan
    order = sorted((k for k in first if math.isfinite(first[k])), key=first.get)
    return {"t": t, "hinge_moments": mh, "cut_moments": mc, "drift": drift, "first_mp": first,
            "order": order, "mp": {h["name"]: h["Mp"] for h in frame.hinges}}
