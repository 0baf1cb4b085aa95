"""The main job written as a [frame] against the same scene written by hand (issue 22, items 4, 6).

``cases/portal_frame.toml`` describes the portal as nodes, members, sections, supports and a
nodal load; ``portal_frame_handwritten.toml`` (beside this file) is the scene as it was written
before, strip by strip. The front end must add nothing to the model: the expansion must give
the same particles (positions, volumes, masses, bodies), the same constrained grid nodes, the
same particles under the load and the same time step, so the step is the same computation
(same bodies, same step cost); the joint history of a short run must then be identical, which
is stronger than the issue's "first peak and period within 0.5%" (checked as well).
"""
import os
import sys

import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, os.path.dirname(__file__))
import frame_runs  # noqa: E402

from pmpm.build import build_solver
from pmpm.core.kernels import MASS  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
HANDWRITTEN = os.path.join(HERE, "portal_frame_handwritten.toml")
FRAME = frame_runs.SCENE
#: a coarse grid for the short run (same domain): what is compared is the expansion, not the MPM
COARSE, T_SHORT = 0.1, 0.05


def _peak_and_period(t, u):
    """First maximum and twice the first half-period between crossings of half the peak."""
    i = int(np.argmax(u[t < 0.03]))
    d = u - 0.5 * u[i]
    k = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    tc = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
    return u[i], 2 * float(np.diff(tc[:2])[0])


@pytest.fixture(scope="module")
def solvers():
    out = {}
    for name, path in (("frame", FRAME), ("hand", HANDWRITTEN)):
        out[name] = build_solver(frame_runs.frame_scene("elastic", scene=path), MPI.COMM_SELF)
    return out


def test_expansion_gives_the_hand_written_particles(solvers):
    a, b = solvers["frame"].particles, solvers["hand"].particles
    assert len(a["x"]) == len(b["x"]) > 7000
    for field in ("x", "v", "vol", "m", "body", "mat", "load_id", "load_w"):
        assert np.array_equal(a[field], b[field]), field


def test_expansion_gives_the_hand_written_supports_and_time_step(solvers):
    fa, fb = solvers["frame"], solvers["hand"]
    assert fa.dt == fb.dt
    # the generated boxes are narrower than the hand-written ones: the nodes they leave out lie
    # beyond the B-splines' reach of every particle, hold no mass and never move; the
    # constrained nodes that carry mass (the ones that act) are the same
    fa.step()  # the grid then holds the nodal masses of the step
    heavy = fa.window.G[..., MASS] > 0
    ma, mb = fa.window.bc_mask, fb.window.bc_mask
    assert ma.shape == mb.shape
    assert np.array_equal(ma[heavy], mb[heavy])
    assert int(ma[heavy].sum()) >= 2 * 2 * 7  # both bases: at least the column's width of nodes
    assert np.all(ma <= mb)
    assert [bc.name for bc in fa.effect("boundary").boundaries] == [bc.name for bc in fb.effect("boundary").boundaries]
    assert [(bc.moment_about, bc.reaction) for bc in fa.effect("boundary").boundaries] == \
           [((0.0, 0.0), True), ((6.096, 0.0), True)]


def test_expansion_gives_the_hand_written_cuts_and_tracks(solvers):
    """Same cut positions on the same bodies (names derived from member and node names)."""
    fa, fb = (frame_runs.frame_scene("elastic", scene=path) for path in (FRAME, HANDWRITTEN))
    ca = [(s.body, round(s.position, 9)) for s in fa.output.sections]
    cb = [(s.body.replace(" ", "_"), round(s.position, 9)) for s in fb.output.sections]
    assert sorted(ca) == sorted(cb)
    tracks = {t.name: t.point for t in fa.output.track}
    for t in fb.output.track:
        assert tracks[t.name] == t.point


def test_same_joint_history_on_a_short_run():
    """The upper-left joint's drift over 0.05 s at 0.1 m cells: identical histories, hence the
    same first peak and period (the issue asks 0.5%)."""
    ra = frame_runs.run_frame("elastic", T_SHORT, every=5, cell_size=COARSE)
    rb = frame_runs.run_frame("elastic", T_SHORT, every=5, cell_size=COARSE, scene=HANDWRITTEN)
    assert np.array_equal(ra["t"], rb["t"]) and np.array_equal(ra["ux"], rb["ux"])
    pa, Ta = _peak_and_period(ra["t"], ra["ux"])
    pb, Tb = _peak_and_period(rb["t"], rb["ux"])
    assert pa > 0.03  # a real sway (the joint drifts about 45 mm)
    assert pa == pytest.approx(pb, rel=0.005) and Ta == pytest.approx(Tb, rel=0.005)
