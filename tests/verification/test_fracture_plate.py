"""Separation: the double-V-notched plate of cases/fracture_notched_plate.toml fractures
through its ligament and its two parts move apart (docs/fracture.md, "Separation").

What is asserted, and why it holds without reference numbers:
- the crack runs between the notch roots: every particle row of the ligament (the 24 mm between
  the notch tips) has a failed point, and all failed points lie within one cell of the
  plate's middle (the section the notches weaken, where the triaxiality is highest);
- the parts separate: once the ligament has failed, the left part (held) stops and the right
  part moves with the pulled face at 2 m/s: over the last 0.4 ms the gap between two tracked
  points either side of the crack grows at the pull's speed (to 5%: the ringing of the freed
  parts, whose elastic wave period 2 L / c = 40 us is far shorter than the window);
- the released points transmit no tension (their tensile stress is zero to round-off).

The single velocity field: particles either side of the crack share grid nodes until the gap
passes the B-spline support (two cells each side); the failed band's particles are the bridge
that is stretched across the gap. The test prints how far the failed band has stretched.
Planted bug: release() with w fixed at 0 (failed points keep their tension) -> the plate
does not separate (the gap grows at the elastic-plastic rate, far below 2 m/s) and fails.
"""
import numpy as np
import pytest

from pmpm.api import run

PULL = 2.0
NOTCH_TIPS = (0.008, 0.032)


@pytest.fixture(scope="module")
def plate():
    return run("cases/fracture_notched_plate.toml", dataframes=False,
               overrides={"solver.end_time": 1.6e-3, "output.interval": 4e-4,
                          "output.fields": ["x", "v", "stress", "damage"]})


def test_the_crack_runs_through_the_ligament(plate):
    x0 = plate.frames["x"][0]
    failed = plate.frames["damage"][-1] >= 1.0
    assert np.all(np.abs(x0[failed, 0] - 0.05) <= 0.002)
    rows = np.unique(np.round(x0[:, 1], 6))
    ligament = rows[(rows > NOTCH_TIPS[0]) & (rows < NOTCH_TIPS[1])]
    broken = np.unique(np.round(x0[failed, 1], 6))
    assert set(ligament) <= set(broken)
    assert "plate" in plate.summary["first_fracture"]
    stress = plate.frames["stress"][-1][failed]
    # released: the tensile part gone (compression of a closing face is allowed)
    principal = 0.5 * (stress[:, 0] + stress[:, 1]) + np.hypot(0.5 * (stress[:, 0] - stress[:, 1]), stress[:, 2])
    assert np.all(principal <= 1e-6 * 355e6)
    x = plate.frames["x"][-1]
    print(f"failed band: {failed.sum()} points, initial width {np.ptp(x0[failed, 0]) * 1e3:.2f} mm, "
          f"now {np.ptp(x[failed, 0]) * 1e3:.2f} mm")


def test_the_parts_move_apart(plate):
    hl, hr = plate.histories["left_of_notch"], plate.histories["right_of_notch"]
    t = hl["time"]
    late = t >= t[-1] - 4e-4
    gap = hr["ux"][late] - hl["ux"][late]
    rate = np.polyfit(t[late], gap, 1)[0]
    assert rate == pytest.approx(PULL, rel=0.05)
    # the held part has stopped: its point moves at most a twentieth of the pull's speed
    assert abs(np.polyfit(t[late], hl["ux"][late], 1)[0]) < 0.05 * PULL
    e = plate.energies
    print({k: round(float(e[k][-1]), 4) for k in ("fracture_work", "plastic_work", "internal_work",
                                                   "external_work", "numerical_loss")})


def energy_balances():
    """The plate's energies with fracture and with a locus it never reaches (eta = 1e9: the
    same plasticity, no point fails), printed by ``python tests/verification/test_fracture_plate.py``
    (docs/fracture.md quotes them)."""
    keys = ("fracture_work", "plastic_work", "strain_energy", "internal_work", "external_work", "numerical_loss")
    for label, over in (("fracturing plate", {}), ("plate that does not fail", {"materials.steel.fracture.eta": 1e9})):
        r = run("cases/fracture_notched_plate.toml", dataframes=False,
                overrides={"solver.end_time": 1.6e-3, "output.fields": ["x"], **over})
        e = {k: float(r.energies[k][-1]) for k in keys}
        print(f"{label}: " + ", ".join(f"{k} {v:.4g} J" for k, v in e.items())
              + f"; loss / external work {100 * e['numerical_loss'] / e['external_work']:.2f}%")


if __name__ == "__main__":
    energy_balances()
