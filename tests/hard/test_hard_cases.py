"""Hard cases that stay numerically stable (issue "hard cases", part 2): the serial checks.

Each scene of cases/hard/ (docs/hard_cases.md says what breaks naive MPM codes there) runs once,
serially, to its end time. Every case must reach its end time with finite fields, lose no
particle, and never let its total energy (kinetic + internal work) exceed the initial energy plus
the external work by more than 2% of the largest energy in play (the issue's tolerance), and the
energy it loses is bounded and reported too (the two-sided check below). Further
tests check that each scene really is as hard as it claims (closing speed, nodal masses, cells
crossed, depth, swing, load) and, where a closed form exists, that the answer is right.

The same answer on 1 and 3 ranks is tested in tests/hard/mpi/ (run under mpirun -n 3); the fixed
time step above the stable limit in tests/hard/test_hard_divergence.py.
"""
import functools
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hard_cases import (CASES, ENERGY_TOLERANCE, ROOT, body_frame_energy, body_velocities,  # noqa: E402
                        exact_load_work, lightest_active_node, load, refined, run_case, wave_speed)

#: what each case records after every step besides the exact work of its loads
PROBES = {"sparse_free_surface": lightest_active_node, "travelling_block": body_frame_energy,
          "impact": body_velocities}


#: cases run to an earlier cap than their own end time. frame_collapse runs "until its drift
#: passes 10% of its height or 1 s" (its [[stop]], end_time = 1 s); on its 0.05 m cells the drift
#: passes 10% only at its second peak, t = 0.091 s, and by 4e-8 m (measured: 0.36580004 m), so a
#: change far inside the physics' tolerances could take the run to the 1 s cap, about 10 minutes
#: on one core. The CI run is capped at the issue's comparison time, 0.1 s, instead.
CI_END_TIME = {"frame_collapse": 0.1}


def _ci_scene(name):
    scene = load(name)
    if name in CI_END_TIME:
        import dataclasses
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, end_time=CI_END_TIME[name]))
    return scene


@functools.lru_cache(maxsize=None)
def record(name):
    """One serial run per case per test session; ``probes[:, 0]`` is the exact work of the loads,
    ``probes[:, 1:]`` the case's own probe."""
    extra = PROBES.get(name, lambda s: [])
    return run_case(_ci_scene(name), probe=lambda s: [exact_load_work(s), *np.atleast_1d(extra(s))])


# -- the checks, for every case --------------------------------------------------------

@pytest.mark.parametrize("name", CASES)
def test_runs_to_its_end_time_with_finite_fields_and_every_particle(name):
    rec = record(name)
    s = rec.solver
    assert rec.error is None, f"{name}: stopped at t = {s.t:.6g} s: {rec.error}"
    end = rec.scene.solver.end_time
    # to its end time, or to its [[stop]] (frame_collapse: the drift criterion)
    assert abs(s.t - end) <= 1e-9 * end or (rec.scene.stop and rec.stopped is not None), f"{name}: t = {s.t}"
    for field, values in s.particles.fields.items():
        if np.issubdtype(values.dtype, np.floating):
            assert np.isfinite(values).all(), f"{name}: non-finite {field}"
    assert np.isfinite(rec.energy).all()
    # no particle lost: none removed, every id still there exactly once
    assert s.removed == 0
    assert np.array_equal(np.sort(s.particles["id"]), np.arange(s.n_total))


@pytest.mark.parametrize("name", CASES)
def test_energy_never_exceeds_the_initial_energy_plus_external_work(name):
    """Tolerance: the issue's 2% of the largest energy in play, checked after every step."""
    rec = record(name)
    excess = rec.energy_excess()
    k = int(np.argmax(excess))
    assert excess[k] <= ENERGY_TOLERANCE, (
        f"{name}: total energy exceeds initial + external work by {100 * excess[k]:.2f}% of the "
        f"largest energy in play ({rec.energy_scale():.4g} J) at t = {rec.t[k]:.4g} s")


@pytest.mark.parametrize("name", CASES)
def test_energy_never_exceeds_the_initial_energy_plus_the_exact_work_of_the_loads(name):
    """The same 2% criterion with the external work computed without pmpm's bookkeeping: the
    loads of these scenes are constant (gravity, step forces from t = 0), so their work is
    sum_p f_p . (x_p - x0_p), and supports that do not move (fixed nodes, rollers) do no work."""
    rec = record(name)
    work = rec.probes[:, 0]
    excess = (rec.energy[:, 3] - (rec.initial_energy + work)) / rec.energy_scale(external=work)
    k = int(np.argmax(excess))
    assert excess[k] <= ENERGY_TOLERANCE, (
        f"{name}: total energy exceeds initial + exact load work by {100 * excess[k]:.2f}% of the "
        f"largest energy in play at t = {rec.t[k]:.4g} s")


