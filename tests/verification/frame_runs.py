"""MPM runs of the portal frame shared by the frame tests (one run per process and setting).

test_portal_frame.py (against the beam model) and test_frame_continuum.py (against the plane-
stress FE model) read the same elastic run, so CI pays for it once; runs are cached per process
by their arguments.
"""
import dataclasses
from functools import lru_cache

import numpy as np
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.io.tracking import Tracker
from pmpm.results.recorder import StructuralRecorder
from pmpm.scene.config import apply_overrides, parse_scene, read_toml

SCENE = "cases/portal_frame.toml"
COLUMNS_X = (0.0, 6.096)
#: the cell size of the frame tests' runs (m): their tolerances are derived there
#: (test_frame_continuum.py, from 0.05 against 0.025 m), whatever the main job's own; the main
#: job's resolution is held by test_main_job_amplitude.py
TEST_CELL = 0.05


def base_moments(s, y0=0.1, y1=0.3):
    """Bending moment in each column over the band y0 < y < y1 near the base:
    M = sum sigma_yy (x - x_c) V / (y1 - y0)  (thickness is inside V)."""
    p = s.particles
    out = []
    for xc in COLUMNS_X:
        band = (np.abs(p["x0"][:, 0] - xc) < 0.2) & (p["x0"][:, 1] > y0) & (p["x0"][:, 1] < y1)
        out.append(np.sum(p["stress"][band, 1] * (p["x"][band, 0] - xc) * p["vol"][band]) / (y1 - y0))
    return out


def frame_scene(variant, damping=0.0, cell_size=None, scene=SCENE, supports=None, load_scale=1.0):
    """The scene's ``variant``, with mass-proportional ``damping`` (1/s) through its
    ``loads.damping`` key when non-zero (validated like any scene file), on cells of
    ``cell_size`` (default TEST_CELL) over the same domain (x in [-0.5, 6.6], y in [0, 4.2])."""
    data = read_toml(scene)
    data = apply_overrides(data, data["variants"][variant], f"variants.{variant}")
    if damping:
        data = apply_overrides(data, {"loads": {"damping": float(damping)}}, "test")
    if supports or load_scale != 1.0:  # the frame's support type, its nodal loads scaled
        for s in data["frame"]["supports"]:
            s["type"] = supports or s["type"]
        for f in data["frame"].get("loads", []):
            f["force"] = [load_scale * c for c in f["force"]]
    cell_size = cell_size or TEST_CELL
    if cell_size != data["grid"]["cell_size"]:
        extent = [h * n for h, n in zip([data["grid"]["cell_size"]] * 2, data["grid"]["cells"])]
        cells = [int(round(e / cell_size)) for e in extent]
        assert all(abs(n * cell_size - e) < 1e-9 for n, e in zip(cells, extent)), "cells must tile the domain"
        data["grid"] = dict(data["grid"], cell_size=float(cell_size), cells=cells)
    return dataclasses.replace(parse_scene(data, scene), variant=variant)


@lru_cache(maxsize=None)
def run_frame(variant, t_end, damping=0.0, every=20, cell_size=None, scene=SCENE, supports=None, load_scale=1.0):
    """Run the frame serially to ``t_end`` and sample every ``every`` steps: time, the upper-left
    joint's ux, base moments and energies; the solver is returned for its final state."""
    scene = frame_scene(variant, damping, cell_size, scene, supports, load_scale)
    s = build_solver(scene, MPI.COMM_SELF)
    tr = Tracker([t for t in scene.output.track if t.name == "upper_left_joint"], s)
    rec = StructuralRecorder(s)
    t, ux, moments, energies, cuts, reactions = [], [], [], [], [], []
    while s.t < t_end:
        s.step()
        if s.step_count % every == 0:
            t.append(s.t)
            ux.append(tr.sample()[0, 0])
            moments.append(base_moments(s))
            energies.append(s.energies())
            c, r = rec.sample()
            cuts.append(c.copy())
            reactions.append(r.copy())
    return {"t": np.array(t), "ux": np.array(ux), "moments": np.array(moments),
            "energies": energies, "solver": s, "cut_names": [c.name for c in (s.effect("sections") or [])],
            "cuts": np.array(cuts), "reaction_names": list(rec.reaction_names), "reactions": np.array(reactions)}
