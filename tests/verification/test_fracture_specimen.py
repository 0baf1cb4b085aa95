"""The round-notched steel plate to ductile fracture: pmpm against an independent finite-element
model of the same specimen, material and locus, and pmpm's refinement (issue 39, "Verification").

The FE model is tests/verification/notched_specimen_fe_model.py (its own mesh, elements,
plane-stress return mapping, void growth damage and nonlocal average; nothing from pmpm); the
comparison is studies/fracture_specimen.py, whose command prints the finer grids' tables
(``python -m studies.fracture_specimen --sizes 3.3333333333 3 2 1``). Here the coarsest two
grids that resolve the specimen's characteristic length, the MPM cell and the FE element edge
equal: 2 mm (the ligament 12 cells) and 1.5 mm (16 cells), with the nonlocal criterion over
l* = 6 mm (a point fails where its own void growth index and the index's average over l* have
both reached 1) and the release over the crack band of BAND_CELLS = 1.3 cells, run to
END_TIME = 2.7 ms, when the crack has crossed the ligament. Resolving l* takes l* / h >= 3
(3 and 4 here): at 3 mm and 10/3 mm (l* / h = 2 and 1.8, one smoothing pass or less) pmpm's
initiation is still 28% and 13% before the 2 mm one while the FE model's moves by 1.1% and 2.5%
(docs/fracture.md, the refinement table), so those grids are not the refinement's.

What is asserted, and where the bounds come from:
- the force-displacement curve to initiation (the held face's reaction averaged over 0.1 ms
  windows, which average out the ringing of the sudden pull the same way in both models):
  its largest difference is at most h / ligament of the FE peak force. The particles (spacing
  h / 2) represent each notch root to within half a particle domain, so the ligament pmpm pulls
  can differ from the 24 mm by up to h / 2 in all, and the net-section force by h / (2 x 24 mm);
  the bound allows as much again for the FE model's own discretisation error;
- the displacement of the pulled face at fracture initiation: within 2 h / ligament of the FE
  model's (the ligament's representation shifting the net-section strain by up to
  h / ligament, and the strain field the average reads by as much again);
- the FE model initiates within a cell of a notch's surface, and pmpm's crack stays in the
  notched section (every failed particle within a notch radius of mid-length);
- refinement (test_refinement, a strict xfail: it fails, below): pmpm's displacement at
  initiation moves between the two grids by no more than the FE model's own move plus the
  issue's 5% (the FE model, body-fitted, shows what discretising this specimen at these sizes
  costs);
- the fracture work by END_TIME (test_fracture_work_is_gf_times_the_ligament) is G_f A within
  the band's discreteness: every released point dissipates G_f / l_c per unit volume (the
  closed form, tests/unit/test_fracture_point.py), and l_c is the width of the band the crack
  runs in, max(BAND_CELLS h, BAND_LSTAR l*) (2.6 mm at 2 mm, the cells' bound; 2.4 mm at
  1.5 mm, the l* bound); the band is made of whole particle rows h / 2 apart, and a strip of
  width l_c holds rows whose width is within h / 2 of l_c, so |W / (G_f A) - 1| <= h / (2 l_c)
  (38% at 2 mm, 31% at 1.5 mm). The release length in cells alone (band_lstar left out,
  l_c = 1.3 h) gives 1.38 G_f A at 1.5 mm, outside it (docs/fracture.md, "The release length once l* is resolved").
The xfail is the defect the refinement found (docs/fracture.md, "l* = 6 mm"): pmpm's initiation
moves by -19.8% from 2 to 1.5 mm (and by -3.0% from 2 to 1 mm) while the FE model's moves by
1.4%.
Planted bugs: band_lstar left out of the specimen (``--band-lstar 0``: the release length in
cells alone) gives 1.376 G_f A at 1.5 mm, outside 1 +- 0.31 (the fifth session's check,
docs/fracture.md); the condition on a point's own index left out (failure on the average
alone) gives 1.012 G_f A at 2 mm (1.63 cells) against 0.930 with l_c = 2.6 mm: within the
bound, so this file does not catch it (tests/unit/test_fracture_nonlocal.py does). The second
session's planted bugs (the FE model's exp(-1.5 T) as exp(+1.5 T); pmpm's hardening doubled)
were caught by the force and initiation checks at the coarser grids then; not rechecked at
these grids.
"""
import math