# -- the other side: the energy lost is bounded and reported ---------------------------------------
#
# loss(t) = (initial energy + exact work of the loads - total) / largest energy in play. Plastic
# work is part of the internal work, so only numerical dissipation and contact lose energy here.

#: no contact and no wall impact: the continuum conserves energy, so a loss is numerical
#: dissipation, held to the issue's 2% like the excess (the balance is checked both ways)
CONSERVATIVE = ("travelling_block", "sparse_free_surface", "thin_member", "frame_near_collapse",
                "frame_collapse", "cantilever_large_rotation")
#: cases that lose energy at their resolution by design: the impact (the bodies share one grid
#: velocity field at contact, an inelastic exchange on the contact nodes) and the high-CFL block
#: (its initial velocity waves of 1 to 3 cells are not representable on the grid). Both losses
#: are discretisation errors, so they must vanish under refinement: with dt proportional to h
#: (fixed CFL) MUSL is first order in time and cubic B-splines second order in space, so the
#: loss is O(h) at least; the check asks for half that order on a grid twice as fine,
#: loss(h/2) <= 2^-1/2 loss(h), to allow for the pre-asymptotic range of such coarse scenes.
CONVERGING = ("impact", "high_cfl")
#: (the cantilever, reported only while it swung against a roller wall, is conservative since
#: issue 20: its clamp alone, no wall)
REPORTED_ONLY = ()
HALF_ORDER = 2 ** -0.5

LOSSES = {}


@pytest.fixture(scope="module", autouse=True)
def _report_losses(request):
    """Hand the losses to tests/hard/conftest.py, which prints them in the terminal summary
    (reported whether or not the tests pass; docs/hard_cases.md quotes the numbers)."""
    request.config.hard_case_losses = LOSSES


def _loss(rec):
    return rec.energy_loss(rec.probes[:, 0])


def test_every_case_has_a_loss_check():
    assert sorted(CONSERVATIVE + CONVERGING + REPORTED_ONLY) == sorted(CASES)


@pytest.mark.parametrize("name", CONSERVATIVE + REPORTED_ONLY)
def test_energy_lost_is_bounded_and_reported(name):
    loss = _loss(record(name))
    LOSSES[name] = {"max": float(loss.max()), "final": float(loss[-1])}
    if name in CONSERVATIVE:
        k = int(np.argmax(loss))
        assert loss[k] <= ENERGY_TOLERANCE, (
            f"{name}: lost {100 * loss[k]:.2f}% of the largest energy in play by t = {record(name).t[k]:.4g} s")


@pytest.mark.parametrize("name", CONVERGING)
def test_energy_lost_falls_under_refinement(name):
    coarse = _loss(record(name))
    fine_rec = run_case(refined(load(name)), probe=lambda s: [exact_load_work(s)])
    assert fine_rec.error is None, fine_rec.error
    fine = _loss(fine_rec)
    LOSSES[name] = {"max": float(coarse.max()), "final": float(coarse[-1]), "max at h/2": float(fine.max())}
    assert coarse.max() > 0  # it does lose energy (else the check says nothing)
    assert fine.max() <= HALF_ORDER * coarse.max(), (
        f"{name}: loss {coarse.max():.3%} at h, {fine.max():.3%} at h/2: not converging")


# -- each case is as hard as it says, and right where a closed form exists ----------------------

def test_impact_closes_at_a_third_of_the_wave_speed_and_the_disks_bounce_apart():
    rec = record("impact")
    s = rec.solver
    c = wave_speed(s)  # plane strain dilatational speed, the one the CFL rule uses
    v = [b.velocity[0] for b in rec.scene.bodies]
    assert abs((v[0] - v[1]) - c / 3) <= 1e-5 * c  # the scene's speeds are rounded to 6 digits
    kinetic = rec.energy[:, 0]
    # the impact stores most of the kinetic energy as strain (measured: down to 6%)...
    assert kinetic.min() < 0.2 * rec.initial_energy
    # ...and gives it back: the disks leave each other (mean x-velocities reversed)
    left, right = rec.probes[-1, 1:]
    assert left < 0 < right
    # momentum, zero at the start, stays zero at every step (the disks have equal masses, so
    # their mean velocities are equal and opposite): the grid forces sum to zero by the
    # partition of unity; round-off of sums over 500 particles
    masses = [float(s.particles["m"][s.particles["body"] == b].sum()) for b in (0, 1)]
    assert masses[0] == pytest.approx(masses[1], rel=1e-14)
    assert np.abs(rec.probes[:, 1] + rec.probes[:, 2]).max() <= 1e-12 * v[0]


