"""Resolution study of the paper's steel portal frame (cases/portal_frame.toml).

For each cell size, both variants (``elastic``, ``elastoplastic``) run in-process on one rank
(``build_solver(scene, MPI.COMM_SELF)``, as tests/verification/test_portal_frame.py does), with the grid's
cells scaled so the domain stays x in [-0.5, 6.6], y in [0, 4.2]. Everything else (bodies, bases,
load, CFL 0.5, cubic B-splines, MUSL, 2 x 2 particles per cell) comes from the case file; the strips
are regenerated at each resolution with their area and second moment matched to the W shapes.

The upper-left joint's displacement (the case's ``upper_left_joint`` track) is sampled every
``output.history_interval`` (1e-4 s). Reported per run: first peak of ux (mm) and its time, the
sway period (the test's estimator: twice the median spacing of the crossings of half the first
peak; a run that yields so much that it never swings back below half its first peak gets the
same rule about its mean level after the peak instead, shown in brackets), particle count,
steps, wall and CPU time of the stepping loop; per cell size, the permanent drift: the centre of
oscillation (time mean of ux over the last full period of each run, the period being that run's
own estimate) of the elastoplastic run minus that of the elastic run. Energies are sampled every
ENERGY_INTERVAL for the plastic work at each sway maximum and the energy balance.

Run (one rank; a shared 2-vCPU machine leaves the other core to other work)::

    python -m studies.frame_resolution --cells 0.1 0.05 0.025 --t-end 0.25 \
        --out docs/portal_frame_resolution.json --histories /tmp/frame_study/histories.npz
    python -m studies.frame_resolution --analyse /tmp/frame_study/histories.npz
    python -m studies.frame_resolution --estimates

``--t-end`` takes one value for all cell sizes or one per cell size (a fine grid can run a shorter
end time that still covers the first peak and two periods, about 0.1 s). The script prints one
progress line per tenth of each run on stderr, then a Markdown table and, last, one JSON line on
stdout; the same JSON is written to ``--out`` (rewritten after every run, so a stopped study
keeps what it finished). ``--histories FILE.npz`` also saves the sampled histories;
``--analyse FILE.npz`` prints the numbers docs/portal_frame.md derives from them (periods over the
first 0.1 s, drift over several windows, sway maxima and minima, uy against ux, spectra, energy
balance), and ``--estimates`` prints the beam model of tests/verification/frame_beam_model.py
extended step by step with the continuum's effects (clear span, Timoshenko shear, a Krawinkler
joint-panel spring, the column-stub mass). Neither of the last two runs the MPM or writes a file.
"""
import argparse
import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

from studies import verification_models

__all__ = ["frame_scene", "run_frame", "peak_and_period", "oscillation_centre", "study", "main",
           "continuum_estimates", "extended_frame", "frame_estimate", "shear_area", "strip_profile",
           "analyse_histories", "sway_extrema"]

CASE = os.path.join(os.path.dirname(__file__), "..", "cases", "portal_frame.toml")
DOMAIN_LO = (-0.5, 0.0)
DOMAIN_HI = (6.6, 4.2)
VARIANTS = ("elastic", "elastoplastic")
TRACK = "upper_left_joint"
ENERGY_INTERVAL = 5e-4   # s between energy samples


def frame_scene(variant, cell_size, t_end, case=CASE):
    """The portal frame scene of ``variant`` with cells of ``cell_size`` over the case's domain and
    ``solver.end_time = t_end``."""
    from pmpm.scene.config import apply_overrides, parse_scene, read_toml

    data = read_toml(case)
    data = apply_overrides(data, data["variants"][variant], f"variants.{variant}")
    cells = [int(round((hi - lo) / cell_size)) for lo, hi in zip(DOMAIN_LO, DOMAIN_HI)]
    for lo, hi, n in zip(DOMAIN_LO, DOMAIN_HI, cells):
        if not math.isclose(lo + n * cell_size, hi, rel_tol=0, abs_tol=1e-9 * max(1.0, abs(hi))):
            raise ValueError(f"cell size {cell_size} does not divide the domain [{lo}, {hi}]")
    data["grid"] = {"origin": list(DOMAIN_LO), "cell_size": float(cell_size), "cells": cells}
    data["solver"]["end_time"] = float(t_end)
    out = data.setdefault("output", {})
    out.pop("checkpoint_interval", None)  # not written here; keeps short end times valid
    scene = parse_scene(data, case)
    return dataclasses.replace(scene, variant=variant)


