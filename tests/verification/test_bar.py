"""Fixed-free elastic bar in axial vibration against its closed form (docs/verification.md section 3).

u(x, t) = (v0 / omega) sin(omega t) sin(beta x),  beta = pi / (2 L),  omega = beta sqrt(E / rho).
"""
import math

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.scene.config import load_scene, parse_scene
from pmpm.build import build_solver

L, E, RHO = 25.0, 100.0, 1.0
BETA = math.pi / (2 * L)
OMEGA = BETA * math.sqrt(E / RHO)
PERIOD = 2 * math.pi / OMEGA


def bar_scene(cells, shape="cubic", v0=1e-3, scheme="musl", ppc=2, cfl=0.5, end=PERIOD):
    """The bar on a grid of ``cells`` cells over its length (one cell deep, nu = 0: 1-D)."""
    h = L / cells
    return parse_scene({
        "particles_per_cell": ppc,
        "grid": {"cell_size": h, "cells": [cells + 4, 3]},
        "materials": {"bar": {"type": "linear_elastic", "E": E, "nu": 0.0, "density": RHO}},
        "bodies": [{"shape": "rectangle", "material": "bar", "lower": [0.0, 0.0], "upper": [L, h],
                    "velocity": [f"{v0} * sin({BETA} * x)", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [0.0, 3 * h]}],
        "solver": {"shape_function": shape, "scheme": scheme, "end_time": end, "cfl": cfl},
    }, "bar.toml")


def run_bar(scene, v0):
    """Max over the run of |u - u_exact| / amplitude (all particles), and the energy history."""
    s = build_solver(scene, MPI.COMM_SELF)
    amp = v0 / OMEGA
    err, energy = 0.0, [s.energies()["total"]]
    while s.t < scene.solver.end_time - 1e-12:
        s.step()
        p = s.particles
        u = p["x"][:, 0] - p["x0"][:, 0]
        exact = amp * math.sin(OMEGA * s.t) * np.sin(BETA * p["x0"][:, 0])
        err = max(err, float(np.abs(u - exact).max()) / amp)
        energy.append(s.energies()["total"])
    return err, np.array(energy), s


def test_bar_case_mid_length_displacement_within_one_percent():
    """The shipped case (v0 = 0.1, cubic B-splines, MUSL) over one period: mid-length
    displacement within 1% of the exact amplitude, total energy constant within 1%."""
    scene = load_scene("cases/bar.toml")[0]
    s = build_solver(scene, MPI.COMM_SELF)
    mid = int(np.argmin(np.abs(s.particles["x0"][:, 0] - L / 2)))
    x_mid = s.particles["x0"][mid, 0]
    v0 = 0.1
    amp = v0 / OMEGA
    e0 = s.energies()["total"]
    assert e0 == pytest.approx(RHO * v0 ** 2 * L / 4 * 0.5, rel=1e-3)  # 0.0625 per unit area, 0.5 deep
    worst, drift = 0.0, 0.0
    while s.t < PERIOD - 1e-12:
        s.step()
        k = int(np.nonzero(s.particles["id"] == mid)[0][0])
        u = s.particles["x"][k, 0] - x_mid
        worst = max(worst, abs(u - amp * math.sin(OMEGA * s.t) * math.sin(BETA * x_mid)) / amp)
        drift = max(drift, abs(s.energies()["total"] / e0 - 1))
    assert worst < 0.01
    assert drift < 0.01


@pytest.mark.parametrize("shape", ["quadratic", "cubic"])
def test_bar_converges_at_second_order(shape):
    """B-splines converge at about second order in space (docs/verification.md section 6); the observed
    order between successive halvings must be at least 1.8 (small amplitude: no large strain)."""
    v0 = 1e-3
    errors = [run_bar(bar_scene(n, shape, v0), v0)[0] for n in (10, 20, 40, 80)]
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    assert min(orders[1:]) >= 1.8, (errors, orders)
    assert math.log2(errors[0] / errors[-1]) / 3 >= 1.8, (errors, orders)


@pytest.mark.parametrize("scheme", ["usl", "musl"])
def test_usl_and_musl_track_the_exact_solution(scheme):
    """USL and MUSL: 1% of the amplitude at 50 cells, and the error is spatial (it does not
    change when the time step is halved)."""
    v0 = 1e-3
    err, energy, _ = run_bar(bar_scene(50, "cubic", v0, scheme), v0)
    err_half_dt, _, _ = run_bar(bar_scene(50, "cubic", v0, scheme, cfl=0.25), v0)
    assert err < 0.01
    assert err_half_dt == pytest.approx(err, rel=0.1)
    assert np.all(np.isfinite(energy))


def test_usf_is_first_order_in_time():
    """USF strains from the start-of-step velocity while positions move with the end-of-step
    one, so strain and displacement lag by one step: its error is O(dt). Halving the CFL
    number must (nearly) halve it, and at CFL 0.1 it is within 1%."""
    v0 = 1e-3
    errs = [run_bar(bar_scene(50, "cubic", v0, "usf", cfl=c), v0)[0] for c in (0.4, 0.2, 0.1)]
    orders = [math.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert min(orders) > 0.8, errs
    assert errs[-1] < 0.01
