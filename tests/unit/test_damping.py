"""Rayleigh damping by ratio (pmpm.physics.rayleigh): the coefficients, the viscous-stress kernel
against its NumPy twin, free vibrations that decay at the asked ratio, and the energy balance.

The decay tests measure each structure's own first period in an undamped run first (the
damping is asked at the structure's periods, as an engineer would from a modal analysis), then
run it damped at ``damping = {ratio = 0.02, periods = [T1, T2]}`` and read the logarithmic
decrement of the tip's (joint's) displacement over the cycles. Structures: a cantilever of
length 1 (period T1 ~ 64 ms) and one of length 0.5 (T2 ~ 17 ms) with the same damping table:
each is damped at one of the two periods; the portal frame of cases/portal_frame.toml (0.1 m
cells, elastic; its sway period ~ 45 ms) with periods [its own, T2]. The 10% tolerance is the
issue's; the first sway/bending cycle is left out (the initial velocity, close to the first
mode, also rings higher modes, which the stiffness part damps out within it).
"""
import math
import pathlib

import numpy as np
import pytest
from mpi4py import MPI

import pmpm
from pmpm.physics.rayleigh import viscous_stress
from pmpm.core.kernels.reference import viscous_stress_reference
from pmpm.build import build_solver
from pmpm.physics.rayleigh import rayleigh_coefficients, ratio_at
from pmpm.scene.config import parse_scene

PORTAL = str(pathlib.Path(__file__).resolve().parents[1] / "verification" / "portal_frame_handwritten.toml")

RATIO = 0.02
H = 0.025   # cantilever cells: 4 across the depth


def _cantilever(L, damping, end, d=0.1):
    """Cantilever along +x clamped by the fixed nodes at x <= 0, E = 1e6, rho = 1, nu = 0,
    started with the velocity 0.05 (x / L)^2 (close to the first bending mode)."""
    return {"particles_per_cell": 2,
            "grid": {"origin": [-2 * H, -0.2], "cell_size": H, "cells": [int(round((L + 3 * H) / H)), 16]},
            "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.0, "density": 1.0}},
            "bodies": [{"shape": "rectangle", "material": "m", "lower": [0, -d / 2], "upper": [L, d / 2],
                        "velocity": [0.0, f"0.05 * (x / {L})**2"]}],
            "boundary": [{"type": "fixed", "lower": [-2 * H, -0.2], "upper": [0.0, 0.2]}],
            "loads": {"damping": damping} if damping else {},
            "solver": {"end_time": end, "cfl": 0.9},
            "output": {"history_interval": 2e-4, "interval": end, "track": [{"name": "tip", "point": [L, 0.0]}]}}


def _portal(damping, end):
    """The portal frame (elastic variant) at 0.1 m cells, unloaded, started swaying: the columns
    with vx = 0.2 (y / H)^2, the beam with vx = 0.2 m/s."""
    top = 3.85942
    ov = {"grid.cell_size": 0.1, "grid.cells": [71, 42], "loads.forces": [], "output.section": [],
          "solver.end_time": end, "output.interval": end,
          "bodies.0.velocity": [f"0.2 * (y / {top})**2", 0.0], "bodies.1.velocity": [f"0.2 * (y / {top})**2", 0.0],
          "bodies.2.velocity": [0.2, 0.0]}
    if damping:
        ov["loads.damping"] = damping
    # the hand-written scene: its bodies are the columns and the beam, in this order (the frame
    # front end of cases/portal_frame.toml expands to the same bodies: tests/verification)
    return pmpm.run(PORTAL, variant="elastic", overrides=ov, dataframes=False)


def _record(result, track, component):
    h = result.histories[track]
    return np.asarray(h["time"]), np.asarray(h[component])


def _upward_crossings(t, u):
    k = np.flatnonzero((u[:-1] < 0) & (u[1:] >= 0))
    return t[k] - u[k] * (t[k + 1] - t[k]) / (u[k + 1] - u[k])