def run_frame(scene, progress=None):
    """Run ``scene`` on this process alone and sample the upper-left joint.

    Returns
    -------
    dict
        t, ux, uy (arrays, every ``output.history_interval``), te and the energies (kinetic,
        strain, plastic work, external work; arrays, every ENERGY_INTERVAL), particles, steps,
        dt0, wall and cpu time of the stepping loop (s), setup time (s), the final energies and
        ``energy_gap_rel``: the largest |kinetic + internal work - external work| (sampled every
        ENERGY_INTERVAL) divided by the external work at the end (P times the final ux; the test
        divides by the largest external work, about twice as much).
    """
    from mpi4py import MPI

    from pmpm.build import build_solver
    from pmpm.io.tracking import Tracker

    t0 = time.perf_counter()
    s = build_solver(scene, MPI.COMM_SELF)
    tracks = [tr for tr in scene.output.track if tr.name == TRACK]
    tr = Tracker(tracks, s)
    setup = time.perf_counter() - t0
    interval = scene.output.history_interval
    end = scene.solver.end_time
    t, ux, uy = [0.0], [0.0], [0.0]
    next_sample, next_energy, next_report = interval, ENERGY_INTERVAL, 0.1 * end
    gap = 0.0
    te, energy = [0.0], [(0.0, 0.0, 0.0, 0.0)]
    w0, c0 = time.perf_counter(), time.process_time()
    while s.t < end * (1 - 1e-12):
        s.step()
        if s.t >= next_sample - 1e-12:
            row = tr.sample()[0]
            t.append(s.t)
            ux.append(row[0])
            uy.append(row[1])
            next_sample += interval * max(1, math.floor((s.t - next_sample) / interval + 1e-9) + 1)
        if s.t >= next_energy - 1e-12:
            e = s.energies()
            gap = max(gap, abs(e["total"] - e["external_work"]))
            te.append(s.t)
            energy.append((e["kinetic"], e["strain"], e["plastic_work"], e["external_work"]))
            next_energy += ENERGY_INTERVAL
        if progress and s.t >= next_report - 1e-12:
            progress(s.t, end, s.step_count, time.perf_counter() - w0)
            next_report += 0.1 * end
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    e = s.energies()
    gap = max(gap, abs(e["total"] - e["external_work"]))
    energy = np.array(energy)
    return {"t": np.array(t), "ux": np.array(ux), "uy": np.array(uy), "te": np.array(te),
            "kinetic": energy[:, 0], "strain": energy[:, 1], "plastic": energy[:, 2],
            "external": energy[:, 3], "particles": int(s.n_total),
            "steps": int(s.step_count), "dt0": float(scene.solver.cfl * s.grid.h / s.wave_speed),
            "wall_s": wall, "cpu_s": cpu, "setup_s": setup, "energies": e,
            "energy_gap_rel": gap / e["external_work"] if e["external_work"] else float("nan")}


def peak_and_period(t, u):
    """First maximum (within 0.03 s) and sway period, exactly as tests/verification/
    test_portal_frame.py estimates them: the period is twice the median spacing of the crossings
    of half the first peak (the static level of an undamped step response), interpolated
    linearly. Returns (peak, time of peak, period)."""
    i = int(np.argmax(u[t < 0.03]))
    return float(u[i]), float(t[i]), _crossing_period(t, u, 0.5 * u[i])


def _crossing_period(t, u, level):
    """Twice the median spacing of the linearly interpolated crossings of ``level`` (NaN when
    the record crosses it fewer than twice)."""
    d = u - level
    k = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    if len(k) < 2:
        return float("nan")
    tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
    return 2 * float(np.median(np.diff(tc)))


def mean_level_period(t, u, t_peak):
    """Fallback period for runs that yield so much that they never swing back below half the first
    peak: the same median-crossing rule about the mean of the record after the first peak."""
    after = t >= t_peak
    return _crossing_period(t[after], u[after], float(np.mean(u[after])))


def oscillation_centre(t, u, period):
    """Time mean of ``u`` over the last full ``period`` of the record (trapezoidal rule)."""
    start = t[-1] - period
    tt = np.concatenate([[start], t[t > start]])
    uu = np.interp(tt, t, u)
    return float(np.trapezoid(uu, tt) / (tt[-1] - tt[0]))


def _beam_module():
    """tests/verification/frame_beam_model.py (NumPy only), or None when the tests are not next
    to this package."""
    if not verification_models.available("frame_beam_model"):
        return None
    return verification_models.load("frame_beam_model")


def beam_reference(t_end):
    """The Euler-Bernoulli frame model of tests/verification (centre lines, stub mass), through the
    same estimator; None when the tests are not next to this package."""
    beam = _beam_module()
    if beam is None:
        return None
    tb, ub = beam.portal_frame_response(t_end=t_end, stub_mass=True)
    peak, tp, period = peak_and_period(tb, ub)
    return {"model": "Euler-Bernoulli, centre lines, column-stub mass (frame_beam_model.py)",
            "peak_mm": round(peak * 1e3, 3), "t_peak_s": round(tp, 5), "period_ms": round(period * 1e3, 2),
            "modal_period_ms": round(float(beam.portal_frame_modes(stub_mass=True)[0]) * 1e3, 2)}


