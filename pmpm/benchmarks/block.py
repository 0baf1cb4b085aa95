"""The benchmark block: a clamped square of material sheared hard enough to yield.

Shared by the throughput, effects and scaling benchmarks, the kernel warm-up and tests.
"""
import math
from pmpm.benchmarks.args import MATERIALS
from pmpm.scene.config import parse_scene

__all__ = ["MATERIALS", "YIELD_AFTER_STEPS", "block_scene"]

#: the benchmark block's materials (the plastic ones' yield stress is set by block_scene)


#: steps of the block's shear after which a plastic block material yields (see block_scene);
#: the benchmarks run them before timing. Not fewer than ~15: the smooth model sub-steps
#: increments above 0.1 of the yield strain, and the step's shear increment is 1/30 of it here.
YIELD_AFTER_STEPS = 30


def block_scene(particles, shape="cubic", scheme="musl", material="elastic", ppc=2, aspect=1.0,
                gravity=None, force=False, extra_solver=None, extra_loads=None, track_F=False, fracture=False):
    """A square (or ``aspect`` wide) elastic block filling a grid, loaded hard enough to yield.

    The block is clamped at its base and starts with a shear velocity field (2 m/s at the
    top), so every particle moves. A plastic material's yield stress is set to the von Mises
    stress that shear reaches after ``YIELD_AFTER_STEPS`` steps: steel's 250 MPa would need
    ~100 times more steps than a benchmark runs, and a plastic model far below yield costs
    what an elastic one does, so the figures are those of the yielding regime, the model's
    most expensive one. ``track_F`` keeps the deformation gradient although nothing needs it
    (as an output field ``F`` does): its cost alone. ``fracture`` gives a plastic material the
    ductile fracture option with a locus it never reaches (eta = 1e6): the damage update's cost
    on every yielding point, no point failing.
    """
    cells_total = particles / ppc ** 2
    ny = max(4, int(round(math.sqrt(cells_total / aspect))))
    nx = max(4, int(round(cells_total / ny)))
    h = 0.01
    mat = dict(MATERIALS[material])
    if "yield_stress" in mat:
        E, nu, rho = mat["E"], mat["nu"], mat["density"]
        cfl = (extra_solver or {}).get("cfl", 0.5)
        dt = cfl * h / math.sqrt(E / (rho * (1 - nu * nu)))  # the CFL step below (plane stress)
        shear_rate = 2.0 / (ny * h)
        mat["yield_stress"] = math.sqrt(3.0) * E / (2 * (1 + nu)) * shear_rate * dt * YIELD_AFTER_STEPS
        if fracture:
            mat["fracture"] = {"model": "void_growth", "eta": 1e6, "fracture_energy": 1e5}
    data = {
        "title": f"throughput block {nx}x{ny} cells",
        "particles_per_cell": ppc,
        "grid": {"origin": [0.0, 0.0], "cell_size": h, "cells": [nx + 4, ny + 3]},
        "materials": {"m": mat},
        "bodies": [{"shape": "rectangle", "material": "m", "lower": [2 * h, 0.0],
                    "upper": [(nx + 2) * h, ny * h],
                    "velocity": [f"2.0 * y / {ny * h}", 0.0]}],
        "boundary": [{"type": "fixed", "lower": [0.0, 0.0], "upper": [(nx + 4) * h, 0.0]}],
        "solver": {"shape_function": shape, "scheme": scheme, "end_time": 1.0, "cfl": 0.5,
                   **(extra_solver or {})},  # (the yield stress above assumes this CFL number)
    }
    if gravity or force or extra_loads:
        data["loads"] = dict(extra_loads or {})
        if gravity:
            data["loads"]["gravity"] = [0.0, -9.81]
        if force:
            data["loads"]["forces"] = [{"lower": [2 * h, (ny - 1) * h], "upper": [(nx + 2) * h, ny * h],
                                        "force": [1e3, 0.0]}]
    if track_F:
        data["output"] = {"fields": ["x", "v", "stress", "F"]}
    return parse_scene(data, "bench.toml")