def _period(t, u):
    """Mean period between upward zero crossings (the motion starts at u = 0 going up, so a
    record of just over one period holds one crossing at T and t = 0 is the other)."""
    c = np.concatenate([[0.0], _upward_crossings(t, u)])
    return float(np.diff(c).mean())


def _decay_ratio(t, u, skip=1):
    """Damping ratio from the logarithmic decrement of the cycle amplitudes (max abs(u) between
    upward crossings), leaving out the first ``skip`` cycles: delta = ln(a_0 / a_n) / n,
    xi = delta / sqrt(4 pi^2 + delta^2). Returns (xi, number of cycles used)."""
    c = np.concatenate([[0.0], _upward_crossings(t, u)])
    amp = np.array([np.abs(u[(t >= a) & (t < b)]).max() for a, b in zip(c[:-1], c[1:])])[skip:]
    n = len(amp) - 1
    delta = math.log(amp[0] / amp[-1]) / n
    return delta / math.sqrt(4 * math.pi ** 2 + delta ** 2), n


def _balance(result):
    """max abs(kinetic + internal work + damping works - external work - E0) / E0 and the two
    damping works over E0 at the end."""
    e = result.energies
    held = (np.asarray(e["kinetic"]) + e["internal_work"] + e["damping_work"] + e["viscous_damping_work"]
            + e["removed_energy"] - e["external_work"])
    e0 = held[0]
    return (float(np.abs(held - e0).max() / e0), float(e["damping_work"][-1] / e0),
            float(e["viscous_damping_work"][-1] / e0))


@pytest.fixture(scope="module")
def periods():
    """Undamped first periods of the two cantilevers (about 1.1 periods each) and their
    undamped energy drift over the same runs."""
    out = {}
    for name, L, end in (("long", 1.0, 0.072), ("short", 0.5, 0.02)):
        r = pmpm.run(_cantilever(L, None, end), dataframes=False)
        out[name] = _period(*_record(r, "tip", "uy"))
        out[name + "_drift"] = _balance(r)[0]
    return out


def test_coefficients_are_the_two_frequency_formula():
    """a0, a1 damp both periods at the ratio, and less in between (xi(omega) is convex)."""
    a0, a1 = rayleigh_coefficients(0.05, (0.5, 0.1))
    w1, w2 = 2 * math.pi / 0.5, 2 * math.pi / 0.1
    assert ratio_at(a0, a1, w1) == pytest.approx(0.05, rel=1e-12)
    assert ratio_at(a0, a1, w2) == pytest.approx(0.05, rel=1e-12)
    assert ratio_at(a0, a1, math.sqrt(w1 * w2)) < 0.05
    assert a0 == pytest.approx(2 * 0.05 * w1 * w2 / (w1 + w2)) and a1 == pytest.approx(2 * 0.05 / (w1 + w2))


@pytest.mark.parametrize("plane_strain", [False, True])
def test_viscous_kernel_matches_its_numpy_twin(plane_strain):
    rng = np.random.default_rng(3)
    n = 257
    sv, de, vol = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 1e-4, rng.uniform(0.5, 2.0, n)
    want, work_want = viscous_stress_reference(sv, de, vol, 1e-5, 2e-4, 2e11, 0.3, plane_strain)
    work = viscous_stress(sv, de, vol, 1e-5, 2e-4, 2e11, 0.3, plane_strain, np.zeros(n, np.int32), -1)
    np.testing.assert_allclose(sv, want, rtol=1e-13)
    assert work == pytest.approx(work_want, rel=1e-12)


def test_off_when_not_asked():
    """No damping table: no RayleighDamping, no viscous-stress field, the plain CFL step; a
    ratio of 0 is the same."""
    for loads in ({}, {"damping": {"ratio": 0.0, "periods": [0.1, 0.05]}}):
        sc = _cantilever(0.5, None, 0.001)
        sc["loads"] = loads
        s = build_solver(parse_scene(sc), MPI.COMM_SELF)
        assert s.effect("rayleigh_damping") is None and s.damping is None and "viscous_stress" not in s.particles
        assert s.dt == pytest.approx(0.9 * H / (1000.0 + s.vmax), rel=1e-12)


