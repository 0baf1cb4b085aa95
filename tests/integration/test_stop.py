"""Stop conditions ([[stop]], pmpm.stop) against a closed form: a free body under gravity.

An elastic block with no support falls freely: with zero stress every node accelerates at g, so
every particle's displacement is uy(t_n) = -g t_n (t_n + dt) / 2 at a fixed step dt (the explicit
update v += g dt, then x += v dt, sums to g dt^2 n (n + 1) / 2), which lies within g t dt / 2 of
the continuum -g t^2 / 2. A stop at uy below -d must then end the run at the first step past it,
within one step of t* = sqrt(2 d / g): u_{n-1} <= d < u_n with u_n between g t_n^2 / 2 and
g (t_n + dt)^2 / 2 gives t* - dt < t_n < t* + dt.
"""
import math
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

import pmpm

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
G, DROP, DT = 9.81, 0.5, 0.01

SCENE = f"""\
title = "free fall to a stop"
[grid]
cell_size = 0.125
cells = [8, 32]

[materials.soft]
type = "linear_elastic"
E = 1.0e4
nu = 0.3
density = 1000.0

[[bodies]]
name = "block"
shape = "rectangle"
material = "soft"
lower = [0.25, 3.0]
upper = [0.75, 3.5]

[loads]
gravity = [0.0, -{G}]

[solver]
end_time = 1.0
time_step = {DT}

[output]
interval = 0.1
history_interval = {DT / 2}
fields = ["x", "v"]

[[output.track]]
name = "corner"
point = [0.25, 3.0]

[[stop]]
track = "corner"
quantity = "uy"
below = -{DROP}
"""


def _uy_closed_form(t):
    return -G * t * (t + DT) / 2


def test_free_fall_stops_at_the_first_step_past_the_drop(tmp_path):
    res = pmpm.run(str(_write(tmp_path)), dataframes=False)
    stop = res.stopped
    t_star = math.sqrt(2 * DROP / G)
    assert stop is not None and stop["track"] == "corner" and stop["side"] == "below"
    assert res.summary["end_reason"] == "stop"
    assert abs(stop["time"] - t_star) < DT, (stop, t_star)
    h = res.histories["corner"]
    # the last history row is the stop's step, the one before still short of the drop
    assert h["time"][-1] == pytest.approx(stop["time"], abs=1e-12)
    assert h["uy"][-1] < -DROP <= h["uy"][-2]
    assert stop["value"] == h["uy"][-1] and stop["threshold"] == -DROP
    # the free fall itself: rounding only (1e-9 of the drop)
    assert np.allclose(h["uy"], _uy_closed_form(h["time"]), atol=1e-9 * DROP)
    # steps: fixed dt, so the stop step is the first n with g dt^2 n (n + 1) / 2 > d
    n = next(k for k in range(1, 1000) if G * DT * DT * k * (k + 1) / 2 > DROP)
    assert stop["step"] == n and res.summary["steps"] == n
    # the final frame is the stop's
    assert res.frame_times[-1] == pytest.approx(stop["time"], abs=1e-12)


def test_above_stops_at_the_same_first_step_past_the_drop(tmp_path):
    """|u| above d: the fall is vertical (ux = 0 exactly), so |u| = -uy and the run stops at the
    same first step n with g dt^2 n (n + 1) / 2 > d as the ``below`` test."""
    res = pmpm.run(str(_write(tmp_path)), overrides={"stop": [{"track": "corner", "quantity": "|u|",
                                                               "above": DROP}]},
                   dataframes=False)
    n = next(k for k in range(1, 1000) if G * DT * DT * k * (k + 1) / 2 > DROP)
    assert res.stopped["side"] == "above" and res.stopped["step"] == n
    assert res.stopped["value"] > DROP


def test_a_threshold_never_reached_runs_to_the_end(tmp_path):
    path = _write(tmp_path)
    res = pmpm.run(str(path), overrides={"stop.0.below": -100.0, "solver.end_time": 0.3},
                   dataframes=False)
    assert res.stopped is None and res.summary["end_reason"] == "end_time"
    assert res.summary["time"] == pytest.approx(0.3)


