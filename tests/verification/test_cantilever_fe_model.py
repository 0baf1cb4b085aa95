"""The independent finite-element model of the large-rotation cantilever
(tests/verification/cantilever_fe_model.py; issue 20) is itself checked before pmpm is judged
against it: it conserves energy (an elastic solid, a clamp that does no work, central
differences: the balance's error is of the step's order, far below 1e-4 of m g L), and under
mesh refinement its corner history converges, each refinement changing it by less than the one
before (quadratic elements: the change falls by at least a factor 2 per refinement of the
element size by 1.5).
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from cantilever_fe_model import corner_history  # noqa: E402

#: the balance's worst error over 2.8 s, relative to m g L (the gravity work of the whole mass
#: falling one beam length); central differences at 0.3 of the wave's crossing time keep it at
#: 1e-6 to 1e-7 (a step instability or a sign error in the stress grows it to order 1)
ENERGY_LIMIT = 1.0e-4


def _rms(a, b):
    return math.sqrt(float(np.mean((a - b) ** 2)))


def test_the_fe_model_conserves_energy_and_converges_under_mesh_refinement():
    runs = {ny: corner_history(ny) for ny in (2, 3, 4)}
    for ny, (t, uy, err, dt) in runs.items():
        assert err < ENERGY_LIMIT, (ny, err)
        assert abs(t[-1] - 2.8) < 1e-9
    first = _rms(runs[2][1], runs[3][1])
    second = _rms(runs[3][1], runs[4][1])
    assert second < 0.5 * first, (first, second)
