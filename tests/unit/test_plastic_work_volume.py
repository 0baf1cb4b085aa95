"""The plastic work is kept in joules while a particle's volume changes (docs/fracture.md,
"Energy accounting"; issue 39 item 4).

The run counts a per-volume field times the particle's current volume. In plane stress the
thickness is constant and plastic flow, incompressible through the thickness, grows the in-plane
area by about half the axial plastic strain: work done at a smaller volume, multiplied by the
current one, was over-counted (the notched plate "gained" 4% of its external work). The
materials now deflate the per-volume plastic work by the step's volume ratio before adding the
step's plastic work (pmpm.physics.materials.base.keep_work_in_joules), so sum V w_p is the
joules the plastic flow dissipated.

A plane-stress strip pulled to a mean eps_p_eq of about 0.18, both steel materials: the energy
balance (kinetic + strain + plastic work = external work) closes to 1% of the external work.
Where 1% comes from: the old bookkeeping's error is w_p dV / V accumulated, with dV / V about half
the plastic strain (0.09 here): several percent of the external work, which is nearly all
plastic work (measured on the old code: -4.8% for both materials, so the test fails on it).
What the bookkeeping still leaves is the stored elastic energy's share of the same volume change,
U dV with U <= sigma^2 / 2E (1.3 MJ/m^3 at the 715 MPa the strip reaches) against a plastic
work near 95 MJ/m^3: about 0.1%; plus the explicit scheme's own energy error of the
elastic-plastic waves the sudden pull starts. 1% separates the two by a factor of five
(measured after the fix: -0.39% for both).
"""
import pytest

from pmpm.api import run

PULL = 2.0


def strip(material):
    return {
        "title": "plane-stress strip pulled into large plastic strain",
        "formulation": "plane_stress",
        "particles_per_cell": 2,
        "grid": {"origin": [-0.004, -0.004], "cell_size": 0.002, "cells": [28, 9]},
        "materials": {"steel": {"type": material, "E": 200e9, "nu": 0.3, "density": 7850.0,
                                "yield_stress": 355e6, "hardening": 0.01}},
        "bodies": [{"name": "strip", "shape": "rectangle", "material": "steel", "thickness": 0.01,
                    "lower": [0.0, 0.0], "upper": [0.04, 0.01]}],
        "boundary": [
            {"name": "held", "type": "fixed", "body": "strip", "face": "left"},
            {"name": "pulled", "type": "velocity", "velocity": [PULL, 0.0], "body": "strip", "face": "right"}],
        "solver": {"end_time": 4.0e-3, "cfl": 0.5},
        "output": {"interval": 4.0e-3, "fields": ["x", "eps_p_eq"]},
    }


@pytest.mark.parametrize("material", ["bilinear_vonmises", "smooth_vonmises"])
def test_energy_balance_closes_under_large_plastic_flow(material):
    r = run(strip(material), dataframes=False)
    e = r.energies
    eps = r.frames["eps_p_eq"][-1]
    assert eps.mean() > 0.1                       # the strip has flowed far
    loss = float(e["numerical_loss"][-1]) / float(e["external_work"][-1])
    print(f"{material}: mean eps_p_eq {eps.mean():.3f}, numerical loss {100 * loss:+.2f}% of the external work")
    assert abs(loss) < 0.01
