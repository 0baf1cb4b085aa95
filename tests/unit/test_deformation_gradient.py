"""The deformation gradient F per particle: the kinematics kernel against its NumPy twin, F
kept only when the scene needs it, and a run that inverts F stops with the particle named."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.core.kernels.reference import g2p_deformation_reference
from pmpm.core.shape import SHAPE_TAGS, SHAPES
from pmpm.build import build_solver
from pmpm.errors import ConfigError, UnstableRunError
from pmpm.scene.config import parse_scene

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}
CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])


def _state(n=200, seed=3):
    rng = np.random.default_rng(seed)
    x = ORIGIN + rng.uniform(0, 1, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 1e-9  # on an edge: the boundary-modified splines
    F = np.zeros((n, 5))
    F[:, :4] = np.array([1.0, 0.0, 0.0, 1.0]) + 0.3 * rng.normal(size=(n, 4))
    F[:, 4] = rng.uniform(0.8, 1.2, n)
    F[:, :4] *= np.sign(F[:, 0] * F[:, 3] - F[:, 1] * F[:, 2])[:, None] ** np.array([1, 1, 0, 0])  # det > 0
    vel = rng.normal(size=(CELLS[0] + 1, CELLS[1] + 1, 2))
    return x, F, rng.uniform(0.1, 0.3, n), vel


@pytest.mark.parametrize("name", list(SHAPES))
def test_kinematics_kernel_matches_reference(name):
    """de, dw, F <- (I + dt L) F, vol = vol0 det F and the polar-angle change agree with the
    matrix twin to round-off (1e-12 relative: the same sums in another order)."""
    x, F, vol0, vel = _state()
    dt = 0.01
    assert np.all(F[:, 0] * F[:, 3] - F[:, 1] * F[:, 2] > 0)
    G = np.zeros((CELLS[0] + 1, CELLS[1] + 1, K.N_FIELDS))
    G[..., K.REMAP:K.REMAP + 2] = vel
    n = len(x)
    de, dw, dq = np.empty((n, 3)), np.empty(n), np.empty((n, 2))
    vol, Fk = vol0.copy(), F.copy()
    K.g2p_kinematics(x, np.ones(n), vol, None, de, dw, Fk, vol0, dq, K.REMAP, None, dt,
                     None, None, None, None, G, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    r_de, r_dw, r_F, r_vol, r_dtheta = g2p_deformation_reference(ORDER[name], x, vel, F, vol0, dt,
                                                                ORIGIN, H, CELLS)
    np.testing.assert_allclose(de, r_de, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dw, r_dw, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Fk, r_F, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(vol, r_vol, rtol=1e-12, atol=1e-14)
    dtheta = np.arctan2(dq[:, 1], dq[:, 0])
    np.testing.assert_allclose(dtheta, r_dtheta, rtol=1e-9, atol=1e-11)  # eigh of F^T F: ~1e-13
    np.testing.assert_allclose(np.hypot(dq[:, 0], dq[:, 1]), 1.0, rtol=1e-14)  # a rotation
    assert np.abs(dtheta).max() > 1e-3  # the angles moved: the comparison means something


def _spin_scene(**solver):
    return parse_scene({
        "particles_per_cell": 2,
        "grid": {"origin": [-2.0, -2.0], "cell_size": 0.2, "cells": [20, 20]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e6, "nu": 0.3, "density": 1000.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [-1.2, -1.2], "upper": [1.2, 1.2],
                    "velocity": ["-0.5 * y", "0.5 * x"]}],
        "solver": {"end_time": 1.0, "cfl": 0.5, **solver},
        "output": {"fields": ["x", "v", "stress"]},
    }, "spin.toml")


def test_F_is_kept_only_when_the_scene_needs_it():
    """No material, rate or output needs F: it is not stored (off costs nothing); an output
    field F, or the Green-Naghdi rate, keeps it, starting from the identity with vol0 = vol."""
    plain = build_solver(_spin_scene(large_rotations=True), MPI.COMM_SELF)
    assert "F" not in plain.particles and "vol0" not in plain.particles and not plain.keeps_F
    gn = build_solver(_spin_scene(objective_rate="green_naghdi"), MPI.COMM_SELF)
    assert gn.keeps_F
    F = gn.particles["F"]
    np.testing.assert_array_equal(F, np.tile([1.0, 0.0, 0.0, 1.0, 1.0], (len(F), 1)))
    np.testing.assert_array_equal(gn.particles["vol0"], gn.particles["vol"])


def test_rigid_rotation_turns_F_into_the_rotation():
    """A square spinning at w = 0.5 rad/s, one step: deep inside (support away from the free
    edges, where B-splines reproduce the linear velocity field exactly; later steps are no
    longer a rigid rotation, the spinning square stretches) F = I + dt W, det F = 1 + (w dt)^2,
    the polar angle atan(w dt), to round-off; the solver's Green-Naghdi increment is that angle."""
    # (a fixed step below the CFL limit, 0.2 m / 33.1 m/s x 0.5 = 0.006 s: a larger one is refused)
    s = build_solver(_spin_scene(objective_rate="green_naghdi", time_step=0.005), MPI.COMM_SELF)
    s.step()  # (it sorts the particles: the mask is taken after it)
    deep = np.abs(s.particles["x"]).max(axis=1) < 1.2 - 3 * 0.2
    assert deep.sum() > 10
    F = s.particles["F"][deep]
    wdt = 0.5 * 0.005
    np.testing.assert_allclose(F, np.tile([1.0, -wdt, wdt, 1.0, 1.0], (len(F), 1)), rtol=0, atol=1e-13)
    vol = s.particles["vol"][deep] / s.particles["vol0"][deep]
    np.testing.assert_allclose(vol, 1 + wdt ** 2, rtol=1e-13)
    np.testing.assert_allclose(np.arctan2(s._dq[deep, 1], s._dq[deep, 0]), math.atan(wdt), rtol=1e-11)