# --------------------------------------------------------------------------------------------------
# Estimates of the continuum effects (no MPM run): the beam model of tests/verification extended
# with Timoshenko shear flexibility and a Krawinkler joint-panel spring (docs/portal_frame.md)
# --------------------------------------------------------------------------------------------------
def shear_area(eta, thickness, depth):
    """Energy-consistent shear area I^2 / int(Q^2 / t) of a section made of equal bands of
    ``depth / len(eta)`` centred at ``eta`` with the given thicknesses (Q: first moment of the
    part beyond eta, evaluated at each band's centre)."""
    order = np.argsort(eta)
    eta, t = np.asarray(eta, float)[order], np.asarray(thickness, float)[order]
    dy = depth / len(eta)
    inertia = np.sum(t * eta ** 2) * dy
    q = np.array([np.sum(t[k + 1:] * eta[k + 1:]) * dy + 0.5 * t[k] * eta[k] * dy for k in range(len(eta))])
    return inertia ** 2 / (np.sum(q ** 2 / t) * dy)


def section_shear_area(sec, rows=20000):
    """Shear area of the idealised W shape (flanges bf x tf, web tw), by :func:`shear_area`."""
    d = sec["d"]
    eta = -d / 2 + (np.arange(rows) + 0.5) * d / rows
    t = np.where(np.abs(eta) > d / 2 - sec["tf"], sec["bf"], sec["tw"])
    return shear_area(eta, t, d)


def strip_profile(cell_size, body_name, case=CASE):
    """Rows (distance from the member axis) and out-of-plane thickness per row of a member strip as
    pmpm generates it at ``cell_size`` (the thicknesses are scaled so the strip's A and I match)."""
    from pmpm.scene.bodies import body_points
    from pmpm.core.grid import Grid

    scene = frame_scene("elastic", cell_size, 0.25, case)
    body = next(b for b in scene.bodies if b.name == body_name)
    geo = body.geometry
    cells = [int(round((hi - lo) / cell_size)) for lo, hi in zip(DOMAIN_LO, DOMAIN_HI)]
    pts, vol = body_points(body, Grid(DOMAIN_LO, cell_size, cells), os.path.dirname(case), body_name)
    start, end = np.asarray(geo["start"]), np.asarray(geo["end"])
    length = float(np.linalg.norm(end - start))
    direction = (end - start) / length
    normal = np.array([-direction[1], direction[0]])
    eta = np.round((pts - start) @ normal, 9)
    rows, first = np.unique(eta, return_index=True)
    thickness = vol[first] / (length * geo["depth"] / len(pts))
    return rows, thickness, geo


def _timoshenko_local(E, G, A, I, L, shear_area_):
    """Local stiffness (u1, v1, th1, u2, v2, th2) of a Timoshenko frame element (Euler-Bernoulli
    when ``shear_area_`` is None)."""
    phi = 0.0 if shear_area_ is None else 12.0 * E * I / (G * shear_area_ * L ** 2)
    k = np.zeros((6, 6))
    a = E * A / L
    k[np.ix_([0, 3], [0, 3])] = a * np.array([[1.0, -1.0], [-1.0, 1.0]])
    b = E * I / (L ** 3 * (1.0 + phi))
    k[np.ix_([1, 2, 4, 5], [1, 2, 4, 5])] = b * np.array(
        [[12.0, 6 * L, -12.0, 6 * L], [6 * L, (4 + phi) * L ** 2, -6 * L, (2 - phi) * L ** 2],
         [-12.0, -6 * L, 12.0, -6 * L], [6 * L, (2 - phi) * L ** 2, -6 * L, (4 + phi) * L ** 2]])
    return k


def _element_transform(c, s, off_i, off_j):
    """Global node dofs -> local dofs at the flexible ends (rotation after rigid offsets)."""
    r = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    rot = np.zeros((6, 6))
    rot[:3, :3] = r
    rot[3:, 3:] = r
    link = np.eye(6)
    for base, (ex, ey) in ((0, off_i), (3, off_j)):
        link[base, base + 2] = -ey
        link[base + 1, base + 2] = ex
    return rot @ link


