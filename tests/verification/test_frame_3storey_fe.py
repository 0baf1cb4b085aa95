"""The continuum FE model of cases/frame_3storey.toml (frame3_fe_model.py) carries the scene's
mass and loads exactly as the MPM scene defines them (level 0 mesh, about 3 s), and it and the
frame model (frame2d_model.py, continuous joints) agree in the first two periods and the step
response (level 1 mesh, about 30 s).

The frame model's Krawinkler scissors joint (``joints="scissors"``) does not: T1 2.7% long, T2
4.5% short, the peak 6.5% high; its column is rigid through the joint, while the strips'
column bends through it (docs/portal_frame.md section 11).
"""
import os
import sys
import tomllib

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import frame3_fe_model as f3  # noqa: E402


@pytest.fixture(scope="module")
def fe():
    return f3.Frame3FE(f3.read_scene3(), 0.2, 0)


def test_mass_is_steel_plus_nodal_masses(fe):
    # the strips' steel (A L rho per expanded body, the thickness rule gives A exactly) plus the
    # [[frame.masses]] of the TOML: the panels' derived density must add exactly those masses;
    # exact quadrature of a polynomial integrand, so only round-off (1e-9) separates them
    with open(f3.SCENE3, "rb") as fh:
        raw = tomllib.load(fh)
    rho = raw["variants"]["elastic"]["materials.steel"]["density"]
    steel = sum(m.area * (m.box[3] - m.box[2] if m.vertical else m.box[1] - m.box[0]) * rho
                for m in fe.data.members)
    lumped = sum(e["mass"] for e in raw["frame"]["masses"])
    assert fe.total_mass() == pytest.approx(steel + lumped, rel=1e-9)


def test_loads_total_the_scene_forces(fe):
    # the basis is a partition of unity: a unit x translation's work on f is the total force
    e = fe.basis.project(lambda x: np.array([np.ones_like(x[0]), np.zeros_like(x[0])]))
    with open(f3.SCENE3, "rb") as fh:
        raw = tomllib.load(fh)
    assert float(e @ fe.f) == pytest.approx(sum(f["force"][0] for f in raw["frame"]["loads"]), rel=1e-9)
    assert len(fe.data.loads) == 3


# --- the two independent models of the frame against each other ---------------------------------
# frame2d_model (Timoshenko members, columns continuous through the joints) and this continuum
# model share nothing but the scene file; the MPM is checked against both (test_frame_3storey.py,
# the study for T2). Bounds: the issue's, 3% for the first two periods and 5% for the step-load
# peak roof drift, here applied also to the whole 1.5 s history (RMS relative to the largest drift).

@pytest.fixture(scope="module")
def fine():
    return f3.Frame3FE(f3.read_scene3(), 0.2, 1, track_cell=0.1)   # 0.2% from its Richardson limit


@pytest.fixture(scope="module")
def frame():
    import frame2d_model
    return frame2d_model.from_scene(str(f3.SCENE3))


def test_frame_model_periods_match_the_continuum(fine, frame):
    fe, fm = fine.periods(3), frame.modes(3)[0]
    print("periods continuum", fe, "frame model", fm)
    assert fm[0] == pytest.approx(fe[0], rel=0.03)
    assert fm[1] == pytest.approx(fe[1], rel=0.03)


def test_frame_model_step_response_matches_the_continuum(fine, frame):
    t = np.arange(0.0, 1.5, 1e-3)
    u = f3.responses(fine, t)[0]
    ff = np.array([frame.step_response(t, frame.node_dofs[n][0]) for n in f3.JOINTS])
    first = t < 0.7 * fine.periods(1)[0]
    assert ff[2][first].max() == pytest.approx(u[2][first].max(), rel=0.05)
    gaps = [np.sqrt(np.mean((ff[k] - u[k]) ** 2)) / np.abs(u[k]).max() for k in range(3)]
    print("first peak frame / continuum", ff[2][first].max() / u[2][first].max(), "rms gaps", gaps)
    assert max(gaps) < 0.05


def test_frame_model_scissors_joint_is_the_gap():
    # Krawinkler's one-spring panel (the column rigid through the joint) is what made the frame
    # model disagree with the continuum: with it T2 is short by more than the 3%, while
    # with both models' panels rigid they agree (docs/portal_frame.md section 11). Guards the
    # joint idealisation being the one used above.
    import frame2d_model
    continuous = frame2d_model.from_scene(str(f3.SCENE3)).modes(2)[0]
    scissors = frame2d_model.from_scene(str(f3.SCENE3), joints="scissors").modes(2)[0]
    assert scissors[1] < 0.97 * continuous[1]