def test_after_delays_the_check(tmp_path):
    """|v| above 1 m/s holds from t = 0.11 s on (|v| = g t); with after = 0.3 s the first step
    at or after 0.3 s stops the run."""
    res = pmpm.run(str(_write(tmp_path)), overrides={"stop": [{"track": "corner", "quantity": "|v|",
                                                               "above": 1.0, "after": 0.3}]},
                   dataframes=False)
    assert res.stopped["quantity"] == "|v|"
    assert 0.3 - 1e-9 <= res.stopped["time"] < 0.3 + DT


def test_command_line_run_stops_cleanly_and_records_why(tmp_path):
    """Exit 0, the one log line, the reason in the results file's attributes and in
    pmpm.load_results, and the XDMF sidecar with the final frame."""
    path = _write(tmp_path)
    env = dict(os.environ, PYTHONPATH=ROOT)
    res = subprocess.run([sys.executable, "-m", "pmpm.cli", path.name, "--no-plots"], cwd=tmp_path,
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    lines = [ln for ln in (res.stdout + res.stderr).splitlines() if "stopped: " in ln]
    assert len(lines) == 1 and "stopped: corner uy = -0." in lines[0] and "< -0.5 at t = " in lines[0], lines
    h5 = tmp_path / "case_results" / "case.h5"
    with h5py.File(h5, "r") as f:
        assert f.attrs["end_reason"] == "stop"
        t_stop = float(f.attrs["stop_time"])
        assert abs(t_stop - math.sqrt(2 * DROP / G)) < DT
        assert f["frames/time"][-1] == t_stop and f["history/time"][-1] == t_stop
    loaded = pmpm.load_results(h5, dataframes=False)
    assert loaded.stopped["time"] == t_stop and loaded.stopped["reason"] in lines[0]
    import meshio
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "case_results" / "case.xdmf")) as reader:
        reader.read_points_cells()
        assert reader.num_steps == 5  # t = 0, 0.1, 0.2, 0.3 and the stop (0.31 s)
        assert reader.read_data(reader.num_steps - 1)[0] == pytest.approx(t_stop)


def _write(tmp_path):
    path = tmp_path / "case.toml"
    path.write_text(SCENE)
    return path


def test_progress_ends_at_the_stop(tmp_path):
    """A progress callback's last report of a stopped run has t = end (a bar closes)."""
    calls = []
    res = pmpm.run(str(_write(tmp_path)), progress=lambda t, end: calls.append((t, end)), dataframes=False)
    assert calls[-1] == (res.stopped["time"], res.stopped["time"])


def test_the_stop_sample_follows_its_particle_when_rows_move(tmp_path):
    """The tracker the stop reads keeps its particle's row between steps; after the rows are
    permuted (as a sort or a migration moves them) it must still read that particle: the
    values of the row found by searching the id afresh."""
    from mpi4py import MPI

    from pmpm.build import build_solver
    from pmpm.scene.config import load_scene
    from pmpm.stop import make_stop_check
    scene = load_scene(str(_write(tmp_path)))[0]
    s = build_solver(scene, MPI.COMM_SELF)
    check = make_stop_check(scene, s)

    def searched():
        p = s.particles
        r = int(np.flatnonzero(p["id"] == check.tracker.ids[0])[0])
        x, x0, v, st = p["x"][r], p["x0"][r], p["v"][r], p["stress"][r]
        return np.array([[x[0] - x0[0], x[1] - x0[1], v[0], v[1], x[0], x[1], st[0], st[1], st[2]]])

    rng = np.random.default_rng(1)
    for _ in range(3):
        s.step()
        assert np.array_equal(check.tracker.sample(), searched())
        order = rng.permutation(s.particles.n)
        s.particles.fields = {k: a[order] for k, a in s.particles.fields.items()}
        assert np.array_equal(check.tracker.sample(), searched())