def extended_frame(geometry="clear", stub_mass=True, column_shear=None, beam_shear=None, panel=None,
                   elements_per_member=8):
    """Stiffness and mass of the frame model of tests/verification with optional Timoshenko shear
    areas (m^2) for the columns and the beam and a joint-panel rotational spring ``panel``
    (N m / rad) between each column top and the beam end (the beam end shares the joint's
    translations, not its rotation). Returns K, M (free dofs), the loaded dof, the panel
    rotation dofs (column, beam) of the left joint, and the frame module."""
    bm = _beam_module()
    if bm is None:
        raise RuntimeError("tests/verification/frame_beam_model.py not found")
    model, loaded = bm.portal_frame_model(elements_per_member, geometry, "handbook", stub_mass)
    g_mod = bm.E_STEEL / (2 * (1 + bm.NU_STEEL))
    tops = [k for k, (x, y) in enumerate(model.nodes) if abs(y - bm.HEIGHT) < 1e-9 and k in (1, 3)]
    ndof = 3 * len(model.nodes)
    beam_rot = {}
    if panel:
        for k in tops:
            beam_rot[k] = ndof
            ndof += 1
    K, M = np.zeros((ndof, ndof)), np.zeros((ndof, ndof))
    for el in model.elements:
        xi = np.add(model.nodes[el["i"]], el["off_i"])
        xj = np.add(model.nodes[el["j"]], el["off_j"])
        length = float(np.hypot(*(xj - xi)))
        c, s = (xj - xi) / length
        is_beam = abs(c) > 0.5
        t = _element_transform(c, s, el["off_i"], el["off_j"])
        area_s = beam_shear if is_beam else column_shear
        k = t.T @ _timoshenko_local(el["E"], g_mod, el["A"], el["I"], length, area_s) @ t
        m = t.T @ bm.frame_element_mass(el["rho"], el["A"], length) @ t
        dofs = []
        for node in (el["i"], el["j"]):
            rot = beam_rot.get(node, 3 * node + 2) if is_beam else 3 * node + 2
            dofs += [3 * node, 3 * node + 1, rot]
        K[np.ix_(dofs, dofs)] += k
        M[np.ix_(dofs, dofs)] += m
    for node, mass in model.point_masses.items():
        M[3 * node, 3 * node] += mass
        M[3 * node + 1, 3 * node + 1] += mass
    for node, dof in beam_rot.items():
        a, b = 3 * node + 2, dof
        K[a, a] += panel
        K[b, b] += panel
        K[a, b] -= panel
        K[b, a] -= panel
    fixed = np.fromiter(model.fixed, int, len(model.fixed))
    free = np.setdiff1d(np.arange(ndof), fixed)
    K, M = K[np.ix_(free, free)], M[np.ix_(free, free)]
    where = lambda dof: int(np.searchsorted(free, dof))  # noqa: E731
    panel_dofs = (where(3 * tops[0] + 2), where(beam_rot[tops[0]])) if panel else None
    return K, M, where(3 * loaded), panel_dofs, bm


def frame_estimate(t_end=0.1, dt=2e-5, **kw):
    """Static lateral stiffness, static and step-response displacement of the loaded joint, the
    sway period (test estimator and first mode) and, with a panel, its static shear rotation and
    moment, for :func:`extended_frame` ``**kw``."""
    K, M, ix, panel_dofs, bm = extended_frame(**kw)
    f = np.zeros(len(K))
    f[ix] = bm.LOAD
    u = np.linalg.solve(K, f)
    w2, _ = bm.generalized_eigen(K, M)
    t, hist = bm.newmark_average_acceleration(K, M, f, dt, int(round(t_end / dt)))
    peak, tp, period = peak_and_period(t, hist[:, ix])
    out = {"k_N_per_m": bm.LOAD / u[ix], "static_mm": u[ix] * 1e3, "peak_mm": peak * 1e3, "t_peak_s": tp,
           "period_ms": period * 1e3, "mode1_ms": 2e3 * np.pi / np.sqrt(w2[0])}
    if panel_dofs:
        gamma = u[panel_dofs[1]] - u[panel_dofs[0]]
        out["panel_rotation_mrad"] = gamma * 1e3
        out["panel_moment_kNm"] = kw["panel"] * gamma / 1e3
    return out


