"""Effects switched on by the scene: ground motion and mass-proportional damping."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.scene.config import parse_scene
from pmpm.errors import ConfigError
from pmpm.physics.groundmotion import G, read_record
from pmpm.build import build_solver

E, RHO = 1e5, 100.0


def _record(tmp_path, amplitude=2.0, freq=3.0, duration=1.0, n=401):
    t = np.linspace(0.0, duration, n)
    a = amplitude * np.sin(2 * math.pi * freq * t)
    path = tmp_path / "record.txt"
    np.savetxt(path, np.column_stack([t, a]), header="time acceleration")
    return path, t, a


def _block(tmp_path, record, box_all=True, end=0.5, direction="x"):
    lower, upper = ([0.0, 0.0], [2.0, 2.0]) if box_all else ([0.0, 0.0], [2.0, 0.0])
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.1, "cells": [20, 20]},
        "materials": {"m": {"type": "linear_elastic", "E": E, "nu": 0.3, "density": RHO}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.5, 0.0], "upper": [1.5, 0.6]}],
        "boundary": [{"name": "ground", "type": "fixed", "lower": lower, "upper": upper}],
        "loads": {"ground_motion": {"file": str(record), "direction": direction}},
        "solver": {"end_time": end, "cfl": 0.5},
        "output": {"fields": ["x", "v", "stress", "strain"]},  # keep the accumulated strain
    }, str(tmp_path / "block.toml"))


def _ground_displacement(t_rec, a_rec, t):
    """Double integral of the linearly interpolated record (fine trapezoid, independent of pmpm)."""
    tt = np.linspace(0.0, t, 20001)
    a = np.interp(tt, t_rec, a_rec)
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(tt))])
    return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(tt)))


def test_a_body_carried_rigidly_by_the_ground_shows_no_strain(tmp_path):
    """Every node moves with the ground: the velocity field is uniform, so its gradient (the
    strain rate) vanishes exactly by the partition of unity, and the body follows the ground."""
    path, t_rec, a_rec = _record(tmp_path)
    s = build_solver(_block(tmp_path, path), MPI.COMM_SELF)
    while s.t < 0.5 - 1e-12:
        s.step()
    p = s.particles
    assert np.abs(p["strain"]).max() < 1e-12
    assert np.abs(p["stress"]).max() < 1e-12 * E
    u = p["x"][:, 0] - p["x0"][:, 0]
    expected = _ground_displacement(t_rec, a_rec, s.t)
    # positions advance with the end-of-step velocity (x += dt v(t + dt)): the accumulated
    # error is at most half a step's travel at the peak ground velocity, dt max|v| / 2
    v_peak = 2.0 / (2 * math.pi * 3.0) * 2
    assert np.all(np.abs(u - expected) <= s.dt * v_peak)
    assert np.ptp(u) < 1e-12  # and all particles move together
    assert np.allclose(p["x"][:, 1], p["x0"][:, 1])


def test_base_motion_shakes_a_free_standing_block(tmp_path):
    """Driven only at its base, the block deforms (inertia) and its base follows the ground."""
    path, t_rec, a_rec = _record(tmp_path)
    s = build_solver(_block(tmp_path, path, box_all=False, end=0.3), MPI.COMM_SELF)
    while s.t < 0.3 - 1e-12:
        s.step()
    p = s.particles
    base = p["x0"][:, 1] < 0.05
    expected = _ground_displacement(t_rec, a_rec, s.t)
    assert np.allclose(p["x"][base, 0] - p["x0"][base, 0], expected, rtol=0.05)  # as above + layer
    assert np.abs(p["strain"][:, 2]).max() > 1e-6  # shear from the base motion


def test_work_of_the_moving_base_converges_with_the_time_step(tmp_path):
    """The ground's work (reaction impulses times the ground velocity) is a first-order
    estimate in dt of the energy the base puts in: the gap to kinetic + internal energy must
    shrink about in proportion to the time step."""
    import dataclasses
    path, _, _ = _record(tmp_path)
    gaps = []
    for cfl in (0.5, 0.125):
        scene = _block(tmp_path, path, box_all=False, end=0.3)
        s = build_solver(dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, cfl=cfl)), MPI.COMM_SELF)
        while s.t < 0.3 - 1e-12:
            s.step()
        e = s.energies()
        gaps.append(abs(e["total"] - s.initial_energy - e["external_work"]) / e["total"])
    assert gaps[1] < 0.5 * gaps[0], gaps


def test_at2_records_are_read_in_g(tmp_path):
    values = np.array([0.0, 0.1, -0.2, 0.05, 0.0, 0.3, 0.1])
    text = ("PEER NGA STRONG MOTION DATABASE RECORD\nTEST RECORD\nACCELERATION TIME SERIES IN UNITS OF G\n"
            f"NPTS=    {len(values)}, DT=   .0100 SEC\n")
    text += "\n".join("  ".join(f"{v: .7E}" for v in values[k:k + 5]) for k in range(0, len(values), 5))
    path = tmp_path / "quake.AT2"
    path.write_text(text)
    t, a = read_record(str(path))
    np.testing.assert_allclose(t, np.arange(len(values)) * 0.01)
    np.testing.assert_allclose(a, values * G)


@pytest.mark.parametrize("content,reason", [("1 2 3\n4 5 6\n", "two columns"),
                                            ("0 1\n0 2\n", "increase")])
def test_bad_records_name_the_file(tmp_path, content, reason):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    with pytest.raises(ConfigError) as err:
        read_record(str(path))
    assert err.value.key == str(path) and reason in err.value.reason


def _bar(damping, end):
    L, h = 25.0, 0.5
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"cell_size": h, "cells": [54, 3]},
        "materials": {"b": {"type": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0}},
        "bodies": [{"shape": "rectangle", "material": "b", "lower": [0, 0], "upper": [L, h],
                    "velocity": ["0.001 * sin(pi * x / 50)", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0, 0], "upper": [0, 1.5]}],
        "loads": {"damping": damping},
        "solver": {"end_time": end},
    }, "bar.toml")


def test_mass_proportional_damping_decays_energy_as_exp_minus_alpha_t():
    """Force -alpha m v on a single mode: the energy envelope is exp(-alpha t) (the modal
    damping ratio is alpha / (2 omega)); over two periods the mean energy follows it within a
    few percent, and kinetic + internal work + damping work stays equal to the initial energy."""
    alpha, T = 0.05, 20.0
    s = build_solver(_bar(alpha, T), MPI.COMM_SELF)
    e0 = s.energies()["total"]
    while s.t < T - 1e-12:
        s.step()
    e = s.energies()
    assert e["kinetic"] + e["strain"] == pytest.approx(e0 * math.exp(-alpha * s.t), rel=0.03)
    assert e["total"] == pytest.approx(e0, rel=0.01)
    assert e["damping_work"] > 0.5 * e0 * (1 - math.exp(-alpha * T))


def test_damping_off_is_compiled_out_and_loses_nothing_else():
    """damping = 0 compiles the damping term out (``Solver.damping`` is None); the specialisation
    without it must still be the same step: it equals, to the bit, the damped kernel at a
    vanishing coefficient (alpha = 1e-300, whose term alpha m v is below the rounding of every
    nodal force and velocity here), and it conserves energy (kinetic + internal work stays the
    initial energy to the 1% of the damped test above; no damping work)."""
    off, tiny = build_solver(_bar(0.0, 2.0), MPI.COMM_SELF), build_solver(_bar(1e-300, 2.0), MPI.COMM_SELF)
    assert off.damping is None and tiny.damping == 1e-300  # compiled out, not multiplied by zero
    e0 = off.energies()["total"]
    for _ in range(30):
        off.step()
        tiny.step()
    for field in ("x", "v", "stress"):
        np.testing.assert_array_equal(off.particles[field], tiny.particles[field])
    e = off.energies()
    assert e["damping_work"] == 0.0 and 0.0 <= tiny.energies()["damping_work"] < 1e-290
    assert e["total"] == pytest.approx(e0, rel=0.01)
    assert np.abs(off.particles["v"] - off.particles["v"][0]).max() > 0  # the bar is moving
