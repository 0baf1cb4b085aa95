"""Two elastic disks colliding (Sulsky, Chen & Schreyer 1994; docs/verification.md section 4)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.scene.config import load_scene
from pmpm.build import build_solver

KE0 = 2 * 0.5 * (1000 * math.pi * 0.2 ** 2) * (0.1 ** 2 + 0.1 ** 2)  # 2.513 per unit thickness


@pytest.fixture(scope="module")
def history():
    s = build_solver(load_scene("cases/two_disks.toml")[0], MPI.COMM_SELF)
    rows = []
    while s.t < 3.0 - 1e-12:
        s.step()
        p = s.particles
        lower = p["body"] == 0
        v_com = (p["m"][lower, None] * p["v"][lower]).sum(0) / p["m"][lower].sum()
        e = s.energies()
        finite = all(np.isfinite(p[k]).all() for k in ("x", "v", "stress"))
        rows.append((s.t, v_com[0], v_com[1], e["total"], e["kinetic"], finite))
    return np.array(rows)


def test_initial_kinetic_energy_is_sulskys(history):
    s = build_solver(load_scene("cases/two_disks.toml")[0], MPI.COMM_SELF)
    assert s.energies()["kinetic"] == pytest.approx(KE0, rel=1e-12)  # volumes carry the exact area
    assert KE0 == pytest.approx(2.513, abs=5e-4)


def test_disks_meet_near_the_predicted_time(history):
    """Surfaces touch at t = (0.5 sqrt 2 - 0.4) / (0.2 sqrt 2) = 1.086. Through the grid the disks
    feel each other once their supports overlap (two cells each side for cubic splines), so
    the momentum exchange starts earlier; the bulk of it (the lower disk's velocity has lost
    half its initial value) must fall within a contact duration (about 0.5) of 1.086."""
    t, vx = history[:, 0], history[:, 1]
    half = t[np.argmax(vx < 0.05)]
    assert 1.086 - 0.1 < half < 1.086 + 0.5
    assert vx[t < 0.5].min() > 0.0999  # no interaction while far apart


def test_disks_bounce_apart(history):
    t, vx, vy = history[:, 0], history[:, 1], history[:, 2]
    assert vx[-1] < -0.05 and vy[-1] < -0.05          # moving back at most of the initial speed
    assert vx[-1] == pytest.approx(vy[-1], rel=1e-6)  # the symmetry about the diagonal holds


def test_total_energy_within_five_percent(history):
    """kinetic + internal work (integrated stress power) stays within 5% of 2.513."""
    total = history[:, 3]
    assert np.all(np.abs(total / KE0 - 1) < 0.05), (total.min() / KE0, total.max() / KE0)


def test_nothing_non_finite(history):
    assert history[:, 5].all()
