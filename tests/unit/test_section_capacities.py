"""A cut's capacities (pmpm.results.hinges.cut_properties: Np, My, Mp, the hinge map's
references) against the closed forms of the particle rows they integrate.

A rectangular strip of depth d and thickness t, n rows of particles across it (midpoint rule,
rows at eta_i = (i + 1/2) d/n - d/2): A = t d, I = t d^3 / 12 (1 - 1/n^2) (the midpoint rule's
sum of eta^2), Z = sum t |eta_i| d/n = t d^2 / 4 (exact: |eta| is linear on each half, which the
midpoint rule integrates exactly), the extreme fibre c = d / 2; so Np = sigma_y A, My = sigma_y
I / c, Mp = sigma_y Z (the plastic moment of a rectangle, 1.5 My for n -> infinity)."""
import copy
import sys
import os

import pytest

sys.path.insert(0, os.path.dirname(__file__))
from test_sections import STRIP, _setup  # noqa: E402

from pmpm.scene.config import parse_scene  # noqa: E402

T, D, ROWS, SY = 0.1, 0.2, 8, 3.5e8


def test_capacities_of_a_rectangular_strip_are_its_closed_forms():
    data = copy.deepcopy(STRIP)
    data["materials"] = {"m": {"type": "bilinear_vonmises", "E": 2e11, "nu": 0.3, "density": 7850.0,
                               "yield_stress": SY, "hardening": 0.05}}
    data["output"] = {"section": [{"name": "a", "segment": [[1.23, -0.3], [1.23, 0.3]]}]}
    (cut,), _ = _setup(parse_scene(data, "strip.toml"))
    props = cut.properties
    A = T * D
    I = T * D ** 3 / 12 * (1 - 1 / ROWS ** 2)
    Z = T * D ** 2 / 4
    # tolerance: round-off of sums over the band's particles
    assert props["A"] == pytest.approx(A, rel=1e-12)
    assert props["I"] == pytest.approx(I, rel=1e-12)
    assert props["Z"] == pytest.approx(Z, rel=1e-12)
    assert props["Np"] == pytest.approx(SY * A, rel=1e-12)
    assert props["My"] == pytest.approx(SY * I / (D / 2), rel=1e-12)
    assert props["Mp"] == pytest.approx(SY * Z, rel=1e-12)