def test_inverted_F_stops_the_run_naming_the_particle():
    """det F <= 0 is a fault: the step raises UnstableRunError with the particle id, its
    position and the time (run.py then saves the last good state, as for any instability)."""
    s = build_solver(_spin_scene(objective_rate="green_naghdi"), MPI.COMM_SELF)
    s.step()
    k = 7
    s.particles["F"][k, :4] = [1.0, 0.0, 0.0, -1.0]  # a reflection: det F = -1
    with pytest.raises(UnstableRunError) as err:
        s.step()
    msg = str(err.value)
    assert f"particle id {s.particles['id'][k]} at (" in msg and "det F = " in msg and "t = " in msg
    s.particles["F"][k, :4] = [np.nan, 0.0, 0.0, 1.0]  # not finite
    with pytest.raises(UnstableRunError, match="not finite"):
        s.step()


def test_objective_rate_config():
    assert _spin_scene().solver.large_rotations is False
    gn = _spin_scene(objective_rate="green_naghdi").solver
    assert (gn.large_rotations, gn.objective_rate) == (True, "green_naghdi")  # the rate switches it on
    assert _spin_scene(large_rotations=True).solver.objective_rate == "jaumann"  # today's default
    with pytest.raises(ConfigError, match="solver.objective_rate"):
        _spin_scene(objective_rate="truesdell")
    with pytest.raises(ConfigError, match="solver.objective_rate"):
        _spin_scene(objective_rate="jaumann", large_rotations=False)


@pytest.mark.parametrize("formulation", ["plane_stress", "plane_strain"])
def test_thickness_stretch_of_a_hypoelastic_material(formulation):
    """Uniaxial strain L = diag(a, 0) of linear_elastic, driven through the solver's phases:
    in plane stress szz = 0 gives d_ezz = -nu / (1 - nu) d_exx each step, so after n steps
    F33 = (1 - nu/(1 - nu) a dt)^n (to round-off); in plane strain F33 stays 1."""
    nu, a, dt, n = 0.3, 2.0, 1e-3, 50
    scene = parse_scene({
        "formulation": formulation,
        "grid": {"origin": [0.0, 0.0], "cell_size": 0.25, "cells": [6, 6]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e9, "nu": nu, "density": 1000.0}},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.5, 0.5], "upper": [1.0, 1.0]}],
        "solver": {"end_time": 1.0},
        "output": {"fields": ["x", "F"]},
    }, "stretch.toml")
    s = build_solver(scene, MPI.COMM_SELF)
    w, g = s.window, s.grid
    x = g.origin[0] + (w.ox + np.arange(w.shape[0])) * g.h
    for _ in range(n):
        w.G[...] = 0.0
        w.G[:, :, K.REMAP] = a * x[:, None]  # v_x = a x
        s.update_strain(dt, K.REMAP, move=False)
        s.update_stress()
    F = s.particles["F"]
    np.testing.assert_allclose(F[:, 0], (1 + a * dt) ** n, rtol=1e-12)
    expect = (1 - nu / (1 - nu) * a * dt) ** n if formulation == "plane_stress" else 1.0
    np.testing.assert_allclose(F[:, 4], expect, rtol=1e-12)


def test_restart_continues_F(tmp_path, monkeypatch):
    """F is a particle field like the others: checkpointed and read back, so a neo-Hookean bar
    run to t = 1 and restarted to t = 2 ends with the F, stress and positions of a run straight
    to t = 2 (bit for bit: the same steps, operations and order on one rank; a fixed step that
    is a power of two lands both runs on t = 1 exactly)."""
    import contextlib
    import io
    import os

    import h5py

    from pmpm.cli import main
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    bar = open(os.path.join(root, "cases", "bar.toml")).read()
    bar = bar.replace('type = "linear_elastic"', 'type = "neo_hookean"').replace(
        "interval = 0.5", "interval = 0.5\ncheckpoint_interval = 1.0").replace(
        'fields = ["x", "v", "stress", "strain"]', 'fields = ["x", "v", "stress", "F"]').replace(
        "cfl = 0.5", "time_step = 0.0078125")  # 2^-7 s: t = 1 exactly after 128 steps in both runs
    assert 'type = "neo_hookean"' in bar and '"F"]' in bar and "time_step" in bar

    def run(name, end, *extra):
        (tmp_path / name).write_text(bar.replace("end_time = 10.0", f"end_time = {end}"))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert main([str(tmp_path / name), "--no-plots", *extra]) == 0

    monkeypatch.chdir(tmp_path)
    run("straight.toml", 2.0)
    run("bar.toml", 1.0)
    run("bar.toml", 2.0, "--restart", "bar_results/bar.h5")
    with h5py.File("straight_results/straight.h5") as a, h5py.File("bar_results/bar.h5") as b:
        for k in ("x", "stress", "F"):
            np.testing.assert_array_equal(a["frames"][k][-1], b["frames"][k][-1])
        assert np.abs(a["frames"]["F"][-1][:, 0] - 1).max() > 1e-3  # the bar is stretched