def continuum_estimates(cells=(0.1, 0.05, 0.025)):
    """The beam model step by step towards the continuum strips (docs/portal_frame.md).

    Shear areas: the web, d tw (the idealised W shape's energy-consistent shear area is within 1%
    of it); joint panel: Krawinkler's K = G d_c t_w d_b. The last rows use, per cell size, the
    shear areas and the column-web thickness of the strips pmpm generates (their A/I scaling
    thins the web when few particle rows cross the depth)."""
    bm = _beam_module()
    if bm is None:
        raise RuntimeError("tests/verification/frame_beam_model.py not found")
    props = bm.portal_frame_properties()
    col, beam = props["column"], props["beam"]
    g_mod = bm.E_STEEL / (2 * (1 + bm.NU_STEEL))
    web_c, web_b = col["d"] * col["tw"], beam["d"] * beam["tw"]
    panel = g_mod * col["d"] * col["tw"] * beam["d"]
    sections = {"G_Pa": g_mod, "column_d_tw_m2": web_c, "beam_d_tw_m2": web_b,
                "column_shear_area_m2": section_shear_area(col), "beam_shear_area_m2": section_shear_area(beam),
                "panel_stiffness_Nm_per_rad": panel, "beam_end_stiffness_6EI_L": 6 * bm.E_STEEL * beam["I"] / bm.SPAN,
                "column_shear_hand_mm": 0.5 * bm.LOAD * bm.HEIGHT / (g_mod * web_c) * 1e3}
    cases = [
        ("Euler-Bernoulli, centre lines", dict(geometry="centreline", stub_mass=False)),
        ("Euler-Bernoulli, centre lines, stub mass", dict(geometry="centreline")),
        ("Euler-Bernoulli, clear span (rigid offsets)", dict(stub_mass=False)),
        ("Euler-Bernoulli, clear span, stub mass", dict()),
        ("  + column shear (Timoshenko, d tw)", dict(column_shear=web_c)),
        ("  + beam shear (Timoshenko, d tw)", dict(beam_shear=web_b)),
        ("  + joint panel (G d_c t_w d_b)", dict(panel=panel)),
        ("  + all three", dict(column_shear=web_c, beam_shear=web_b, panel=panel)),
        ("  + all three, no stub mass", dict(stub_mass=False, column_shear=web_c, beam_shear=web_b, panel=panel)),
        ("  + all three, panel stiffness doubled (stiffened joint)", dict(column_shear=web_c, beam_shear=web_b,
                                                                         panel=2 * panel)),
        ("  + column and beam shear, rigid panel", dict(column_shear=web_c, beam_shear=web_b)),
        ("centre lines, stub mass + all three", dict(geometry="centreline", column_shear=web_c,
                                                     beam_shear=web_b, panel=panel)),
    ]
    strips = {}
    for h in cells:
        rows_c, t_c, geo_c = strip_profile(h, "left_column")
        rows_b, t_b, geo_b = strip_profile(h, "beam")
        a_c = shear_area(rows_c, t_c, geo_c["depth"])
        a_b = shear_area(rows_b, t_b, geo_b["depth"])
        tw_c = float(t_c.min())
        strips[h] = {"column_rows": len(rows_c), "beam_rows": len(rows_b),
                     "column_web_over_tw": tw_c / col["tw"], "beam_web_over_tw": float(t_b.min()) / beam["tw"],
                     "column_shear_area_m2": a_c, "beam_shear_area_m2": a_b}
        cases.append((f"clear span, stub mass, strips of h = {h:g} m (their A_s and web)",
                      dict(column_shear=a_c, beam_shear=a_b, panel=g_mod * col["d"] * tw_c * beam["d"])))
    rows = []
    for name, kw in cases:
        r = frame_estimate(**kw)
        r["model"] = name
        rows.append(r)
    return {"sections": sections, "strips": strips, "models": rows}


