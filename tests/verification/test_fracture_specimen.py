"""The round-notched steel plate to ductile fracture initiation: pmpm against an independent
finite-element model of the same specimen, material and locus (issue 39, "Verification").

The FE model is tests/verification/notched_specimen_fe_model.py (its own mesh, elements,
plane-stress return mapping and void growth damage; nothing from pmpm); the comparison is
studies/fracture_specimen.py, whose command prints the finer grids' table
(``python -m studies.fracture_specimen --sizes 3.333 2 1``). Here the two coarsest sizes, the
MPM cell and the FE element edge equal: 10/3 mm (the ligament 7.2 cells) and 2 mm (12 cells).

What is asserted, and where the bounds come from:
- the force-displacement curve to initiation (the held face's reaction averaged over 0.1 ms
  windows, which average out the ringing of the sudden pull the same way in both models):
  its largest difference is at most h / ligament of the FE peak force. The particles (spacing
  h / 2) represent each notch root to within half a particle domain, so the ligament pmpm pulls
  can differ from the 24 mm by up to h / 2 in all, and the net-section force by h / (2 x 24 mm);
  the bound allows as much again for the FE model's own discretisation error (its 4-node
  elements are stiffer than the converged solution);
- the displacement of the pulled face at fracture initiation (first point with damage 1), at
  2 mm: within 2 h / ligament of the FE model's, the ligament's representation (above) shifting
  the net-section strain by up to h / ligament and the strain concentration at the root, which
  the damage integrates, by as much again. At 10/3 mm the root is resolved by one particle
  layer: only that both models initiate, at a notch;
  Caveat (docs/fracture.md): the study's 1 mm run shows pmpm's initiation moving away from the
  FE model's under refinement (the two cross near 2 mm), so this check guards the 2 mm value
  against a change, it does not show convergence; the force check does converge (5%, 3%, 1%);
- both models initiate at a notch's surface, within a cell of it (1.5 cells for pmpm's failed
  particles, whose positions are the start's): the strain is highest at the notch, where the
  free surface's triaxiality is 1/3 (the coarse FE mesh's first point is 4 mm off the root,
  on the arc).
Planted bugs that the test catches (checked once, then restored): the FE model's damage with
exp(-1.5 T) replaced by exp(+1.5 T) (initiation far later: the displacement check fails); pmpm's
bilinear hardening read as twice its value (forces above the bound).
"""
import math

import numpy as np
import pytest

from studies import fracture_specimen as study

LIGAMENT = 0.024
CENTRES = ((0.05, 0.0), (0.05, 0.04))   # of the notches' arcs, radius 8 mm


def _near_notch(x, y, tol):
    """Within ``tol`` of a notch's surface (its arc)."""
    return min(abs(math.hypot(x - cx, y - cy) - 0.008) for cx, cy in CENTRES) <= tol


@pytest.mark.parametrize("h, end_time", [(0.1 / 30, 1.5e-3), (0.002, 1.3e-3)])
def test_specimen_against_fe(h, end_time):
    sp = study.fe_module().SPECIMEN
    a, b = study.mpm(h, end_time), study.fe(h, end_time)
    assert a["initiation"] is not None and b["initiation"] is not None
    until = 1e-4 * math.floor(min(a["initiation"], b["initiation"]) / 1e-4)
    _, fa = study.window_means(a["time"], a["force"], 1e-4, until)
    _, fb = study.window_means(b["time"], b["force"], 1e-4, until)
    diff = np.max(np.abs(fa - fb)) / np.max(np.abs(fb))
    ua, ub = sp["pull"] * a["initiation"], sp["pull"] * b["initiation"]
    print(f"h = {h * 1e3:.3g} mm: force difference {100 * diff:.1f}% of the FE peak "
          f"(bound {100 * h / LIGAMENT:.1f}%); initiation at u = {ua * 1e3:.3f} mm (pmpm), "
          f"{ub * 1e3:.3f} mm (FE); wall {a['wall']:.0f} s / {b['wall']:.0f} s")
    assert diff <= h / LIGAMENT
    assert _near_notch(*b["where"], h)
    r = a["result"]
    failed = r.frames["damage"][-1] >= 1.0
    x0 = r.frames["x"][0][failed]
    assert failed.any() and all(_near_notch(x, y, 1.5 * h) for x, y in x0)
    if h < 0.003:
        assert abs(ua - ub) <= 2 * h / LIGAMENT * ub
