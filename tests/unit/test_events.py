"""Scene events (pmpm.physics.events): a body removed during the run (issue 23, item 3).

The scene is cases/hard/column_loss.toml shortened and coarsened (0.1 m cells, the floor load
ramped over 10 ms, the middle column removed at 12 ms over 5 ms, 22 ms in all): the checks are
of the bookkeeping, not of the structure's answer (that is the study's,
studies/column_loss.py).
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.build import build_solver
from pmpm.scene.config import load_scene

CASE = "cases/hard/column_loss.toml"
SHORT = {"grid.cell_size": 0.1, "grid.cells": [132, 42], "loads.forces.0.time_function.duration": 0.01,
         "events.0.time": 0.012, "events.0.duration": 0.005, "solver.end_time": 0.022,
         "output.section": []}


def short_scene(**extra):
    return load_scene(CASE, overrides={**SHORT, **extra})[0]


def _run(scene):
    s = build_solver(scene, MPI.COMM_SELF)
    rows = []
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
        e = s.energies()
        rows.append((s.t, e["total"] - s.initial_energy - e["external_work"], e["removed_energy"],
                     e["external_work"], s.particles.n))
    return s, np.array(rows)


@pytest.fixture(scope="module")
def removal():
    return _run(short_scene())


def test_the_body_leaves_at_the_end_of_its_fade(removal):
    s, rows = removal
    body = [b.name for b in short_scene().bodies].index("middle column")
    assert not np.any(s.particles["body"] == body)
    t, n = rows[:, 0], rows[:, 4]
    ev = s.effect("events")[0]
    # every other particle is still there, and the body's particles left at the first step ending
    # at or after time + duration (not before)
    assert np.all(n[t < ev.time + ev.duration - 1e-12] == n[0])
    gone = n[0] - n[-1]
    assert gone > 0 and np.all(n[t >= ev.time + ev.duration] == n[-1])
    assert s.n_total - s.particles.n == gone


def test_energy_balance_closes_with_the_removed_energy(removal):
    """kinetic + internal work + damping + removed energy = initial + external work across the
    fade and the removal: the gap changes over the event's window by less than the scheme's
    own gap before it (the time integration's O(dt) mismatch between the force's stress and
    the internal work's trapezoid), while the removed energy is many times that (without it
    the balance would be off by all of it); over the whole run the gap stays below 0.1% of
    the external work (the run's own drift: the collapse after the removal moves the beam
    fast)."""
    s, rows = removal
    t, gap, removed, external = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    ev = s.effect("events")[0]
    before = t < ev.time
    window = (t >= ev.time - 1e-12) & (t <= ev.time + ev.duration + 2 * s.dt)
    own = np.abs(gap[before]).max()
    change = np.ptp(gap[window])
    assert change < own
    assert abs(removed[-1]) > 10 * own
    assert np.abs(gap).max() < 1e-3 * np.abs(external).max()
    assert np.all(removed[before] == 0.0)
    assert np.all(removed[t >= ev.time + ev.duration] == removed[-1])


def test_force_stress_is_the_stress_itself_until_the_event_acts():
    """An event costs nothing until its time: the force stress is the particles' stress array
    (no copy); while it fades, the body's rows are scaled by 1 - (t - time) / duration."""
    s = build_solver(short_scene(), MPI.COMM_SELF)
    assert s.force_stress() is s.particles["stress"]
    ev = s.effect("events")[0]
    s.t = ev.time + 0.4 * ev.duration
    f = s.force_stress()
    rows = s.particles["body"] == ev.body
    np.testing.assert_allclose(f[rows], 0.6 * s.particles["stress"][rows][:, :3], rtol=1e-14)
    np.testing.assert_array_equal(f[~rows], s.particles["stress"][~rows][:, :3])
    none = build_solver(short_scene(events=[]), MPI.COMM_SELF)
    assert none.effect("events") is None and none.force_stress() is none.particles["stress"]


def test_heavy_floor_turns_the_beam_to_catenary_tension():
    """The study's heavy-floor variant (floor load x3, 90 kN/m), shortened like SHORT but run 50 ms
    past the removal: once the point above the removed column has dropped by over two beam depths
    the beam's cuts beside it carry tension (catenary action; in the case's 30 kN/m run the beam stays
    in compression), and that tension stays below the cable estimate w L^2 / (8 delta) of the double
    span, a cable carrying the whole load (the beam still carries part in bending)."""
    from studies import column_loss as cl
    import pmpm
    factor = 3.0
    ov = {**SHORT, **cl.catenary_overrides(factor), "solver.end_time": 0.062}
    ov.pop("output.section")
    r = pmpm.run(CASE, overrides=ov, dataframes=False, comm=MPI.COMM_SELF)
    h = r.histories[cl.TRACK]
    t, uy = np.asarray(h["time"]), np.asarray(h["uy"])
    w = cl.FLOOR_FORCE * factor / cl.CLEAR_SPAN + cl.BEAM_WEIGHT
    deep = np.abs(uy) > 2 * 0.40284
    assert deep.any(), f"the drop reaches only {uy.min():.3f} m"
    cable = w * cl.CLEAR_SPAN ** 2 / (8 * np.abs(uy[deep]))
    for name in ("beam_mid_left", "beam_mid_right"):
        N = np.asarray(r.sections[name]["N"])
        assert N[(t > 0) & (t < 0.012)].max() < 0, f"{name}: the preloaded beam is not in compression"
        assert N[deep][-1] > 0, f"{name}: no tension at a drop of {uy[deep][-1]:.2f} m"
        assert np.all(N[deep] < cable), f"{name}: tension above the cable estimate"