def test_travelling_block_crosses_many_cells_without_pumping_its_vibration():
    rec = record("travelling_block")
    s = rec.solver
    assert rec.track("front")[-1, 0] > 30 * s.grid.h
    # Vibration energy in the block's own frame (kinetic relative to the centre of mass plus
    # strain), against its initial value (no strain at t = 0). Cell crossing may pump it only by
    # a discretisation error, which converges with cubic B-splines (first order here: the
    # position update is first order in dt, and dt is proportional to h) and does not with
    # linear hat functions, whose force jumps at every crossing (docs/verification.md section 6;
    # +96% at h, docs/hard_cases.md). So the pumping must fall on a grid twice as fine, by at
    # least half of first order as in the energy-loss check above: pump(h/2) <= 2^-1/2 pump(h).
    pump = rec.probes[:, 1].max() / _initial_body_frame_kinetic(load("travelling_block")) - 1
    fine_scene = refined(load("travelling_block"))
    fine = run_case(fine_scene, probe=body_frame_energy)
    assert fine.error is None, fine.error
    pump_fine = fine.probes.max() / _initial_body_frame_kinetic(fine_scene) - 1
    assert pump > 0  # it does pump at the scene's resolution (else the check says nothing)
    assert pump_fine <= HALF_ORDER * pump, f"vibration pumped {pump:.2%} at h, {pump_fine:.2%} at h/2"


def _initial_body_frame_kinetic(scene):
    from mpi4py import MPI
    from pmpm.build import build_solver
    return body_frame_energy(build_solver(scene, MPI.COMM_SELF))


def test_sparse_free_surface_uses_nodes_lighter_than_a_millionth_of_a_particle():
    rec = record("sparse_free_surface")
    s = rec.solver
    assert all(b.particles_per_cell == 1 for b in rec.scene.bodies)
    # nodes down to the mass cutoff (1e-8 of the heaviest particle) take part in the step; the
    # scene must really produce them (measured: 1.0e-8)
    assert rec.probes[:, 1].min() < 1e-6


def test_sparse_free_surface_flies_with_its_momentum_and_its_centre_of_mass_on_a_line():
    """No load acts on the flying block: its momentum stays the initial one, sum m v(x0) of the
    scene's velocity field (computed here from the initial positions), and its centre of mass
    moves on the straight line x_G(0) + P t / M. FLIP moves exactly the momentum of the nodes
    it accelerates, so the only loss is what the nodes below the mass cutoff (1e-8 of the
    heaviest particle) hold each step: at most n_nodes 1e-8 m_max v_max per step."""
    rec = record("sparse_free_surface")
    s = rec.solver
    p = s.particles
    x0, m = p["x0"], p["m"]
    v0 = np.column_stack([1.2 + 0.262 * np.sin(np.pi * (x0[:, 0] - 0.93) / 1.2),
                          0.8 + 0.262 * np.sin(np.pi * (x0[:, 1] - 0.77) / 0.8)])
    M = m.sum()
    P0, P = (m[:, None] * v0).sum(axis=0), (m[:, None] * p["v"]).sum(axis=0)
    v_max = np.abs(v0).max() + 0.5  # the breathing adds less than 0.5 m/s (the velocity field above)
    lost = len(rec.t) * s.window.G.shape[0] * s.window.G.shape[1] * 1e-8 * m.max() * v_max
    assert np.abs(P - P0).max() <= lost, (P, P0, lost)
    x_line = (m[:, None] * x0).sum(axis=0) / M + P0 / M * s.t
    x_G = (m[:, None] * p["x"]).sum(axis=0) / M
    assert np.abs(x_G - x_line).max() <= s.t * lost / M + 1e-12, (x_G, x_line)
    assert np.linalg.norm(P0 / M) * s.t > 2.0  # it flew far: 2.9 m, 29 cells


