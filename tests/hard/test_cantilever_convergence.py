"""The large-rotation cantilever as published (issue 20): cases/hard/cantilever_large_rotation.toml,
the benchmark of Sadeghirad, Brannon & Burghardt 2011 (plane strain, neo-Hookean, the clamp
alone, the grid extended on every side), against its finite-element curve
(cases/hard/data/cantilever_fe_corner.csv, the lower free corner's uy).

CI runs the two coarser neo-Hookean cell sizes (0.25 and 0.125 m; about 80 s together on this
machine when it is lightly loaded); the finest (0.0625 m, several minutes) runs when
PMPM_CANTILEVER_FINE=1 or by ``python -m studies.cantilever_convergence``, which
prints the table of docs/hard_cases.md.

Where the limits come from:

* RMS gap to the FE curve, 0.10 m. The curve is digitised to two decimals from a figure whose
  vertical axis spans about 3.5 m: reading error about 0.02 to 0.03 m (a 1% of the axis pixel
  error). The FE solution is itself a discretisation (the paper's mesh; not converged to
  better than about 1% of the 3.28 m drop, 0.03 m). A beam that holds, swings down to within
  3% of the published largest drop and comes back in phase is inside 0.1 m; a beam torn off its
  clamp (the issue's failure: the root moved 0.77 m by 1.0 s, the beam fell) is off by metres,
  and a beam 10% too stiff or too flexible (a drop 0.33 m off, a period 5% off) is off by more
  than 0.15 m over the swing back.
* Energy, 2% lost and 2% gained: the scene conserves energy (no wall, no contact, no damping,
  an elastic material; the clamp does no work), so both signs are discretisation error; 2% is
  the hard cases' tolerance (tests/hard/hard_cases.py), checked both ways here.
* Whole: no particle leaves the grid and lattice neighbours stay within a cell of each other.
* The corner's largest drop within 5% of the FE curve's 3.28 m (the reading error above plus
  the first-order error of a beam four cells deep at 0.25 m).

Converged over the whole history (issue 20, item 3) is judged against the independent FE model
on a converged mesh (tests/verification/cantilever_fe_model.py, 9-node elements 7 deep; its own
convergence is tested in tests/verification/test_cantilever_fe_model.py), not against the
digitised curve: that curve is a coarse-mesh solution (the FE model matches it best with 2
elements through the depth, RMS 0.047 m, and moves away from it as its mesh is refined, to
0.081 / 0.083 m at 6 and 7 deep, which differ by 0.003 m: the converged swing back is about
0.05 s later than the published one; docs/hard_cases.md). A method that converges must therefore
close its gap to the converged model, and CI asks the two coarser grids for at least
half-order convergence: halving the cell cuts the RMS gap by at least 2^-1/2 (first order would
halve it).
"""
import functools
import os

import pytest

from studies.cantilever_convergence import CELL_SIZES, FEM_LARGEST_DROP, run_variant

#: a gain or a loss of energy, relative to the largest energy in play (see above)
ENERGY_TOLERANCE = 0.02
#: RMS of (pmpm - FE) over the curve's samples to 2.8 s (see above)
RMS_LIMIT = 0.10
#: the corner's largest drop against the FE curve's (see above)
DROP_TOLERANCE = 0.05
#: "no separation": lattice neighbours (a quarter cell apart) stay within one cell
SEPARATION_CELLS = 1.0
FINE = os.environ.get("PMPM_CANTILEVER_FINE") == "1"
COARSE = [f"neo_hookean_h{h}" for h in CELL_SIZES[:2]]


@functools.lru_cache(maxsize=None)
def result(variant):
    return run_variant(variant)[0]


@pytest.mark.parametrize("variant", COARSE)
def test_follows_the_fe_curve_whole_with_energy_conserved(variant):
    r = result(variant)
    assert r["error"] is None, f"{variant}: {r['error']}"
    assert abs(r["t_end"] - 2.8) < 1e-9
    assert r["separation"] < SEPARATION_CELLS, f"{variant}: neighbours {r['separation']:.2f} cells apart"
    for key in ("excess", "excess_exact", "loss", "loss_exact"):
        assert r[key] < ENERGY_TOLERANCE, f"{variant}: {key} {100 * r[key]:.2f}%"
    assert r["rms_gap_fe"] < RMS_LIMIT, f"{variant}: RMS gap to the FE curve {r['rms_gap_fe']:.3f} m"
    assert abs(r["corner_largest_drop"] - FEM_LARGEST_DROP) < DROP_TOLERANCE * FEM_LARGEST_DROP, r


def test_the_gap_to_the_converged_fe_model_shrinks_at_least_at_half_order():
    coarse, fine = (result(v) for v in COARSE)
    assert coarse["error"] is None and fine["error"] is None
    ratio = fine["rms_gap_reference"] / coarse["rms_gap_reference"]
    assert ratio < 2 ** -0.5, (coarse["rms_gap_reference"], fine["rms_gap_reference"])


@pytest.mark.slow
@pytest.mark.skipif(not FINE, reason="the 0.0625 m variant takes several minutes: set "
                                     "PMPM_CANTILEVER_FINE=1 or run the study command")
def test_the_gap_to_the_fe_curve_shrinks_with_refinement():
    """Issue 20, item 3: the RMS gap to the converged FE model shrinks with each refinement and
    is at most 0.05 m at the finest; the finest corner drop within 1% of 3.28 m; energy within
    1% both ways."""
    runs = [result(f"neo_hookean_h{h}") for h in CELL_SIZES]
    for r in runs:
        assert r["error"] is None and r["separation"] < SEPARATION_CELLS, r
        assert max(r["loss"], r["excess"]) < 0.01, r
    gaps = [r["rms_gap_reference"] for r in runs]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] <= 0.05, gaps
    assert abs(runs[2]["corner_largest_drop"] - FEM_LARGEST_DROP) < 0.01 * FEM_LARGEST_DROP, runs[2]
