"""XPIC(m) (pmpm.core.transfers.XPIC, pmpm.core.kernels.xpic; Hammerquist & Nairn 2017): the
particle pass against its NumPy twin, m = 1 is PIC, and the numerical loss falls with m, as the
velocity removed from a mode the grid resolves falls from (1 - lambda) to (1 - lambda)^m."""
import shutil
from pathlib import Path

import numpy as np
import pytest

import pmpm
from pmpm.core.kernels.reference import basis_matrix
from pmpm.core.kernels.xpic import grid_particle_grid
from pmpm.core.shape import SHAPE_TAGS
from pmpm.core.transfers import xpic_coefficients

ORDER = {"linear": 1, "quadratic": 2, "cubic": 3}
CELLS = (9, 6)
H = 0.25
ORIGIN = np.array([-1.0, 0.5])
REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", list(ORDER))
def test_grid_particle_grid_matches_reference(name):
    rng = np.random.default_rng(11)
    n = 300
    x = ORIGIN + rng.uniform(0, 1, (n, 2)) * np.array(CELLS) * H
    x[:5, 0] = ORIGIN[0] + 1e-9
    m = rng.uniform(0.5, 2, n)
    U = rng.normal(size=(CELLS[0] + 1, CELLS[1] + 1, 2))
    out = np.zeros_like(U)
    grid_particle_grid(x, m, U, out, 0, 0, ORIGIN, 1 / H, CELLS[0], CELLS[1], SHAPE_TAGS[name])
    N, _ = basis_matrix(ORDER[name], x, ORIGIN, H, CELLS)
    up = np.einsum("pij,ijd->pd", N, U)
    np.testing.assert_allclose(out, np.einsum("pij,p,pd->ijd", N, m, up), rtol=1e-12, atol=1e-12)


def test_coefficients():
    assert xpic_coefficients(1) == [1]
    assert xpic_coefficients(3) == [3, -3, 1]
    assert all(sum(xpic_coefficients(m)) == 1 for m in range(1, 9))   # keeps a boundary value


@pytest.fixture
def bar(tmp_path, monkeypatch):
    shutil.copy(REPO / "cases" / "bar.toml", tmp_path)
    monkeypatch.chdir(tmp_path)
    return "bar.toml"


def _run(bar, **over):
    return pmpm.run(bar, overrides={"solver.end_time": 4.0, **over}, dataframes=False)


def test_order_one_is_pic(bar):
    pic = _run(bar, **{"solver.pic_blend": 1.0})
    x1 = _run(bar, **{"solver.transfer": "xpic", "solver.xpic_order": 1})
    for track in pic.histories:
        for column in ("ux", "vx"):
            np.testing.assert_allclose(x1.histories[track][column], pic.histories[track][column],
                                       rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(x1.energies["numerical_loss"], pic.energies["numerical_loss"], rtol=1e-9)


def test_the_loss_falls_with_the_order(bar):
    loss = [float(_run(bar, **{"solver.transfer": "xpic", "solver.xpic_order": m}).energies["numerical_loss"][-1])
            for m in (1, 2, 4)]
    assert loss[0] > loss[1] > loss[2] > 0, loss


@pytest.mark.parametrize("solver, key", [
    ({"transfer": "apic", "shape_function": "linear"}, "solver.transfer"),
    ({"transfer": "apic", "interpolation": "ugimp", "shape_function": "cubic"}, "solver.transfer"),
    ({"transfer": "xpic", "interpolation": "cpdi"}, "solver.transfer"),
    ({"transfer": "apic", "pic_blend": 0.1}, "solver.pic_blend"),
    ({"transfer": "xpic", "pic_blend": 0.1}, "solver.pic_blend"),
    ({"xpic_order": 3}, "solver.xpic_order"),
    ({"transfer": "xpic", "xpic_order": 0}, "solver.xpic_order"),
    ({"transfer": "taylor"}, "solver.transfer"),
])
def test_bad_transfer_settings_name_their_key(solver, key):
    from pmpm.errors import ConfigError
    from pmpm.scene.config import parse_scene
    scene = {"grid": {"origin": [0.0, 0.0], "cell_size": 0.5, "cells": [10, 4]},
             "materials": {"m": {"type": "linear_elastic", "E": 100.0, "nu": 0.0, "density": 1.0}},
             "bodies": [{"shape": "rectangle", "material": "m", "lower": [0.0, 0.0], "upper": [2.0, 0.5]}],
             "solver": {"end_time": 1.0, **solver}}
    with pytest.raises(ConfigError) as err:
        parse_scene(scene, "bar.toml")
    assert str(err.value).startswith(key) or key in str(err.value)
