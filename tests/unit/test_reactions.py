"""Support reactions (pmpm.results.reactions): the grid update's constraint impulses, their
moment, the mean over a sampling interval, and that nothing changes when none is asked for."""
import numpy as np

from pmpm.core import kernels as K
from pmpm.core.grid import Grid, GridWindow
from pmpm.core.kernels.reference import reaction_reference
from pmpm.results.reactions import Reactions, node_centroid
from pmpm.scene.config import BoundaryConfig


def _grid_state():
    G = np.zeros((4, 3, K.N_FIELDS))
    rng = np.random.default_rng(3)
    G[..., 0] = rng.uniform(1.0, 2.0, (4, 3))
    G[..., 1:3] = rng.normal(size=(4, 3, 2))   # momentum
    G[..., 3:5] = rng.normal(size=(4, 3, 2))   # force
    return G


def _bcs():
    return (BoundaryConfig("floor", "fixed", (0.0, 0.0), (3.0, 0.0), (0.0, 0.0), reaction=True),
            BoundaryConfig("wall", "roller_y", (3.0, 0.0), (3.0, 2.0), (0.0, 0.0), reaction=True,
                           moment_about=(1.0, 1.0)))


def _window(bcs):
    from pmpm.physics.boundary import apply_boundary_masks
    grid = Grid((0.0, 0.0), 1.0, (3, 2))
    w = GridWindow(grid, 0, (0, 4))
    apply_boundary_masks(w, bcs)
    return grid, w


def test_impulses_are_the_momentum_the_bcs_remove():
    """Jx, Jy of each boundary = sum over its nodes of m (v_bc - v_free); its moment about
    the chosen point = sum (x - p) x J; and the velocities are those of the kernel without
    the bookkeeping (it only watches)."""
    bcs = _bcs()
    grid, w = _window(bcs)
    G0 = _grid_state()
    dt = 0.1
    G_plain = G0.copy()
    K.grid_update(G_plain, dt, 0.0, w.bc_mask, w.bc_vel, 0, 4, 0, 3, None, np.array([0, 0, 4]))
    r = Reactions(bcs, grid)
    r.bind(w, bcs)
    r.since = 0.0
    G = G0.copy()
    K.grid_update(G, dt, 0.0, w.bc_mask, w.bc_vel, 0, 4, 0, 3, None, np.array([0, 0, 4]), r.kernel_arg())
    np.testing.assert_array_equal(G, G_plain)
    # the NumPy twin, with the ownership written out here: the corner's x goes to the wall
    # (the later box), its y to the floor (the wall leaves y free)
    X, Y = w.node_coords()
    floor, wall = Y == 0.0, X == 3.0
    ids = np.full((*w.shape, 2), -1)
    ids[floor, :] = 0
    ids[wall, 0] = 1
    ref = reaction_reference(G0, dt, w.bc_mask, w.bc_vel, ids, 2, 0.0, 0.0, 1.0)
    points = np.array([[1.5, 0.0], [1.0, 1.0]])   # the floor's node centroid, the wall's point
    ref[:, 2] -= points[:, 0] * ref[:, 1] - points[:, 1] * ref[:, 0]
    R = r.take(dt, lambda a: a)
    # tolerance: rounding of sums of a dozen terms
    np.testing.assert_allclose(R, ref / dt, rtol=1e-12, atol=1e-12)
    assert R[1, 1] == 0.0 and R[0, 1] != 0.0   # a roller_y wall takes no vertical force


def test_mean_over_the_interval_and_nan_without_one():
    bcs = _bcs()
    grid, w = _window(bcs)
    r = Reactions(bcs, grid)
    r.bind(w, bcs)
    assert np.isnan(r.take(0.0, lambda a: a)).all()   # no time has passed since "start"
    r.sums[:] = [[2.0, 4.0, 0.0], [6.0, 0.0, 0.0]]
    R = r.take(0.5, lambda a: a)
    assert R[0, 0] == 4.0 and R[0, 1] == 8.0   # impulse / elapsed time
    assert not r.sums.any()                     # the next interval starts empty