def estimates_table(est):
    """:func:`continuum_estimates` as Markdown."""
    lines = ["| model | k (MN/m) | static (mm) | step peak (mm) | at (s) | period (ms) | mode 1 (ms) "
             "| panel rotation (mrad) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in est["models"]:
        gamma = f"{r['panel_rotation_mrad']:.2f}" if "panel_rotation_mrad" in r else ""
        lines.append(f"| {r['model']} | {r['k_N_per_m'] / 1e6:.2f} | {r['static_mm']:.2f} | {r['peak_mm']:.2f} "
                     f"| {r['t_peak_s']:.4f} | {r['period_ms']:.1f} | {r['mode1_ms']:.1f} | {gamma} |")
    lines.append("")
    lines.append("| cell (m) | rows across column / beam | web thickness / tw, column / beam "
                 "| shear area column / beam (m^2) |")
    lines.append("|---|---|---|---|")
    for h, s in est["strips"].items():
        lines.append(f"| {h:g} | {s['column_rows']} / {s['beam_rows']} | {s['column_web_over_tw']:.2f} / "
                     f"{s['beam_web_over_tw']:.2f} | {s['column_shear_area_m2']:.3e} / {s['beam_shear_area_m2']:.3e} |")
    sec = est["sections"]
    lines.append("")
    lines.append(f"G = {sec['G_Pa'] / 1e9:.1f} GPa; web areas d tw: column {sec['column_d_tw_m2']:.3e}, beam "
                 f"{sec['beam_d_tw_m2']:.3e} m^2 (energy shear areas of the idealised shapes "
                 f"{sec['column_shear_area_m2']:.3e}, {sec['beam_shear_area_m2']:.3e}); panel G d_c t_w d_b = "
                 f"{sec['panel_stiffness_Nm_per_rad']:.3e} N m/rad "
                 f"against the beam end's 6 E I_b / L = {sec['beam_end_stiffness_6EI_L']:.3e}; hand estimate of column "
                 f"shear sway (P/2) h / (G d tw) = {sec['column_shear_hand_mm']:.2f} mm static")
    return "\n".join(lines)


def sway_extrema(t, u, t_peak):
    """Times of the sway maxima and minima after the start: the extreme of each half cycle
    between successive crossings of the mean level after the first peak (higher-mode ripple
    does not split a half cycle)."""
    after = t >= t_peak
    d = u - float(np.mean(u[after]))
    k = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0] + 1
    bounds = np.concatenate([[0], k, [len(u)]])
    peaks, troughs = [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a < 2 or b == len(u):   # the last, unfinished half cycle is left out
            continue
        if d[a] > 0:
            peaks.append(float(t[a + np.argmax(u[a:b])]))
        else:
            troughs.append(float(t[a + np.argmin(u[a:b])]))
    return peaks, troughs


def _summary(cell, variant, t_end, run):
    peak, tp, period = peak_and_period(run["t"], run["ux"])
    fallback = mean_level_period(run["t"], run["ux"], tp)
    window = period if math.isfinite(period) else fallback
    return {"cell_size": cell, "variant": variant, "t_end": t_end, "particles": run["particles"],
            "steps": run["steps"], "dt0_s": run["dt0"], "peak_mm": peak * 1e3, "t_peak_s": tp,
            "period_ms": period * 1e3, "period_mean_level_ms": fallback * 1e3,
            "centre_mm": oscillation_centre(run["t"], run["ux"], window) * 1e3,
            "centre_window_ms": window * 1e3,
            "wall_s": run["wall_s"], "cpu_s": run["cpu_s"], "setup_s": run["setup_s"],
            "energy_gap_rel": run["energy_gap_rel"],
            "plastic_work_J": run["energies"]["plastic_work"],
            "plastic_work_at_sway_peaks_J": ([round(float(np.interp(tp_, run["te"], run["plastic"])), 1)
                                              for tp_ in sway_extrema(run["t"], run["ux"], tp)[0]]
                                             if run["plastic"][-1] > 0 else []),
            "external_work_J": run["energies"]["external_work"]}


def _rounded(d):
    out = {}
    for k, v in d.items():
        if isinstance(v, float):
            out[k] = float(f"{v:.6g}") if math.isfinite(v) else None  # strict JSON has no NaN
        else:
            out[k] = v
    return out


def markdown_table(rows, full_t_end):
    """The study's rows as a Markdown table (drift on the elastoplastic rows)."""
    head = ("| cell (m) | variant | particles | steps | end time (s) | first peak (mm) | at (s) "
            "| sway period (ms) | drift (mm) | wall (s) | CPU (s) |")
    lines = [head, "|" + "|".join(["---"] * 11) + "|"]
    for r in rows:
        drift = f"{r['drift_mm']:.2f}" if r.get("drift_mm") is not None else ""
        period = (f"{r['period_ms']:.1f}" if r.get("period_ms") is not None else
                  f"({r['period_mean_level_ms']:.1f})" if r.get("period_mean_level_ms") is not None else "n/a")
        end = f"{r['t_end']:g}" + ("" if r["t_end"] >= full_t_end else " (shortened)")
        lines.append(f"| {r['cell_size']:g} | {r['variant']} | {r['particles']} | {r['steps']} | {end} "
                     f"| {r['peak_mm']:.2f} | {r['t_peak_s']:.4f} | {period} | {drift} "
                     f"| {r['wall_s']:.0f} | {r['cpu_s']:.0f} |")
    if any(r.get("period_ms") is None for r in rows):
        lines.append("")
        lines.append("(period in brackets: the run never swings back below half its first peak, so the "
                     "test's estimator has no crossings; the same rule about the mean level after the peak)")
    return "\n".join(lines)


def study(cells, t_ends, out=None, histories=None, reference=True, log=sys.stderr):
    """Run every cell size and variant; returns the result dict (also written to ``out``)."""
    from mpi4py import MPI

    result = {"case": "cases/portal_frame.toml", "track": TRACK, "ranks": 1,
              "host": {"cpus": os.cpu_count(), "note": "2 vCPUs shared with other work: wall times are noisy"},
              "command": "python -m studies.frame_resolution " + " ".join(sys.argv[1:]),
              "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(), "runs": []}
    if reference:
        ref = beam_reference(max(t_ends))
        result["beam_model"] = _rounded(ref) if ref else None
    saved = {}
    for cell, t_end in zip(cells, t_ends):
        pair = {}
        for variant in VARIANTS:
            scene = frame_scene(variant, cell, t_end)
            print(f"[frame_resolution] h = {cell:g} m, {variant}, end {t_end:g} s: starting", file=log, flush=True)

            def progress(t, end, steps, wall, _v=variant, _c=cell):
                eta = wall * (end - t) / t if t > 0 else float("nan")
                print(f"[frame_resolution] h = {_c:g} m, {_v}: t = {t:.4f}/{end:g} s, {steps} steps, "
                      f"{wall:.0f} s elapsed, about {eta:.0f} s to go", file=log, flush=True)

            run = run_frame(scene, progress)
            row = _summary(cell, variant, t_end, run)
            pair[variant] = row
            saved[f"h{cell:g}_{variant}_t"] = run["t"]
            saved[f"h{cell:g}_{variant}_ux"] = run["ux"]
            saved[f"h{cell:g}_{variant}_uy"] = run["uy"]
            for key in ("te", "kinetic", "strain", "plastic", "external"):
                saved[f"h{cell:g}_{variant}_{key}"] = run[key]
            row["drift_mm"] = None
            if variant == "elastoplastic" and "elastic" in pair:
                row["drift_mm"] = row["centre_mm"] - pair["elastic"]["centre_mm"]
            result["runs"].append(_rounded(row))
            print(f"[frame_resolution] h = {cell:g} m, {variant}: peak {row['peak_mm']:.2f} mm at "
                  f"{row['t_peak_s']:.4f} s, period {row['period_ms']:.1f} ms "
                  f"(mean-level rule {row['period_mean_level_ms']:.1f} ms), {row['steps']} steps, "
                  f"{row['wall_s']:.0f} s", file=log, flush=True)
            if out:
                _write(out, result)
            if histories:
                np.savez_compressed(histories, **saved)
    return result


def _spectral_periods(t, u, count):
    """Periods (ms) of the ``count`` strongest spectral peaks of ``u`` (resampled uniformly, mean
    removed, Hann window); peaks closer than 8 Hz to a stronger one are skipped."""
    dt = float(np.median(np.diff(t)))
    tu = np.arange(0.0, t[-1], dt)
    y = np.interp(tu, t, u)
    y = (y - y.mean()) * np.hanning(len(y))
    amp = np.abs(np.fft.rfft(y))
    freq = np.fft.rfftfreq(len(y), dt)
    found = []
    for i in np.argsort(amp)[::-1]:
        if 1 < i < len(amp) - 1 and amp[i] >= amp[i - 1] and amp[i] >= amp[i + 1] \
                and all(abs(freq[i] - f) > 8.0 for f in found):
            found.append(freq[i])
            if len(found) == count:
                break
    return [round(1e3 / float(f), 2) for f in found]


def analyse_histories(path, early=0.1):
    """Derived numbers of docs/portal_frame.md from a ``--histories`` file: the test's estimator on
    the first ``early`` s, the drift over several windows, the sway maxima and minima, uy extremes
    and spectra, and the energy balance kinetic + strain + plastic work - external work."""
    d = np.load(path)
    cells = sorted({float(k.split("_")[0][1:]) for k in d.files}, reverse=True)
    out = {}
    for h in cells:
        key = f"h{h:g}"
        runs = {v: {f: d[f"{key}_{v}_{f}"] for f in ("t", "ux", "uy", "te", "kinetic", "strain", "plastic",
                                                       "external")}
                for v in VARIANTS if f"{key}_{v}_t" in d.files}
        res = {}
        for v, r in runs.items():
            t, u = r["t"], r["ux"]
            m = t <= early + 1e-9
            pk, tp, per = peak_and_period(t[m], u[m])
            tmax, tmin = sway_extrema(t, u, tp)
            gap = r["kinetic"] + r["strain"] + r["plastic"] - r["external"]
            # uy against ux: linear (axial force from the beam's end shear) plus quadratic (the arc
            # shortening of a swaying column, -0.6 ux^2 / h for a double-curvature shape)
            basis = np.column_stack([u, u * u])
            (lin, quad), *_ = np.linalg.lstsq(basis, r["uy"], rcond=None)
            resid = r["uy"] - basis @ (lin, quad)
            res[v] = {f"period_first_{early:g}s_ms": round(per * 1e3, 2) if math.isfinite(per) else None,
                      "sway_maxima_mm": [round(float(np.interp(x, t, u)) * 1e3, 1) for x in tmax],
                      "sway_minima_mm": [round(float(np.interp(x, t, u)) * 1e3, 1) for x in tmin],
                      "uy_min_mm": round(float(r["uy"].min()) * 1e3, 3),
                      "uy_max_mm": round(float(r["uy"].max()) * 1e3, 3),
                      "uy_mean_mm": round(float(r["uy"].mean()) * 1e3, 3),
                      "uy_fit_linear": round(float(lin), 5), "uy_fit_quadratic_per_m": round(float(quad), 4),
                      "uy_fit_residual_rms_mm": round(float(np.sqrt(np.mean(resid ** 2))) * 1e3, 4),
                      "uy_rms_about_mean_mm": round(float(np.std(r["uy"])) * 1e3, 4),
                      "uy_spectral_periods_ms": _spectral_periods(t, r["uy"], 6),
                      "ux_spectral_periods_ms": _spectral_periods(t, u, 4),
                      "energy_gap_end_J": round(float(gap[-1]), 1),
                      "energy_gap_end_over_final_work": round(float(gap[-1] / r["external"][-1]), 5),
                      "energy_gap_max_over_max_work": round(float(np.abs(gap).max() / r["external"].max()), 5)}
        if len(runs) == 2:
            el, ep = runs["elastic"], runs["elastoplastic"]
            end = float(min(el["t"][-1], ep["t"][-1]))
            windows = {f"test window ({early - 0.04:g}, {early:g}] s": (early - 0.04, early),
                       f"last 40 ms ({end - 0.04:g}, {end:g}] s": (end - 0.04, end),
                       f"last 80 ms ({end - 0.08:g}, {end:g}] s": (end - 0.08, end),
                       f"(0.05, {end:g}] s": (0.05, end)}
            drift = {}
            for name, (lo, hi) in windows.items():
                me = (el["t"] > lo) & (el["t"] <= hi + 1e-9)
                mp = (ep["t"] > lo) & (ep["t"] <= hi + 1e-9)
                drift[name] = round(float(ep["ux"][mp].mean() - el["ux"][me].mean()) * 1e3, 2)
            res["drift_mm_by_window"] = drift
        out[key] = res
    return out


def _write(path, result):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(result, fh, indent=1)
        fh.write("\n")
    os.replace(tmp, path)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.frame_resolution", description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=float, nargs="+", default=[0.1, 0.05, 0.025], help="cell sizes in m")
    ap.add_argument("--t-end", type=float, nargs="+", default=[0.25],
                    help="end time in s: one for all cell sizes, or one per cell size")
    ap.add_argument("--out", default="docs/portal_frame_resolution.json", help="JSON file to write")
    ap.add_argument("--histories", default=None, help="also save the sampled histories (.npz)")
    ap.add_argument("--no-reference", action="store_true", help="skip the beam-model reference")
    ap.add_argument("--estimates", action="store_true",
                    help="print only the beam-model estimates of the continuum effects (no MPM run, nothing written)")
    ap.add_argument("--analyse", metavar="HISTORIES.npz", default=None,
                    help="print only the numbers derived from a --histories file (no MPM run, nothing written)")
    args = ap.parse_args(argv)
    if args.analyse:
        res = analyse_histories(args.analyse)
        for key, runs in res.items():
            print(f"## {key[1:]} m")
            for name, vals in runs.items():
                print(f"- {name}: " + "; ".join(f"{k} {v}" for k, v in vals.items()))
        print(json.dumps(res, separators=(",", ":")))
        return 0
    if args.estimates:
        est = continuum_estimates(args.cells)
        print(estimates_table(est))
        print(json.dumps(est, separators=(",", ":"), default=float))
        return 0
    from mpi4py import MPI
    if MPI.COMM_WORLD.size > 1:
        ap.error("runs on one rank (every rank would repeat the whole study); start it without mpirun -n > 1")
    t_ends = args.t_end * len(args.cells) if len(args.t_end) == 1 else args.t_end
    if len(t_ends) != len(args.cells):
        ap.error("--t-end takes one value or one per cell size")
    full = max(t_ends)
    result = study(args.cells, t_ends, args.out, args.histories, not args.no_reference)
    print(markdown_table(result["runs"], full))
    ref = result.get("beam_model")
    if ref:
        period = "n/a" if ref["period_ms"] is None else f"{ref['period_ms']:.1f} ms"
        print(f"\nbeam model (centre lines, stub mass): peak {ref['peak_mm']:.2f} mm at {ref['t_peak_s']:.4f} s, "
              f"period {period} (first mode {ref['modal_period_ms']:.1f} ms)")
    print(json.dumps(result, separators=(",", ":")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
