"""Transfers and waiting where the suite was blind (issue 38): XPIC's smoothing passes keep a
moving boundary's prescribed velocity, APIC under USF through a real run (the run's own energy
check runs), and the timer slack that keeps the naps of a wait between ranks short.

How each test was shown to fail on its bug (planted, watched fail, restored):
* ``mutate.py --only xpic_smoothing_drops_the_boundary``: the smoothing pass returns M u without
  the boundary values: ``test_xpic_keeps_a_moving_boundarys_velocity`` fails;
* ``mutate.py --only apic_usf_skips_the_force_pass``: ``test_apic_under_usf_runs_the_bar`` fails
  (no internal force reaches the grid: the bar never swings back);
* ``mutate.py --only waiting_timer_slack_unset`` and ``--only waiting_timer_slack_value``:
  ``test_the_first_nap_sets_a_fine_timer_slack`` fails.
"""
import ctypes
import math
import os
import types

import numpy as np
import pytest

import pmpm
from decomposition import waiting

BAR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "cases", "bar.toml")
H = 0.05
V_BC = np.array([0.3, -0.2])      # m/s, the moving boundary's velocity
BOX_X = (0.2, 0.7)                # the prescribed nodes: x in BOX_X (10 cells), every y


def xpic_moving_boundary(end=0.02):
    """A block on a grid off the origin, its left part carried by a moving (prescribed-velocity)
    box of nodes over its whole height, the rest free: an elastic wave runs into the free part,
    so the nodal velocities near the box edge differ from the box's."""
    return {"particles_per_cell": 2,
            "grid": {"origin": [0.0, 0.1], "cell_size": H, "cells": [30, 14]},
            "materials": {"m": {"type": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 100.0}},
            "bodies": [{"name": "block", "shape": "rectangle", "material": "m", "lower": [0.3, 0.3],
                        "upper": [1.2, 0.6]}],
            "boundary": [{"name": "carrier", "type": "velocity", "velocity": list(V_BC),
                          "lower": [BOX_X[0], 0.1], "upper": [BOX_X[1], 0.8]}],
            "solver": {"end_time": end, "cfl": 0.5, "transfer": "xpic", "xpic_order": 3},
            "output": {"interval": end / 4, "history_interval": end / 4, "fields": ["x", "x0", "v"]}}


def test_xpic_keeps_a_moving_boundarys_velocity():
    """A particle whose whole cubic B-spline stencil (every node within 2h of it) lies among the
    prescribed nodes moves with the boundary's velocity exactly: v^L = v^n = V on its nodes, and
    every smoothing pass M^k v^n keeps the boundary values, so v* = V (the coefficients sum to 1)
    and v_p = sum S (v^L - v^n + v*) = V. Checked at every frame on the particles at least 2h
    inside the box along x (the box spans the grid's height); their displacement is V t. Without
    the boundary values in a smoothing pass, M v^n at box nodes within 4h of the free nodes
    carries the free part's velocities into those particles. Tolerance: round-off."""
    res = pmpm.run(xpic_moving_boundary(), dataframes=False)
    checked = 0
    for k, t in enumerate(res.frame_times):
        x, v, x0 = res.frames["x"][k], res.frames["v"][k], res.frames["x0"][k]
        inside = (x[:, 0] >= BOX_X[0] + 2 * H) & (x[:, 0] <= BOX_X[1] - 2 * H)
        near_edge = inside & (x[:, 0] >= BOX_X[1] - 6 * H)   # within reach of the free nodes' smoothing
        if t == 0:
            continue
        assert near_edge.sum() > 10
        np.testing.assert_allclose(v[inside], np.broadcast_to(V_BC, v[inside].shape), rtol=0, atol=1e-12)
        np.testing.assert_allclose(x[inside] - x0[inside], np.broadcast_to(V_BC * t, v[inside].shape),
                                   rtol=0, atol=1e-12)
        # the free part really moves otherwise (so the smoothing has something to carry in)
        free = x0[:, 0] > BOX_X[1] + 2 * H
        assert np.abs(v[free] - V_BC).max() > 0.05
        checked += 1
    assert checked >= 3


def test_apic_under_usf_runs_the_bar():
    """The fixed-free bar (cases/bar.toml) with APIC under USF through pmpm.run, so the run's
    health and energy checks run every step, at CFL 0.5 and 0.25: over a quarter period (2.5 s)
    the free end's displacement converges on the closed form u = (v0 / omega) sin(omega t) over
    the whole history at first order in the step (USF's stress from the start-of-step velocity:
    halving the step halves the error; 0.6 leaves room for the part of the error that is the
    grid's and does not fall with the step), and kinetic + strain energy stays the initial
    energy within the issue's 2% in both runs."""
    omega = math.pi / 50.0 * 10.0
    amp = 0.1 / omega
    errors = {}
    for cfl in (0.5, 0.25):
        res = pmpm.run(BAR, overrides={"solver.end_time": 2.5, "solver.transfer": "apic", "solver.scheme": "usf",
                                       "solver.cfl": cfl}, dataframes=False)
        tip = res.histories["free_end"]
        t, ux = np.asarray(tip["time"]), np.asarray(tip["ux"])
        assert t[-1] == pytest.approx(2.5)
        errors[cfl] = np.abs(ux - amp * np.sin(omega * t)).max() / amp
        e = res.energies
        held = np.asarray(e["kinetic"]) + np.asarray(e["strain_energy"])
        assert np.abs(held - held[0]).max() < 0.02 * held[0]
    assert errors[0.25] < 0.6 * errors[0.5], errors


PR_GET_TIMERSLACK = 30


def test_the_first_nap_sets_a_fine_timer_slack(monkeypatch):
    """A wait that outlasts the spin phase sets this thread's timer slack to 1 us before its
    first nap (Linux's default, 50 us, would stretch every 10 us nap to ~65 us: docs/
    performance.md, "The spin phase"); read back from the kernel with prctl(PR_GET_TIMERSLACK).
    The thread's slack is put back afterwards."""
    libc = ctypes.CDLL(None)
    before = libc.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
    if before < 0:
        pytest.skip("prctl(PR_GET_TIMERSLACK) is not available (not Linux)")
    libc.prctl(29, 50_000, 0, 0, 0)   # the default, whatever an earlier wait set
    calls = {"n": 0}

    def testall(requests):
        calls["n"] += 1
        return calls["n"] > 3

    monkeypatch.setattr(waiting, "MPI", types.SimpleNamespace(Request=types.SimpleNamespace(Testall=testall)))
    monkeypatch.setattr(waiting, "_slack_set", False)
    monkeypatch.setattr(waiting, "SPIN_SECONDS", 0.0)
    slept = []
    monkeypatch.setattr(waiting.time, "sleep", slept.append)
    try:
        waiting.wait_all(["request"])
        assert slept, "the wait never napped"
        assert libc.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0) == 1000   # ns
    finally:
        libc.prctl(29, before, 0, 0, 0)
