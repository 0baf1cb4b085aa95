"""The CFL-number part of ``pmpm bench accuracy`` (studies/accuracy_cfl.py).

* the bisection for the largest stable CFL number finds a known threshold;
* the bar's time-step error is that of the explicit central-difference update: a mode of
  frequency omega advanced with step dt runs at (2 / dt) arcsin(omega dt / 2), i.e. fast by
  (omega dt)^2 / 24, so after one period its phase leads by 2 pi (omega dt)^2 / 24, and the
  error measure (largest |u - u_exact| / amplitude) moves by that much per unit of CFL^2
  (dt = CFL h / c). The spatial error lags the phase, so the total error falls as the CFL
  number grows; the fitted slope of error against CFL^2 must be this theory's, to within a
  factor 1.5 either way (the measure is a maximum over the run and the particles, not the
  phase at the end, and the MUSL velocity projection adds its own small dt-dependence);
* the recommendation takes the largest swept CFL number that still meets the target.
"""
import math

import numpy as np
import pytest

from studies import accuracy as A
from studies import accuracy_cfl as C


def test_bisection_brackets_a_known_threshold():
    threshold = 1.234
    calls = []

    def run(c):
        calls.append(c)
        return {"cfl": c, "stable": c <= threshold}

    known = [run(c) for c in C.CFL_VALUES]
    value, extra = C.largest_stable(run, known, tol=0.01)
    assert threshold - 0.01 <= value <= threshold
    assert all(r["stable"] == (r["cfl"] <= threshold) for r in extra)
    # an unstable value among the swept ones bounds the search from above at once
    value, _ = C.largest_stable(lambda c: {"cfl": c, "stable": c <= 0.6},
                                [{"cfl": c, "stable": c <= 0.6} for c in C.CFL_VALUES], tol=0.01)
    assert 0.59 <= value <= 0.6


@pytest.mark.parametrize("shape", ["linear", "cubic"])
def test_bar_time_step_error_is_the_central_difference_phase_error(shape):
    cells = 40
    rows = [A.run_bar(cells, shape, "musl", 2, cfl=c) for c in C.CFL_VALUES]
    assert all(r["energy_drift"] < C.STABLE_DRIFT for r in rows)
    slope = np.polyfit([c * c for c in C.CFL_VALUES], [r["error"] for r in rows], 1)[0]
    h = A.BAR_L / cells
    wave = math.sqrt(A.BAR_E / A.BAR_RHO)  # nu = 0: the plane-stress wave speed is sqrt(E / rho)
    theory = -2 * math.pi * (A.BAR_OMEGA * h / wave) ** 2 / 24
    assert theory / 1.5 >= slope >= theory * 1.5, (slope, theory)


def _row(shape, cfl, error, stable=True, **kw):
    return dict(problem="frame", shape=shape, ppc=2, scheme="musl", cell_size=0.05, cfl=cfl, error=error,
                stable=stable, status="ok", steps=int(1000 / cfl), **kw)


def test_recommendation_takes_the_largest_cfl_that_meets_the_target():
    rows = [_row("cubic", 0.3, 0.004), _row("cubic", 0.5, 0.004), _row("cubic", 0.7, 0.006),
            _row("cubic", 0.9, 0.012), _row("cubic", 1.2, 0.02, bisection=True)]
    rec = {"shape": "cubic", "ppc": 2, "scheme": "musl", "cell_size": 0.05, "error": 0.004,
           "wall_s": 10.0, "cpu_s": 9.0}
    best = {"frame": {"cubic": 1.2}}
    r = C.cfl_recommendation(rec, rows, best, 0.01)
    assert r["swept"] and r["cfl"] == 0.7
    assert r["wall_s"] == pytest.approx(10.0 * 0.5 / 0.7)
    # at most SAFETY times the largest stable value
    r = C.cfl_recommendation(rec, rows, {"frame": {"cubic": 0.75}}, 0.1)
    assert r["cfl"] == 0.5
    # a setting the CFL sweep did not cover keeps the main sweep's CFL number
    r = C.cfl_recommendation(dict(rec, cell_size=0.1), rows, best, 0.01)
    assert not r["swept"] and r["cfl"] == 0.5
    lines = "\n".join(C.cfl_markdown(rows, best))
    assert "| frame | cubic | 0.05 | 0.7 |" in lines and "cubic 1.2" in lines