@pytest.mark.parametrize("name,L,end_periods", [("long", 1.0, 4.2), ("short", 0.5, 4.2)])
def test_cantilever_decays_at_the_asked_ratio(periods, name, L, end_periods):
    """Each cantilever is damped at one of the two periods: the decrement of cycles 2-4 gives
    the asked 2% within 10%, and the energy balance closes with both damping works in it."""
    damping = {"ratio": RATIO, "periods": [periods["long"], periods["short"]]}
    r = pmpm.run(_cantilever(L, damping, end_periods * periods[name]), dataframes=False)
    xi, cycles = _decay_ratio(*_record(r, "tip", "uy"))
    assert cycles >= 2
    assert xi == pytest.approx(RATIO, rel=0.10)
    gap, mass_part, stiffness_part = _balance(r)
    # the balance closes as well as the undamped run's (its drift is the scheme's own, 1-4%
    # here: the time integration's, it falls with the step), while leaving out either damping
    # work would break it by more than twice that
    tolerance = periods[name + "_drift"] + 0.01
    assert gap < tolerance
    assert min(mass_part, stiffness_part) > 2 * tolerance


def test_portal_decays_at_the_asked_ratio(periods):
    """The portal's sway mode, damped at [its own period, the short cantilever's]: 2% within
    10% over cycles 2-3; the balance closes with the damping works."""
    t, u = _record(_portal(None, 0.05), "upper_left_joint", "ux")
    T1 = _period(t, u)
    r = _portal({"ratio": RATIO, "periods": [T1, periods["short"]]}, 3.6 * T1)
    xi, cycles = _decay_ratio(*_record(r, "upper_left_joint", "ux"))
    assert cycles >= 1
    assert xi == pytest.approx(RATIO, rel=0.10)
    gap, mass_part, stiffness_part = _balance(r)
    assert gap < 0.01 and min(mass_part, stiffness_part) > 0.1


def report():
    """Print the measured periods, ratios and balances (``python tests/unit/test_damping.py``)."""
    T = {}
    for name, L, end in (("long", 1.0, 0.072), ("short", 0.5, 0.02)):
        r = pmpm.run(_cantilever(L, None, end), dataframes=False)
        T[name] = _period(*_record(r, "tip", "uy"))
        print(f"cantilever L = {L}: undamped T = {T[name] * 1e3:.3f} ms, energy drift {_balance(r)[0]:.2e}")
    damping = {"ratio": RATIO, "periods": [T["long"], T["short"]]}
    for name, L in (("long", 1.0), ("short", 0.5)):
        r = pmpm.run(_cantilever(L, damping, 4.2 * T[name]), dataframes=False)
        xi, n = _decay_ratio(*_record(r, "tip", "uy"))
        gap, wm, wk = _balance(r)
        print(f"cantilever L = {L} damped {damping}: xi = {xi:.5f} over {n} cycles ({r.summary['steps']} steps); "
              f"balance gap {gap:.2e}, mass part {wm:.3f} E0, stiffness part {wk:.3f} E0")
    t, u = _record(_portal(None, 0.05), "upper_left_joint", "ux")
    T1 = _period(t, u)
    r = _portal({"ratio": RATIO, "periods": [T1, T["short"]]}, 3.6 * T1)
    xi, n = _decay_ratio(*_record(r, "upper_left_joint", "ux"))
    gap, wm, wk = _balance(r)
    print(f"portal (0.1 m): undamped T1 = {T1 * 1e3:.3f} ms; damped at [{T1:.5f}, {T['short']:.5f}]: xi = {xi:.5f} "
          f"over {n} cycles ({r.summary['steps']} steps); balance gap {gap:.2e}, mass part {wm:.3f} E0, "
          f"stiffness part {wk:.3f} E0")


if __name__ == "__main__":
    report()