def test_default_moment_point_is_the_node_centroid():
    grid = Grid((0.0, 0.0), 0.5, (8, 4))
    bc = BoundaryConfig("b", "fixed", (0.9, -1.0), (2.6, 0.0), (0.0, 0.0), reaction=True)
    np.testing.assert_allclose(node_centroid(bc, grid), [(1.0 + 1.5 + 2.0 + 2.5) / 4, 0.0])


def test_nothing_exists_when_nothing_is_asked(tmp_path):
    """A scene without reactions and cuts has no bookkeeping: no Reactions object, no recorder,
    the grid update gets None (numba compiles the kernel without the branch), no HDF5 group."""
    import h5py
    from mpi4py import MPI
    from pmpm.runner import Run
    from pmpm.scene.config import parse_scene
    data = {"grid": {"cell_size": 0.5, "cells": [8, 4]},
            "materials": {"m": {"type": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0}},
            "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.0, 0.0], "upper": [2.0, 1.0]}],
            "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [4.0, 0.0]}],
            "solver": {"end_time": 0.05}, "output": {"directory": str(tmp_path)}}
    run = Run(parse_scene(data, str(tmp_path / "plain.toml")), MPI.COMM_SELF)
    assert run.solver.effect("reactions") is None and run.solver.effect("sections") is None and run.structural is None
    run.execute()
    with h5py.File(run.path) as f:
        assert "sections" not in f and "reactions" not in f
    none_type = [sig for sig in K.grid_update.signatures if str(sig[11]) == "none"]  # reaction
    assert none_type, K.grid_update.signatures


def test_restart_continues_the_tables_without_duplicates(tmp_path):
    """A run stopped after some steps and restarted from its checkpoint: the /reactions and
    /sections rows are those of the uninterrupted run's time grid, each time once; only the
    very first reaction row (no interval behind it) is NaN: after the restart the impulses are
    summed from the restart time."""
    import dataclasses
    import h5py
    from mpi4py import MPI
    from pmpm.runner import Run
    from pmpm.scene.config import parse_scene
    data = {"grid": {"cell_size": 0.25, "cells": [12, 6]},
            "materials": {"m": {"type": "linear_elastic", "E": 100.0, "nu": 0.3, "density": 1.0}},
            "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.0, 0.0], "upper": [2.0, 1.0]}],
            "boundary": [{"name": "floor", "type": "fixed", "lower": [0.0, 0.0], "upper": [3.0, 0.0]}],
            "loads": {"gravity": [0.0, -1.0]},
            "solver": {"end_time": 0.4},
            "output": {"directory": str(tmp_path), "reactions": True, "history_interval": 0.02,
                       "checkpoint_interval": 0.1,
                       "section": [{"name": "mid", "segment": [[1.0, 0.0], [1.0, 1.0]]}]}}
    scene = parse_scene(data, str(tmp_path / "block.toml"))
    first = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, max_steps=15))  # dt = 0.0125: stops at 0.1875
    Run(first, MPI.COMM_SELF).execute()
    # as after a crash: the newest checkpoint is lost, the file holds rows past the older one
    def ckpt_time(path):
        with h5py.File(path) as f:
            return float(f.attrs["time"])
    ckpts = sorted(tmp_path.glob("block.ckpt*.h5"), key=ckpt_time)
    ckpts[-1].unlink()
    run = Run(scene, MPI.COMM_SELF, restart=str(tmp_path / "block.h5"))
    t_restart = run.solver.t
    run.execute()
    with h5py.File(tmp_path / "block.h5") as f:
        t_hist = f["history/time"][()]
        for group in ("reactions/floor", "sections/mid"):
            t = f[group]["time"][()]
            np.testing.assert_allclose(t, t_hist)            # one row per history time
            assert np.all(np.diff(t) > 0)
        Ry = f["reactions/floor/Ry"][()]
        t = f["reactions/floor/time"][()]
        assert np.isnan(Ry[0]) and np.isfinite(Ry[1:]).all()
        assert 0 < t_restart < 0.4
