"""Bounds on every number that sizes a run's work, at parse time (pmpm.scene.limits.
check_work_bounds, issue 35 deliverable 5): one ConfigError naming the key, before anything runs.

Each case was accepted before (shown by running these tests on the parent commit: the scenes
parsed, the nested overrides raised RecursionError, the crafted checkpoint validated), and then
ran forever (xpic_order 100000, a Scene with end_time nan), died with a traceback (intervals of
5e-324) or failed after the run started (thickness, pushover displacement).
"""
import dataclasses
import math
import os
import tomllib

import h5py
import numpy as np
import pytest

from pmpm.errors import ConfigError
from pmpm.scene import limits
from pmpm.scene.config import apply_overrides, load_scene, parse_scene

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

BASE = """
[grid]
cell_size = 0.5
cells = [8, 4]
[materials.steel]
type = "linear_elastic"
E = 100.0
nu = 0.3
density = 1.0
[[bodies]]
name = "b"
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]
[solver]
end_time = 0.01
"""


def _refused(text, key):
    with pytest.raises(ConfigError) as exc:
        parse_scene(tomllib.loads(text))
    assert exc.value.key == key, str(exc.value)
    assert "\n" not in str(exc.value)
    return str(exc.value)


@pytest.mark.parametrize("edit,key", [
    (lambda t: t.replace("end_time = 0.01", "end_time = 5e-324"), "solver.end_time"),
    (lambda t: t + "[output]\ninterval = 5e-324\n", "output.interval"),
    (lambda t: t + "[output]\nhistory_interval = 5e-324\n", "output.history_interval"),
    (lambda t: t + "[output]\ncheckpoint_interval = 5e-324\n", "output.checkpoint_interval"),
    # just past each cap (the caps' reasons are in pmpm/scene/limits.py)
    (lambda t: t + f"[output]\ninterval = {0.01 / (limits.MAX_FRAMES * 1.01)!r}\n", "output.interval"),
    (lambda t: t.replace("end_time = 0.01", f"end_time = 0.01\ntransfer = \"xpic\"\nxpic_order = 100000"),
     "solver.xpic_order"),
    (lambda t: t.replace("end_time = 0.01", f"end_time = 0.01\ntransfer = \"xpic\"\n"
                                            f"xpic_order = {limits.MAX_XPIC_ORDER + 1}"), "solver.xpic_order"),
    (lambda t: t.replace('name = "b"', 'name = "b"\nthickness = 1e308'), "bodies[0].thickness"),
    (lambda t: t.replace('name = "b"', 'name = "b"\nthickness = 5e-324'), "bodies[0].thickness"),
    (lambda t: "thickness = 1e308\n" + t, "thickness"),
])
def test_numbers_that_size_work_are_bounded(edit, key):
    _refused(edit(BASE), key)


def test_the_caps_themselves_are_accepted():
    parse_scene(tomllib.loads(BASE + f"[output]\ninterval = {0.01 / limits.MAX_FRAMES!r}\n"))
    parse_scene(tomllib.loads(BASE.replace("end_time = 0.01", f"end_time = 0.01\ntransfer = \"xpic\"\n"
                                                              f"xpic_order = {limits.MAX_XPIC_ORDER}")))


@pytest.mark.parametrize("value", [math.nan, math.inf, -1.0, 5e-324])
def test_a_scene_built_in_python_is_bounded_too(value):
    from pmpm.api import _scenes
    scene = parse_scene(tomllib.loads(BASE))
    bad = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, end_time=value))
    with pytest.raises(ConfigError, match="solver.end_time"):
        _scenes(bad, None, None)


def test_overrides_nested_5000_deep_are_one_line():
    deep = {}
    node = deep
    for _ in range(5000):
        node["a"] = {}
        node = node["a"]
    with pytest.raises(ConfigError, match="nested more than"):
        apply_overrides(tomllib.loads(BASE), {"solver": deep}, "overrides")


def test_pushover_displacement_beyond_the_grid():
    with pytest.raises(ConfigError, match=r"pushover.displacement"):
        load_scene(os.path.join(ROOT, "cases", "portal_pushover.toml"),
                   overrides={"pushover.displacement": 1e300})


def test_checkpoint_step_of_1e30_is_refused(tmp_path):
    from mpi4py import MPI
    from pmpm.io import checkpoint
    from pmpm.io.validate import check_checkpoint_schema
    fields = {"id": np.arange(3, dtype=np.int64), "x": np.zeros((3, 2))}
    path = checkpoint.write_checkpoint(str(tmp_path / "c"), MPI.COMM_SELF, 0.1, 7, fields, {})
    with h5py.File(path, "r") as f:
        check_checkpoint_schema(f, checkpoint.LAYOUT)  # as written: fine
    with h5py.File(path, "r+") as f:
        f.attrs["step"] = 1e30
    with h5py.File(path, "r") as f, pytest.raises(ValueError, match="'step' is above"):
        check_checkpoint_schema(f, checkpoint.LAYOUT)


def test_a_record_scaled_past_1000_g_is_refused_before_the_run(tmp_path):
    """A record scaled past 1e300 g overflowed to inf and the run failed with exit 3 after it
    had started; now the ground motion refuses it when it is set up (before any step or file)."""
    from pmpm.physics.groundmotion import G, MAX_GROUND_ACCELERATION, GroundMotion
    rec = tmp_path / "rec.txt"
    rec.write_text("0.0 0.0\n0.01 1.0\n0.02 -1.0\n")  # m/s^2, two columns
    ok = {"file": str(rec), "format": "two_column", "scale": MAX_GROUND_ACCELERATION * 0.99, "boundaries": [],
          "direction": "x"}
    with pytest.raises(ConfigError) as exc:  # past the scale check, stopped for want of a support
        GroundMotion(ok, [], str(tmp_path))
    assert exc.value.key == "loads.ground_motion"
    for scale in (MAX_GROUND_ACCELERATION * 1.01, 1e100, 1e300 * G):
        with pytest.raises(ConfigError, match="loads.ground_motion.scale"):
            GroundMotion(dict(ok, scale=scale), [], str(tmp_path))