import numpy as np
import pytest

from studies import fracture_specimen as study

LIGAMENT = 0.024
CENTRES = ((0.05, 0.0), (0.05, 0.04))   # of the notches' arcs, radius 8 mm
SIZES = (0.002, 0.0015)
END = study.END_TIME


def _near_notch(x, y, tol):
    """Within ``tol`` of a notch's surface (its arc)."""
    return min(abs(math.hypot(x - cx, y - cy) - 0.008) for cx, cy in CENTRES) <= tol


@pytest.fixture(scope="module")
def rows():
    return {h: study.compare(h, 1e-4, END) for h in SIZES}


@pytest.mark.parametrize("h", SIZES)
def test_specimen_against_fe(rows, h):
    r = rows[h]
    print(f"h = {h * 1e3:.3g} mm: force difference {100 * r['force_max_diff']:.1f}% of the FE peak "
          f"(bound {100 * h / LIGAMENT:.1f}%); initiation at u = {r['u_init_mpm_mm']:.3f} mm (pmpm), "
          f"{r['u_init_fe_mm']:.3f} mm (FE); fracture work {r['fracture_work_over_GfA']:.3f} G_f A, band "
          f"{r['band_cells']:.2f} cells; wall {r['wall_mpm_s']:.0f} s / {r['wall_fe_s']:.0f} s")
    assert math.isfinite(r["u_init_mpm_mm"]) and math.isfinite(r["u_init_fe_mm"])
    assert r["force_max_diff"] <= h / LIGAMENT
    assert _near_notch(*r["fe_where"], h)
    x0 = np.asarray(r["failed_x0"])
    assert len(x0) and np.all(np.abs(x0[:, 0] - 0.05) <= 0.008)
    assert abs(r["u_init_diff"]) <= 2 * h / LIGAMENT


# Known defects, measured by the session that set l* = 6 mm (docs/fracture.md, "l* = 6 mm"):
# strict, so that these fail the day they pass and the bounds become plain assertions again.
INITIATION_SCATTER = ("pmpm's initiation depends on the particle lattice's alignment with the notch: 4.13, 3.99, "
                      "4.00 mm at 2, 1.33, 1 mm (a particle-domain edge on the notch root), 3.44 and 3.69 mm at "
                      "1.5 and 1.2 mm (not); the FE model's within 1.4% (docs/fracture.md)")


@pytest.mark.xfail(strict=True, reason=INITIATION_SCATTER)
def test_refinement(rows):
    coarse, fine = (rows[h] for h in SIZES)
    move = (fine["u_init_mpm_mm"] - coarse["u_init_mpm_mm"]) / fine["u_init_mpm_mm"]
    fe_move = (fine["u_init_fe_mm"] - coarse["u_init_fe_mm"]) / fine["u_init_fe_mm"]
    print(f"initiation moves by {100 * move:+.1f}% (pmpm), {100 * fe_move:+.1f}% (FE)")
    assert abs(move) <= abs(fe_move) + 0.05


@pytest.mark.parametrize("h", SIZES)
def test_fracture_work_is_gf_times_the_ligament(rows, h):
    r = rows[h]
    lc = max(study.BAND_CELLS * h, study.BAND_LSTAR * study.fe_module().SPECIMEN["characteristic_length"])
    assert r["l_c_mm"] == pytest.approx(lc * 1e3, rel=1e-12)   # the run's own release length
    print(f"h = {h * 1e3:.3g} mm: fracture work {r['fracture_work_over_GfA']:.3f} G_f A (bound 1 +- "
          f"{h / (2 * lc):.2f}), band {r['band_cells']:.2f} cells, {r['band_mm']:.2f} mm, l_c {lc * 1e3:.2f} mm")
    assert abs(r["fracture_work_over_GfA"] - 1.0) <= h / (2 * lc)