def test_thin_member_is_one_cell_deep_and_bends_as_a_beam():
    rec = record("thin_member")
    s = rec.solver
    scene = rec.scene
    body = scene.bodies[0].geometry
    depth = body["upper"][1] - body["lower"][1]
    length = body["upper"][0] - body["lower"][0]
    assert abs(depth - s.grid.h) < 1e-12
    mat = scene.materials["m"]
    load_ = -scene.loads.forces[0].force[1]
    inertia = depth ** 3 / 12  # per unit thickness
    peak = 2 * load_ * length ** 3 / (3 * mat["E"] * inertia)  # step load: twice the static
    measured = -rec.track("tip")[:, 1].min()
    # Two particles through the depth integrate the second moment as 0.75 I (points at +-d/4), so
    # the discrete member may be up to 1/0.75 = 1.33 times as flexible as Euler-Bernoulli; a
    # locking member (linear hat functions: measured 0.43 of the peak) is far stiffer. Measured
    # with cubic B-splines: 1.02 of the peak.
    assert 0.7 * peak <= measured <= 1.35 * peak, (measured, peak)


def test_cantilever_swings_down_more_than_3m_and_back():
    rec = record("cantilever_large_rotation")
    uy = rec.track("tip")[:, 1]
    k = int(np.argmin(uy))
    assert uy[k] < -3.0, f"tip drops only {-uy[k]:.2f} m"
    # "and back": after the bottom of the swing the tip rises to within 1 m of where it started,
    # two thirds of the way up (the scene's first variant, linear_elastic_h0.25, measured 0.38 m
    # below; a beam torn off its clamp, as with 2 particles per cell, falls on below -5 m)
    assert uy[k:].max() > -1.0, f"tip comes back only to {uy[k:].max():.2f} m"




def test_frame_is_loaded_near_its_sway_collapse_load_and_yields():
    sys.path.insert(0, os.path.join(ROOT, "tests", "verification"))
    from frame_beam_model import E_STEEL, SIGMA_Y, sway_collapse_load
    rec = record("frame_near_collapse")
    s = rec.solver
    applied = rec.scene.loads.forces[0].force[0]
    assert abs(applied / sway_collapse_load() - 0.9) < 1e-6
    # a step load near collapse takes the frame far past first yield (measured: 27 times the
    # yield strain; an elastic run would not reach it at all)
    assert s.particles["eps_p_eq"].max() > 10 * SIGMA_Y / E_STEEL


def test_frame_is_loaded_past_its_sway_collapse_load_and_stops_when_its_drift_passes_a_tenth_of_its_height():
    """1.2 P_c with large rotations: above P_c the rigid-plastic frame has no equilibrium and only
    the 5% hardening arrests the sway, near the issue's collapse measure, a drift of 10% of the
    column height. The scene runs "until its drift passes 10% of its height or 1 s" (its [[stop]]
    and end_time; CI caps it at 0.1 s, see CI_END_TIME). The drift must come within the issue's
    3% refinement tolerance of 10% (this 0.05 m grid is the coarse end of that check), and if it
    passes 10% the run must end at the first step past it. Convergence under refinement is the
    study studies/frame_collapse.py (docs/hard_cases.md)."""
    sys.path.insert(0, os.path.join(ROOT, "tests", "verification"))
    from frame_beam_model import HEIGHT, sway_collapse_load
    case = load("frame_collapse")
    assert case.solver.large_rotations and case.solver.end_time == 1.0
    rec = record("frame_collapse")
    s = rec.solver
    applied = rec.scene.loads.forces[0].force[0]
    # the scene gives the load to 1e-2 N of 1.26e6 N
    assert abs(applied / sway_collapse_load() - 1.2) < 1e-6
    # the stop is the issue's: the loaded joint's drift above 10% of the height (to 1e-12 m)
    (stop,) = case.stop
    assert (stop.track, stop.quantity, stop.below) == ("upper_left_joint", "ux", None)
    assert abs(stop.above - 0.1 * HEIGHT) < 1e-12
    drift = rec.track("upper_left_joint")[:, 0]  # sampled every step
    assert drift.max() > (1 - 0.03) * stop.above, f"largest drift {drift.max():.4g} m by t = {rec.t[-1]:.4g} s"
    if rec.stopped is None:  # capped: never past the threshold
        assert drift.max() <= stop.above and abs(s.t - CI_END_TIME["frame_collapse"]) < 1e-12
    else:  # the first step past the threshold ends the run: its drift is above, every earlier one not
        assert drift[-1] > stop.above >= drift[:-1].max()
        assert rec.stopped["value"] == drift[-1] and rec.t[-1] == s.t == rec.stopped["time"]


def test_high_cfl_runs_at_cfl_0_9():
    rec = record("high_cfl")
    s = rec.solver
    assert rec.scene.solver.cfl == 0.9 and rec.scene.solver.time_step is None
    # the steps taken are 0.9 h / (c + max|v|): within 2% of 0.9 h / c for this slow block
    assert rec.dt.max() >= 0.88 * s.grid.h / wave_speed(s)
