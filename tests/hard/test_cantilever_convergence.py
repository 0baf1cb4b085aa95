"""The large-rotation cantilever converges (issue 12, item 5): cases/hard/cantilever_large_rotation.toml
run as its variants ``<material>_h<cell size>``.

Every variant must run to its end time (2.8 s >= the 2.5 s the issue asks for: the first swing
down and back) with no particle leaving the grid and no separation, and keep its energy balance
within 2%. The two coarser cell sizes of both materials run here (CPDI at CFL 0.25: about 26 s
in all, measured at load 5); the finest (0.0625 m, about 2 min per material) runs when
PMPM_CANTILEVER_FINE=1 or by the study command
``python -m pmpm.benchmarks.studies.cantilever_convergence``, which also prints the table of
docs/hard_cases.md. With it the test checks the issue's convergence criterion: the successive
differences of the largest tip drop shrink and the two finest are within 2%.
"""
import functools
import os

import pytest

from pmpm.benchmarks.studies.cantilever_convergence import CELL_SIZES, MATERIALS, run_variant

#: the issue's tolerance on the energy balance (relative to the largest energy in play)
ENERGY_TOLERANCE = 0.02
#: "no separation": particles that started as lattice neighbours (a quarter cell apart) stay
#: within one cell of each other; a larger gap is an empty cell inside the material, a crack.
#: (Measured with CPDI: 0.46 to 0.59 in whole runs, the largest at the clamp's top corner;
#: with the B-spline GIMP the finest beams tore off the clamp with gaps of 1.6 and 2.5.)
SEPARATION_CELLS = 1.0
FINE = os.environ.get("PMPM_CANTILEVER_FINE") == "1"
COARSE = [f"{m}_h{h}" for m in MATERIALS for h in CELL_SIZES[:2]]


@functools.lru_cache(maxsize=None)
def result(variant):
    return run_variant(variant)[0]


@pytest.mark.parametrize("variant", COARSE)
def test_runs_whole_to_its_end_within_the_energy_tolerance(variant):
    r = result(variant)
    assert r["error"] is None, f"{variant}: {r['error']}"
    assert r["t_end"] >= 2.5 and abs(r["t_end"] - 2.8) < 1e-9
    assert r["separation"] < SEPARATION_CELLS, f"{variant}: neighbours {r['separation']:.2f} cells apart"
    assert r["excess"] < ENERGY_TOLERANCE and r["excess_exact"] < ENERGY_TOLERANCE, r
    # the swing really is large and comes back: the tip drops past 3 m (the published reference
    # drops 3.28 m) and rises back above -2 m, more than half way up, before the end
    assert r["largest_drop"] > 3.0 and r["rebound"] > -2.0, r


@pytest.mark.slow
@pytest.mark.skipif(not FINE, reason="the 0.0625 m variants take about 2 min each: set "
                                     "PMPM_CANTILEVER_FINE=1 or run the study command")
@pytest.mark.parametrize("material", MATERIALS)
def test_largest_tip_drop_converges(material):
    runs = [result(f"{material}_h{h}") for h in CELL_SIZES]
    for r in runs:
        assert r["error"] is None and r["separation"] < SEPARATION_CELLS, r
        assert r["excess"] < ENERGY_TOLERANCE and r["excess_exact"] < ENERGY_TOLERANCE, r
    d = [r["largest_drop"] for r in runs]
    diffs = [abs(a - b) / b for a, b in zip(d, d[1:])]
    assert diffs[1] < diffs[0], f"{material}: drops {d}, differences {diffs} do not shrink"
    assert diffs[1] < 0.02, f"{material}: the two finest differ by {100 * diffs[1]:.2f}% (issue: 2%)"
