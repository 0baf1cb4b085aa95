"""The ground motion moves the supports a ``[frame]`` generates (issue 22, items 5 and 6).

``cases/frame_3storey.toml``'s ``ground_motion`` variant shakes the SAC three-storey frame with
``cases/records/synthetic_quake.AT2``. Its supports are not written as ``[[boundary]]`` tables:
the front end (pmpm.scene.frame) generates them, one ``fixed`` box per support on the grid node
line y = 0, with no ``body``. pmpm.physics.groundmotion drives every ``fixed`` box support when
``[loads.ground_motion]`` names no boundaries, so the generated ones are driven: checked here on
the case itself at 0.2 m cells (3 x 3 particles per cell, about 12,000 particles), 0.2 s of the
record (about 5,900 steps, some 30 s on this host), against the record integrated here:

* the record is read here independently (the AT2 header's NPTS and DT, values in g times
  9.80665 m/s^2) and integrated exactly for its piecewise-linear acceleration (trapezoids over
  whole intervals, Simpson's rule, exact for the quadratic velocity, for the ground displacement);
* the driven nodes are exactly the grid nodes of the three generated support boxes, and at every
  step they are prescribed the exact ground velocity at the step's end;
* the base particles (the lowest particle row of every column) move with the ground: their
  displacement is the sum of dt times those velocities, up to the column's own deformation at
  their stencil's reach (bounded below by beam theory and the run's first-storey drift);
* the frame responds in its relative frame: the total horizontal momentum equals the impulse of
  the base reactions at every step (no other horizontal force acts: momentum balance), and
  while the ground's first displacement pulse grows the reaction impulse is positive, the
  direction of the ground's push (in the relative frame the load is -m a_g, which the base shear
  resists; the floors lag behind the ground).

Each of these fails if the record does not move the supports (the frame then stays at rest).
"""
import os
import re

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.scene.config import apply_overrides, parse_scene, read_toml

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASE = os.path.join(ROOT, "cases", "frame_3storey.toml")
RECORD = os.path.join(ROOT, "cases", "records", "synthetic_quake.AT2")
H, PPC, T_END = 0.2, 3, 0.2
G = 9.80665
STOREY = 3.96          # the case's storey height (m)
COLUMNS = (0.0, 9.15, 18.3)


def read_at2(path):
    """(t, a in m/s^2) of a PEER AT2 file, parsed here (not with pmpm's reader)."""
    with open(path) as f:
        lines = f.read().splitlines()
    head = " ".join(lines[:4])
    n = int(re.search(r"NPTS\s*=\s*(\d+)", head).group(1))
    dt = float(re.search(r"DT\s*=\s*([0-9.Ee+-]+)", head).group(1))
    a = np.array(" ".join(lines[4:]).split(), dtype=float)[:n] * G
    return np.arange(n) * dt, a


T_REC, A_REC = read_at2(RECORD)
#: the velocity at the samples: trapezoids, exact for a linear acceleration on each interval
V_REC = np.concatenate([[0.0], np.cumsum(0.5 * (A_REC[1:] + A_REC[:-1]) * np.diff(T_REC))])


def v_exact(t):
    """Ground velocity: the sample's velocity plus Simpson's rule (exact) on the linear a."""
    k = min(int(np.searchsorted(T_REC, t, side="right") - 1), len(T_REC) - 2)
    lo = T_REC[k]
    a = lambda s: np.interp(s, T_REC, A_REC)  # noqa: E731
    return V_REC[k] + (t - lo) / 6 * (a(lo) + 4 * a(0.5 * (lo + t)) + a(t))


def u_exact(t):
    """Ground displacement: Simpson's rule on each piece of [0, t] where v is one quadratic."""
    knots = [0.0] + [x for x in T_REC if 0.0 < x < t] + [t]
    return sum((hi - lo) / 6 * (v_exact(lo) + 4 * v_exact(0.5 * (lo + hi)) + v_exact(hi))
               for lo, hi in zip(knots[:-1], knots[1:]))


def coarse_scene():
    """The case's ground_motion variant on cells of H over the case's own domain."""
    data = read_toml(CASE)
    data = apply_overrides(data, data["variants"]["ground_motion"], "variants.ground_motion")
    grid = data["grid"]
    cells = [int(round(grid["cell_size"] * n / H)) for n in grid["cells"]]
    data["grid"] = dict(grid, cell_size=H, cells=cells)
    data["particles_per_cell"] = PPC
    return parse_scene(data, CASE)


@pytest.fixture(scope="module")
def run():
    scene = coarse_scene()
    assert not scene.loads.forces, "the ground_motion variant has no other load"
    s = build_solver(scene, MPI.COMM_SELF)
    p = s.particles
    assert s.transfer.name == "flip" and s.transfer.pic_blend == 0.0  # momentum: see below
    x0 = p["x"][np.argsort(p["id"])].copy()
    base = x0[:, 1] < H / 3            # the lowest particle row (at h / 6 with 3 per cell)
    floor2 = (np.abs(x0[:, 1] - STOREY) < 0.3) & (np.min([np.abs(x0[:, 0] - c) for c in COLUMNS], axis=0) < 0.3)
    out = {"scene": scene, "solver": s, "bc_error": 0.0, "vmax": 1e-30, "u_sum": [], "t": [],
           "u_base": [], "u_floor2": [], "P": [], "J": [], "mass": p["m"].sum()}
    u_sum = 0.0
    while s.t < T_END:
        t_before = s.t
        s.step()
        dt = s.t - t_before
        v = v_exact(s.t)
        u_sum += dt * v               # the solver moves particles with the step's end velocity
        g = s.effect("ground_motion")
        err = np.abs(s.window.bc_vel[g.nodes[0], g.nodes[1], 0] - v).max()
        out["bc_error"] = max(out["bc_error"], err)
        out["vmax"] = max(out["vmax"], abs(v))
        ux = p["x"][np.argsort(p["id"]), 0] - x0[:, 0]
        out["t"].append(s.t)
        out["u_sum"].append(u_sum)
        out["u_base"].append(ux[base])
        out["u_floor2"].append(ux[floor2].mean())
        out["P"].append(float((p["m"] * p["v"][:, 0]).sum()))
        out["J"].append(float(s.effect("reactions").sums[:, 0].sum()))   # never taken here: the sums since t = 0
    for k in ("t", "u_sum", "P", "J", "u_floor2"):
        out[k] = np.array(out[k])
    out["u_base"] = np.array(out["u_base"])
    out["n_base"] = int(base.sum())
    return out


def test_the_generated_supports_are_the_driven_nodes(run):
    s, scene = run["solver"], run["scene"]
    supports = [b for b in scene.boundaries if b.name in ("c0_f0", "c1_f0", "c2_f0")]
    assert len(supports) == 3 and all(b.type == "fixed" and b.body is None for b in supports)
    assert sorted(b.name for b in s.effect("ground_motion").boundaries) == ["c0_f0", "c1_f0", "c2_f0"]
    # the grid nodes inside the three boxes (on y = 0), computed here from the boxes' corners
    w0 = s.decomp.window[0]
    want = set()
    for b in supports:
        i_lo = int(np.ceil((b.lower[0] - scene.grid.origin[0]) / H - 1e-9))
        i_hi = int(np.floor((b.upper[0] - scene.grid.origin[0]) / H + 1e-9))
        want |= {(i - w0, 0) for i in range(max(i_lo, 0), i_hi + 1)}
    got = set(zip(s.effect("ground_motion").nodes[0].tolist(), s.effect("ground_motion").nodes[1].tolist()))
    assert got == want and len(got) >= 3 * 6   # each box spans the column depth plus 2 cells a side
    # every step, the exact ground velocity at the step's end (round-off of Simpson's few terms)
    assert run["bc_error"] <= 1e-12 * run["vmax"]


def test_the_base_particles_move_with_the_ground(run):
    t, u_sum, u_base = run["t"], run["u_sum"], run["u_base"]
    u_g = np.array([u_exact(x) for x in t[::50]])
    umax = np.abs(u_g).max()
    assert run["n_base"] >= 3 and umax > 1e-3   # the window holds the record's first pulses (mm)
    # the sum of dt v(t_n+1) is the right Riemann sum of v: within max|a| T dt / 2 of u(T)
    dt = np.diff(np.concatenate([[0.0], t])).max()
    assert np.abs(u_sum[::50] - u_g).max() <= 0.5 * np.abs(A_REC).max() * T_END * dt
    # a base particle at y = h / 6 reads the driven row y = 0 and the free rows up to 2 h above
    # it (cubic B-splines); the column's displacement relative to its fixed base is at most the
    # fixed-fixed (double curvature) shape 3 s^2 - 2 s^3 of the first-storey drift, at s = (2 h +
    # h / 6) / storey height, times the drift (taken from this run's floor-2 joints, relative
    # to the ground)
    s_reach = (2 * H + H / 6) / STOREY
    shape = 3 * s_reach ** 2 - 2 * s_reach ** 3          # 0.033
    drift = np.abs(run["u_floor2"] - u_sum).max()
    gap = np.abs(u_base - u_sum[:, None]).max()
    assert gap <= shape * drift, (gap, shape * drift)
    # and so they follow the ground (not at rest): the bound is a small part of its motion
    assert shape * drift < 0.1 * umax


def test_momentum_equals_the_base_reaction_impulse_and_the_frame_lags(run):
    t, P, J, u_sum = run["t"], run["P"], run["J"], run["u_sum"]
    scale = run["mass"] * run["vmax"]
    # FLIP without PIC blend changes the particles' momentum by sum_i m_i dv_i: the internal
    # forces sum to zero (partition of unity) and no load acts, so what is left is the supports'
    # impulse. Tolerance: round-off of ~6,000 steps of sums over ~12,000 particles, each ~1e-16
    # of M max|v| (below 1e-11 of it)
    assert np.abs(P - J).max() <= 1e-9 * scale
    assert np.abs(J).max() > 1e-4 * scale    # the supports push (a resting frame has J = 0)
    # the first pulse: while the ground moves out in +x up to its first maximum, the base shear
    # on the frame (the support reaction) pushes it in +x, resisting -m a_g in the relative
    # frame; its impulse, the frame's momentum, stays positive and below M v_g (the frame lags)
    k_peak = int(np.argmax(u_sum[t < 0.12]))
    assert u_sum[k_peak] > 0
    early = slice(10, k_peak + 1)
    assert np.all(J[early] > 0)
    # the first floor lags the ground: its displacement relative to the ground is opposite.
    # A mode at rest under a base displacement u_g moves by w int sin w(t - s) u_g(s) ds, at most
    # (w t)^2 / 2 max|u_g| (|sin x| <= x): 0.17 of it for the fundamental mode (T1 = 0.913 s,
    # frame2d_model), which carries most of the floor masses, at t ~ 0.085 s; 0.5 leaves the
    # higher modes' smaller share room
    rel = run["u_floor2"][k_peak] - u_sum[k_peak]
    assert rel < 0 and abs(rel) > 0.5 * u_sum[k_peak]
