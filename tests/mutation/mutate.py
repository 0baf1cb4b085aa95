#!/usr/bin/env python
"""Targeted mutation testing: plant one plausible physics bug at a time in a scratch copy of the
repository and check that the tests named for it fail.

Usage::

    python tests/mutation/mutate.py            # every mutation (docs/testing.md: run time)
    python tests/mutation/mutate.py --fast     # the CI subset (tests/unit/test_mutation_fast.py)
    python tests/mutation/mutate.py --only NAME [--only NAME ...]
    python tests/mutation/mutate.py --list     # names, files and killing tests, nothing run

Each mutation is (name, file, the exact original snippet, its replacement, the test commands
expected to kill it). The driver

1. checks that every selected snippet occurs exactly once in its file, and stops with exit
   code 2 naming the ones that do not (the source moved: the list must follow it, it cannot
   rot silently);
2. copies the tree (without .git, .venv and caches) into a temporary directory and runs the
   killing tests there unmutated once (the baseline: a test that already fails kills nothing);
3. for each mutation: replaces the snippet, runs its tests with PYTHONPATH at the copy and
   NUMBA_CACHE_DIR in the scratch directory, and restores the file (with its time stamp, so
   numba's cache of the unmutated sources stays valid);
4. prints a table and, last, one JSON line; exits 0 when every mutation was killed, 1 otherwise.

pmpm/jitcache.py names the kernel cache by a hash of the numba modules' sources, so a mutated
kernel compiles afresh (about a minute per mutation of a kernel file; mutations of other files
reuse the baseline's compiled kernels).

A test command is a list of arguments for ``python -m pytest`` (run in the copy), or, when its
first element is ``("mpi", n)``, the same under ``mpirun -n n``. "killed" means pytest exited 1
(tests failed); any other non-zero code (collection error, no test ran) is an error of the
driver's list, reported as such and counted as not killed.
"""
import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
PYTEST = ["-q", "-x", "-p", "no:cacheprovider", "--no-header", "-o", "addopts="]
#: a test command that runs longer than this is stopped and the mutation counted as killed
#: ("timeout": a planted bug that makes a run hang is caught, but the table says so)
TIMEOUT_S = 900


def mpi(n, *args):
    """A test command run under ``mpirun -n n``."""
    return [("mpi", n), *args]


KERNELS = "tests/unit/test_kernels.py"
TWIN = KERNELS + "::test_g2p_kinematics_matches_reference"
PHASES = "tests/unit/test_solver_phases.py"
ROT = "tests/unit/test_plastic_rotation.py"
GROUND = "tests/unit/test_ground_motion_between_samples.py"
REACT = "tests/unit/test_reactions_off_origin.py"
REPORTED = "tests/unit/test_reported_quantities.py"
GEOMETRY = "tests/unit/test_geometry_blind.py"
ENERGY = "tests/unit/test_energy_combined.py"
FILES = "tests/unit/test_files_blind.py"
TRANSFERS = "tests/unit/test_transfers_blind.py"

#: (name, file, original, replacement, test commands); ``fast`` names the CI subset
MUTATIONS = [
    dict(name="jaumann_spin_sign", file="pmpm/core/kernels/transfer.py",
         original="dw[p] = 0.5 * c * (lyx - lxy)", replacement="dw[p] = 0.5 * c * (lxy - lyx)",
         tests=[[TWIN]],
         why="the spin of the Jaumann rate with the wrong sign (rotates the stress the other way)"),
    dict(name="musl_strain_from_updated_velocity", file="pmpm/core/schemes.py",
         original="ctx.grid_velocity(source=REMAP, target=REMAP)\n        ctx.update_strain(dt, velocity_field=REMAP, move=True)",
         replacement="ctx.grid_velocity(source=REMAP, target=REMAP)\n        ctx.update_strain(dt, velocity_field=MOM, move=True)",
         tests=[[PHASES + "::test_musl_strain_comes_from_the_remapped_momenta"]],
         why="MUSL takes its strain from the updated grid velocity instead of the re-mapped one"),
    dict(name="volume_update_without_y_strain", file="pmpm/core/kernels/transfer.py",
         original="vol[p] *= 1.0 + dexx + deyy", replacement="vol[p] *= 1.0 + dexx",
         tests=[[TWIN]], fast=True,
         why="the volume update drops the y strain"),
    dict(name="no_volume_update", file="pmpm/core/kernels/transfer.py",
         original="vol[p] *= 1.0 + dexx + deyy", replacement="vol[p] *= 1.0",
         tests=[[TWIN]],
         why="particle volumes never change"),
    dict(name="tensor_instead_of_engineering_shear", file="pmpm/core/kernels/transfer.py",
         original="dgxy = c * (lxy + lyx)", replacement="dgxy = 0.5 * c * (lxy + lyx)",
         tests=[[TWIN]],
         why="the shear strain increment as tensor shear, half the engineering shear the materials expect"),
    dict(name="body_force_sign", file="pmpm/core/kernels/transfer.py",
         original="fy += m[p] * gravity[1]", replacement="fy -= m[p] * gravity[1]",
         tests=[[KERNELS + "::test_p2g_matches_reference"]],
         why="gravity's y component with the wrong sign on the grid (and in the external work)"),
    dict(name="internal_force_sign", file="pmpm/core/kernels/transfer.py",
         original="c = -vol[p] * inv_h", replacement="c = vol[p] * inv_h",
         tests=[[KERNELS + "::test_p2g_matches_reference"]],
         why="f_int = +V sigma . grad N (the material pushes the wrong way)"),
    dict(name="hardening_term", file="pmpm/physics/materials/smooth_vonmises.py",
         original="c = alpha * E / (1.0 - alpha)", replacement="c = alpha * E",
         tests=[["tests/unit/test_plasticity_point.py::test_post_yield_tangent_is_alpha_E"]],
         why="the Ziegler modulus without its 1 / (1 - alpha)"),
    dict(name="halo_accumulate_overwrites", file="decomposition/decomp.py",
         original="                    self._columns(arr, cols)[...] += buf",
         replacement="                    self._columns(arr, cols)[...] = buf",
         tests=[mpi(2, "tests/mpi/test_decomposition.py::test_halo_sums_equal_serial_sums")], fast=True,
         why="the halo accumulate replaces the owner's sum by the neighbour's part"),
    dict(name="one_round_halo_overwrites", file="decomposition/decomp.py",
         original="                    self._columns(arr, shared)[...] += buf",
         replacement="                    self._columns(arr, shared)[...] = buf",
         tests=[mpi(2, "tests/mpi/test_decomposition.py::test_one_round_halo_equals_accumulate_then_fill_bit_for_bit")],
         why="the one-round halo (the step's own) replaces the shared columns' sums by the neighbour's part"),
    dict(name="halo_fill_adds", file="decomposition/decomp.py",
         original="                    self._columns(arr, cols)[...] = buf",
         replacement="                    self._columns(arr, cols)[...] += buf",
         tests=[mpi(2, "tests/mpi/test_decomposition.py::test_halo_sums_equal_serial_sums")],
         why="the halo fill adds the owner's value to the ghost's instead of copying it"),
    dict(name="essential_bc_ignored", file="pmpm/core/kernels/grid_ops.py",
         original="                        v_new = bc_vel[i, j, d]\n",
         replacement="                        v_new = v_free\n",
         tests=[[KERNELS + "::test_grid_update_applies_bcs_and_mass_cutoff"]],
         why="prescribed nodal velocities are not imposed in the grid update"),
    dict(name="flip_pic_blend_swapped", file="pmpm/core/kernels/transfer.py",
         original="nvx = flip * (v[p, 0] + dvx) + pic * vx\n            nvy = flip * (v[p, 1] + dvy) + pic * vy",
         replacement="nvx = pic * (v[p, 0] + dvx) + flip * vx\n            nvy = pic * (v[p, 1] + dvy) + flip * vy",
         tests=[[KERNELS + "::test_g2p_velocity_matches_reference"]],
         why="the FLIP and PIC weights of the velocity update exchanged"),
    dict(name="cfl_without_particle_speed", file="pmpm/core/solver.py",
         original="dt = self.options.cfl * self.grid.h / (self.wave_speed + vmax)",
         replacement="dt = self.options.cfl * self.grid.h / self.wave_speed",
         tests=[[PHASES + "::test_cfl_step_is_c_h_over_wave_speed_plus_particle_speed"]],
         why="the CFL step ignores the particle speed"),
    dict(name="mass_cutoff_ignored", file="pmpm/core/kernels/grid_ops.py",
         original="accelerate = mi > mass_cutoff", replacement="accelerate = True",
         tests=[[KERNELS + "::test_grid_update_applies_bcs_and_mass_cutoff"]],
         why="nearly empty nodes are accelerated by f / m"),
    dict(name="cubic_gradient_block", file="pmpm/core/shape.py",
         original="W[6, q] = -1.5 * f2 + f + 0.5", replacement="W[6, q] = -1.5 * f2 + 2.0 * f + 0.5",
         tests=[[KERNELS + "::test_p2g_matches_reference"]],
         why="a wrong cubic B-spline derivative in the block path the transfer kernels use"),
    dict(name="cubic_gradient_scalar", file="pmpm/core/shape.py",
         original="g1 = 1.5 * f2 - 2.0 * f", replacement="g1 = 1.5 * f2 - f",
         tests=[["tests/unit/test_shape.py::test_cubic_gradient_is_derivative_of_weight"]],
         why="a wrong cubic B-spline derivative in the scalar path (edges, point loads)"),
    dict(name="plane_stress_thickness_unscaled", file="pmpm/scene/bodies.py",
         original="thickness = a * w_web + b * w_fl", replacement="thickness = w_web + w_fl",
         tests=[["tests/unit/test_config.py::test_i_section_matches_area_and_second_moment"]], fast=True,
         why="the I-section strip's thickness rule without the area / inertia scaling"),
    dict(name="objective_rate_sign", file="pmpm/core/kernels/objective.py",
         original="t[p, 0] = txx - 2.0 * w * txy", replacement="t[p, 0] = txx + 2.0 * w * txy",
         tests=[["tests/unit/test_objective_rate.py::"
                 "test_many_small_spins_rotate_the_stress_like_the_rotation_matrix"]],
         why="the Jaumann rotation of sxx with the wrong sign"),
    dict(name="musl_second_exchange_dropped", file="pmpm/core/schemes.py",
         original="ctx.exchange_halo(REMAPPED)\n", replacement="pass  # mutated: no re-map exchange\n",
         tests=[mpi(2, "tests/mpi/test_same_answer.py::test_bar_same_on_any_rank_count")],
         why="MUSL's re-mapped momenta not summed across ranks"),
    dict(name="solver_point_loads_not_scattered", file="pmpm/physics/loads.py",
         original="            K.scatter_point_loads(idx, s.particles[\"x\"], load_id, load_w, load_vec, *s._geometry())",
         replacement="            pass  # mutated: point loads not scattered",
         tests=[[PHASES + "::test_particles_to_grid_scatters_internal_body_and_set_forces"]],
         why="the solver's load path (scatter_point_loads) never reaches the grid"),
    dict(name="undamped_step_drops_the_force", file="pmpm/core/kernels/grid_ops.py",
         original="                            f -= damping * G[i, j, 1 + d]\n                        v_new = v_old + f * dt * inv_m",
         replacement="                            f -= damping * G[i, j, 1 + d]\n                            v_new = v_old + f * dt * inv_m",
         tests=[["tests/unit/test_effects.py::test_damping_off_is_compiled_out_and_loses_nothing_else"]],
         why="the specialisation without damping (damping = None) skips the momentum update"),
    dict(name="spurious_pic_dissipation", file="pmpm/core/transfers.py",
         original='K.g2p_velocity(p["x"], p["m"], p["v"], self.pic_blend,',
         replacement='K.g2p_velocity(p["x"], p["m"], p["v"], max(0.3, self.pic_blend),',
         tests=[["tests/hard/test_hard_cases.py::test_energy_lost_is_bounded_and_reported[thin_member]"]],
         why="a PIC share the scene did not ask for: energy drained, none created"),
    dict(name="apic_affine_momentum_dropped", file="pmpm/core/kernels/affine.py",
         original="return mp, (mp * C[p, 0] * h, mp * C[p, 1] * h, mp * C[p, 2] * h, mp * C[p, 3] * h, sx, sy)",
         replacement="return mp, (0.0, 0.0, mp * C[p, 2] * h, mp * C[p, 3] * h, sx, sy)",
         tests=[["tests/unit/test_apic.py::test_apic_conserves_angular_momentum_off_the_origin[musl]"]],
         why="APIC's p2g without the affine part of the x momentum: angular momentum not kept"),
    dict(name="numerical_loss_counts_damping", file="pmpm/core/solver.py",
         # the held terms in registration order: plastic_work, damping_work, ... (pmpm.core.effects)
         original="    for term in held:\n        loss = loss - term",
         replacement="    for term in held[:1] + held[2:]:\n        loss = loss - term",
         tests=[["tests/unit/test_numerical_loss.py::test_damping_is_damping_work_not_numerical_loss"]],
         why="damping work counted as numerical loss"),
    dict(name="plane_stress_modulus", file="pmpm/physics/materials/linear_elastic.py",
         original="c = E / (1 - nu * nu)", replacement="c = E",
         tests=[["tests/unit/test_elastic.py::test_plane_stress_increment_is_D_de"]],
         why="the plane-stress modulus E / (1 - nu^2) without its denominator"),
    # -- issue 21: the classes the suite was blind to, and every package ---------------------
    dict(name="back_stress_not_rotated", file="pmpm/physics/materials/base.py",
         original='    tensor_state_fields = ("back_stress",)', replacement="    tensor_state_fields = ()",
         tests=[[ROT + "::test_a_rigid_rotation_rotates_the_plastic_state"]],
         why="the kinematic back stress not rotated with the stress under large rotations"),
    dict(name="solver_skips_state_rotation", file="pmpm/core/solver.py",
         original="        for name in dict.fromkeys(n for m in self.materials for n in m.tensor_state_fields):\n            self._rotate(p[name])",
         replacement="        for name in ():\n            self._rotate(p[name])",
         tests=[[ROT + "::test_a_spinning_yielded_block_carries_its_back_stress_round"]],
         why="the solver's update_stress rotates the stress but not the materials' tensor state"),
    dict(name="bilinear_plane_strain_multiplier", file="pmpm/physics/materials/bilinear_vonmises.py",
         original="dl = (phi_tr - sy) / (c + 3.0 * mu)", replacement="dl = (phi_tr - sy) / (3.0 * mu)",
         tests=[[ROT + "::test_rotating_plastic_straining_matches_the_closed_form"]],
         why="the plane-strain return mapping's multiplier without the hardening modulus"),
    dict(name="ground_velocity_quadratic_term", file="pmpm/physics/groundmotion.py",
         original="(self.a[k + 1] - self.a[k]) * tau * tau / (2 * h))",
         replacement="(self.a[k + 1] - self.a[k]) * tau * tau / h)",
         tests=[[GROUND + "::test_velocity_at_and_between_samples_is_the_exact_integral"]],
         why="the ground velocity between samples with a wrong quadratic term of the integral"),
    dict(name="ground_accelerates_after_the_record", file="pmpm/physics/groundmotion.py",
         original="return float(self.v[-1] + self.a[-1] * 0.0)",
         replacement="return float(self.v[-1] + self.a[-1] * (time - self.t[-1]))",
         tests=[[GROUND + "::test_velocity_at_and_between_samples_is_the_exact_integral"]],
         why="after the record ends the ground keeps accelerating instead of keeping its velocity"),
    dict(name="reaction_moment_wrong_origin", file="pmpm/results/reactions.py",
         original="        x0, y0 = self.grid.node_coords(window.ox, window.oy)",
         replacement="        x0, y0 = window.ox * self.grid.h, window.oy * self.grid.h",
         tests=[[REACT + "::test_kernel_moments_on_a_window_away_from_the_origin"]],
         why="the reactions' moments taken with node coordinates that miss the grid's origin"),
    dict(name="reaction_moment_point_drops_a_term", file="pmpm/results/reactions.py",
         original="R[:, 2] -= self.points[:, 0] * R[:, 1] - self.points[:, 1] * R[:, 0]",
         replacement="R[:, 2] -= self.points[:, 0] * R[:, 1]",
         tests=[[REACT + "::test_a_held_body_reacts_with_minus_its_loads_and_their_moment"]],
         why="the moment moved to the boundary's point without the horizontal reaction's arm"),
    dict(name="elastic_energy_shear_term", file="pmpm/core/kernels/grid_ops.py",
         original="e += vol[p] * (0.5 * normal / E + (1 + nu) / E * sxy * sxy)",
         replacement="e += vol[p] * (0.5 * normal / E + 0.5 * (1 + nu) / E * sxy * sxy)",
         tests=[[REPORTED + "::test_energies_are_the_sums_of_the_frame_fields"]],
         why="the strain energy's shear term halved (tensor instead of engineering shear)"),
    dict(name="point_load_work_component", file="pmpm/core/kernels/point_loads.py",
         original="load_vec[k, 1] * dx[p, 1])", replacement="load_vec[k, 1] * dx[p, 0])",
         tests=[[REPORTED + "::test_external_work_is_the_work_of_gravity_and_the_tip_force"]],
         why="the work of a set force's y component taken over the x move"),
    dict(name="plastic_work_not_volume_weighted", file="pmpm/core/solver.py",
         original='(float(np.sum(p[t.name] * p["vol"])) if t.name in p else 0.0)',
         replacement='(float(np.sum(p[t.name])) if t.name in p else 0.0)',
         tests=[[REPORTED + "::test_energies_are_the_sums_of_the_frame_fields"]],
         why="the reported plastic work sums the densities without the particle volumes"),
    dict(name="history_uy_from_x0", file="pmpm/io/tracking.py",
         original="out[k] = (x[0] - x0[0], x[1] - x0[1],", replacement="out[k] = (x[0] - x0[0], x[1] - x0[0],",
         tests=[[REPORTED + "::test_histories_follow_their_particles"]],
         why="a track's uy measured from the initial x instead of y"),
    dict(name="stress_units", file="pmpm/io/schema.py",
         original='"stress": ("Pa", "Cauchy stress', replacement='"stress": ("kPa", "Cauchy stress',
         tests=[["tests/unit/test_python_api.py::test_in_memory_and_written_results_agree"]],
         why="the results file says kPa for a stress stored in Pa"),
    dict(name="rectangle_lattice_offset", file="pmpm/scene/bodies.py",
         original="xs = lo[0] + (np.arange(n[0]) + 0.5) * dx[0]", replacement="xs = lo[0] + (np.arange(n[0]) + 0.25) * dx[0]",
         tests=[[REPORTED + "::test_fields_and_their_derived_state"]],
         why="a rectangle's particles a quarter spacing off their cell centres along x"),
    dict(name="expression_minus_adds", file="pmpm/scene/expressions.py",
         original="ast.Sub: np.subtract", replacement="ast.Sub: np.add",
         tests=[["tests/unit/test_expressions.py::test_values_match_numpy"]],
         why="a scene expression's minus evaluated as a plus"),
    dict(name="roller_components_swapped", file="pmpm/physics/boundary.py",
         original='"roller_x": (1,), "roller_y": (0,)', replacement='"roller_x": (0,), "roller_y": (1,)',
         tests=[["tests/unit/test_reactions.py::test_impulses_are_the_momentum_the_bcs_remove"]],
         why="a roller fixes the component it should leave free"),
    dict(name="block_range_remainder", file="decomposition/slab.py",
         original="count = q + (1 if r > rank else 0)", replacement="count = q + (1 if r >= rank else 0)",
         tests=[["tests/unit/test_slab.py::test_block_range_covers_contiguously"]],
         why="the slab rule gives the remainder to one rank too many (overlapping slabs)"),
    dict(name="plastic_moment_from_inertia", file="pmpm/results/hinges.py",
         original='Mp=sigma_y * props["Z"])', replacement='Mp=sigma_y * props["I"])',
         tests=[["tests/unit/test_section_capacities.py::test_capacities_of_a_rectangular_strip_are_its_closed_forms"]],
         why="a cut's plastic moment from its second moment instead of its plastic modulus"),
    dict(name="effects_overhead_figure", file="pmpm/benchmarks/throughput.py",
         original='"overhead": med / base - 1,', replacement='"overhead": med / base,',
         tests=[["tests/unit/test_bench.py::test_effects_prints_every_effect"]],
         why="bench effects' JSON overhead is the time ratio, not the ratio less one it prints"),
    dict(name="effects_scene_without_its_effect", file="pmpm/benchmarks/throughput.py",
         original='"damping": block_scene(n, extra_loads={"damping": 0.5}),', replacement='"damping": block_scene(n),',
         tests=[["tests/unit/test_bench.py::test_each_effect_scene_differs_from_the_bare_block_by_its_effect_only"]],
         why="bench effects times the bare block under the name of an effect"),
    dict(name="migrate_rows_unsorted", file="decomposition/exchange.py",
         original='order = np.argsort(dest, kind="stable")', replacement="order = np.arange(len(dest))",
         tests=[mpi(2, "tests/mpi/test_decomposition.py::test_alltoallv_round_trip_mixed_dtypes")],
         why="migration packs the rows unsorted by destination: rows reach the wrong ranks"),
    dict(name="stress_component_names_swapped", file="pmpm/io/hdf5.py",
         original='"stress": ("sxx", "syy", "sxy", "szz"),', replacement='"stress": ("sxx", "sxy", "syy", "szz"),',
         tests=[[REPORTED + "::test_named_components_are_the_columns_they_name"]],
         why="the results file names the stress columns in the wrong order (syy labelled sxy)"),
    dict(name="mpi_outcomes_not_agreed", file="tests/conftest.py",
         original="    if _AGREE is not None:\n        _agree(_AGREE, item, report)",
         replacement="    pass  # mutated: no agreement",
         tests=[["tests/unit/test_mpi_failures_do_not_hang.py::test_with_x_a_failure_on_one_rank_stops_every_rank"]],
         why="under mpirun a failure on one rank is not a failure on the others (-x leaves them hanging)"),
    dict(name="viscous_work_dropped", file="pmpm/physics/rayleigh.py",
         original="        work += vol[p] * (sv[p, 0] * de[p, 0] + sv[p, 1] * de[p, 1] + sv[p, 2] * de[p, 2])",
         replacement="        work += 0.0",
         tests=[["tests/unit/test_damping.py::test_viscous_kernel_matches_its_numpy_twin",
                 "tests/unit/test_damping.py::test_cantilever_decays_at_the_asked_ratio"]],
         why="the viscous stress of Rayleigh damping dissipates energy the balance never counts"),
    dict(name="removal_energy_not_moved", file="pmpm/physics/events.py",
         original="        self.removed_energy += kinetic + held\n",
         replacement="        self.removed_energy += held\n",
         tests=[["tests/unit/test_events.py::test_energy_balance_closes_with_the_removed_energy"]],
         why="the kinetic energy of the removed body's particles vanishes from the balance"),
    # -- issue 38: the code added since 2026-12-02 (frame front end, supports, damping, events,
    # XPIC, ownership, validation, waiting), each with the test written to see it ----------------
    dict(name="frame_cut_offsets_by_lower_node", file="pmpm/scene/frame.py",
         original="cut_offsets={a: float(offsets[0]), b: float(offsets[1])}",
         replacement="cut_offsets={lo: float(offsets[0]), hi: float(offsets[1])}",
         tests=[[GEOMETRY + "::test_a_reversed_member_expands_like_its_hand_expansion"]],
         why="a member given from its upper / right node takes its cut offsets at the wrong ends"),
    dict(name="frame_weak_flange_precedence", file="pmpm/scene/frame.py",
         original='"flange_thickness": (p["bf"] - p["tw"]) / 2,',
         replacement='"flange_thickness": p["bf"] - p["tw"] / 2,',
         tests=[[GEOMETRY + "::test_a_weak_axis_strip_is_the_section_turned"]],
         why="the weak-axis strip's flange zone bf - tw / 2 (operator precedence) instead of (bf - tw) / 2"),
    dict(name="frame_line_load_over_the_clear_length", file="pmpm/scene/frame.py",
         original='"force": [m.load[0] * length, m.load[1] * length]',
         replacement='"force": [m.load[0] * (c1 - c0), m.load[1] * (c1 - c0)]',
         tests=[[GEOMETRY + "::test_a_reversed_member_expands_like_its_hand_expansion"]],
         why="a member's load per length times its clear length instead of its node-to-node length"),
    dict(name="frame_fixed_support_reach", file="pmpm/scene/frame.py",
         original="lower[across] -= depth / 2 + REACH_CELLS * h",
         replacement="lower[across] -= depth / 2 + h",
         tests=[["tests/unit/test_frame.py::test_supports_cuts_tracks_and_loads"]],
         why="a fixed frame support reaches one cell beyond the member's face on one side instead of two"),
    dict(name="frame_nodal_mass_density", file="pmpm/scene/frame.py",
         original="density=rho * (1 + mass / steel))",
         replacement="density=rho * mass / steel)",
         tests=[["tests/unit/test_frame.py::test_nodal_masses_add_exactly_their_mass_to_the_joint_panel"]],
         why="a nodal mass replaces the joint panel's steel instead of adding to it"),
    dict(name="section_spacing_axes_swapped", file="pmpm/results/sections.py",
         original="return abs(normal @ axis) * along + abs(normal[0] * axis[1] - normal[1] * axis[0]) * across",
         replacement="return abs(normal @ axis) * across + abs(normal[0] * axis[1] - normal[1] * axis[0]) * along",
         tests=[[GEOMETRY + "::test_i_section_cut_forces_are_the_band_integral"]],
         why="an I-section cut's particle spacing along its normal taken from the step across the strip"),
    dict(name="held_face_moment_sign", file="pmpm/physics/supports.py",
         original="reactions.sums[row, 2] += np.sum(x[mine] * Jy) - np.sum(y[mine] * Jx)",
         replacement="reactions.sums[row, 2] += np.sum(x[mine] * Jy) + np.sum(y[mine] * Jx)",
         tests=[[GEOMETRY + "::test_held_faces_react_with_minus_the_loads_and_their_moment"]],
         why="the moment of a held face's constraint impulses with the wrong sign of its y Jx term"),
    dict(name="held_face_reaction_drops_x", file="pmpm/physics/supports.py",
         original="            reactions.sums[row, 0] += Jx.sum()\n",
         replacement="            reactions.sums[row, 0] += 0.0\n",
         tests=[[GEOMETRY + "::test_held_faces_react_with_minus_the_loads_and_their_moment"]],
         why="a held face's horizontal reaction leaves out the constraint impulses"),
    dict(name="held_particles_momentum_not_counted", file="pmpm/physics/supports.py",
         original="            reactions.sums[row, 0] += cx.sum()\n",
         replacement="            reactions.sums[row, 0] += 0.0\n",
         tests=[[GEOMETRY + "::test_a_held_face_under_a_moving_body_reacts_with_its_momentum_balance"]],
         why="the momentum the held particles' velocities lose is left out of their support's reaction"),
    dict(name="numerical_loss_drops_viscous", file="pmpm/core/solver.py",
         # the held terms in registration order: plastic, damping, viscous, removed (pmpm.core.effects)
         original="    for term in held:\n        loss = loss - term",
         replacement="    for term in held[:2] + held[3:]:\n        loss = loss - term",
         tests=[[ENERGY + "::test_the_loss_column_is_initial_plus_external_less_every_term"]],
         why="the numerical loss counts Rayleigh damping's viscous work as lost"),
    dict(name="numerical_loss_drops_removed", file="pmpm/core/solver.py",
         original="    for term in held:\n        loss = loss - term",
         replacement="    for term in held[:3]:\n        loss = loss - term",
         tests=[[ENERGY + "::test_the_loss_column_is_initial_plus_external_less_every_term"]],
         why="the numerical loss counts the energy a removed body carried out as lost"),
    dict(name="summary_share_without_viscous", file="pmpm/runner.py",
         original='held = [e[t.name] for t in energy_terms()]',
         replacement='held = [e[t.name] for t in energy_terms() if t.name != "viscous_damping_work"]',
         tests=[[ENERGY + "::test_the_summary_share_is_the_loss_over_initial_plus_external"]],
         why="the run summary's energy put in leaves out the viscous work (the issue-38 defect)"),
    dict(name="released_work_without_viscous_stress", file="pmpm/physics/events.py",
         original='acting = 0.5 * (before + particles["stress"][rows, :3]) + viscous',
         replacement='acting = 0.5 * (before + particles["stress"][rows, :3])',
         tests=[[ENERGY + "::test_balance_closes_across_a_damped_removal"]],
         why="the work a fading body holds back leaves out the viscous stress it passed on"),
    dict(name="event_fades_at_half_rate", file="pmpm/physics/events.py",
         original="return 1.0 - (t - self.time) / self.duration",
         replacement="return 1.0 - (t - self.time) / (2 * self.duration)",
         tests=[[ENERGY + "::test_a_fading_body_passes_its_share_of_stress_and_viscous_stress"]],
         why="a removed body's stress fades over twice its duration"),
    dict(name="event_particles_leave_at_its_start", file="pmpm/physics/events.py",
         original="return not self.done and t_next >= self.time + self.duration * (1 - 1e-12)",
         replacement="return not self.done and t_next >= self.time",
         tests=[["tests/unit/test_events.py::test_the_body_leaves_at_the_end_of_its_fade"]],
         why="a removed body's particles leave when its fade starts, not when it ends"),
    dict(name="rayleigh_step_without_the_limit", file="pmpm/physics/rayleigh.py",
         original="xi = self.a1 * wave_speed / (undamped_limit * h)",
         replacement="xi = self.a1 * wave_speed / h",
         tests=[[ENERGY + "::test_the_damped_step_is_the_rules_closed_form"]],
         why="the damped stable step's xi without the undamped CFL limit (a step shorter than the rule)"),
    dict(name="rayleigh_undamped_limit_cubic", file="pmpm/physics/rayleigh.py",
         original='UNDAMPED_CFL_LIMIT = {"cubic": 2.5,', replacement='UNDAMPED_CFL_LIMIT = {"cubic": 2.57,',
         tests=[[ENERGY + "::test_the_damped_step_is_the_rules_closed_form"]],
         why="the cubic undamped limit taken as measured, without the rule's 3% margin"),
    dict(name="rayleigh_a1_half", file="pmpm/physics/rayleigh.py",
         original="return 2 * ratio * w1 * w2 / (w1 + w2), 2 * ratio / (w1 + w2)",
         replacement="return 2 * ratio * w1 * w2 / (w1 + w2), ratio / (w1 + w2)",
         tests=[["tests/unit/test_damping.py::test_coefficients_are_the_two_frequency_formula"]],
         why="Rayleigh damping's stiffness coefficient a1 half the two-frequency formula's"),
    dict(name="pushover_ratio_without_plastic_work", file="pmpm/results/capacity.py",
         original='held = np.asarray(e["strain_energy"][:n]) + np.asarray(e["plastic_work"][:n])',
         replacement='held = np.asarray(e["strain_energy"][:n])',
         tests=[[ENERGY + "::test_the_pushovers_quasi_static_ratio_is_kinetic_over_strain_plus_plastic"]],
         why="the pushover's quasi-static ratio over the strain energy alone (the plastic work left out)"),
    dict(name="restart_viscous_work_wrong_name", file="pmpm/runner.py",
         original='float(attrs.get(name, 0.0))',
         replacement='float(attrs.get(name.replace("viscous_damping_work", "viscous_work"), 0.0))',
         tests=[[FILES + "::test_a_restarted_damped_run_ends_with_the_uninterrupted_energies"]],
         why="a restart reads the viscous work back under a name it was not written with (from zero)"),
    dict(name="checkpoint_overwrites_the_newer", file="pmpm/io/checkpoint.py",
         original="return paths[int(np.argmin(steps))]", replacement="return paths[int(np.argmax(steps))]",
         tests=[[FILES + "::test_the_next_checkpoint_replaces_the_older_file"]],
         why="the next checkpoint overwrites the newer of the two files (a crash then loses both intervals)"),
    dict(name="owner_record_not_compared", file="pmpm/io/ownership.py",
         original="if owner is not None and found != owner:",
         replacement="if owner is not None and found != owner and False:",
         tests=[[FILES + "::test_a_file_of_another_scene_is_never_overwritten"]],
         why="an HDF5 file whose owner record names another scene is overwritten"),
    dict(name="series_lengths_not_compared", file="pmpm/io/validate.py",
         original="if len(lengths) > 1:", replacement="if len(lengths) > 2:",
         tests=[[FILES + "::test_an_inconsistent_results_file_is_refused"]],
         why="a results file whose energy columns have different lengths is read"),
    dict(name="frame_particle_count_not_checked", file="pmpm/io/validate.py",
         original="if d.ndim < 2 or d.shape[:2] != (count, n) or",
         replacement="if d.ndim < 2 or d.shape[:1] != (count,) or",
         tests=[[FILES + "::test_an_inconsistent_results_file_is_refused"]],
         why="a results file whose frame fields hold another particle count is read"),
    dict(name="history_rows_not_checked", file="pmpm/io/validate.py",
         original="if d.shape != (ht.shape[0], len(columns)):", replacement="if d.shape[1:] != (len(columns),):",
         tests=[[FILES + "::test_an_inconsistent_results_file_is_refused"]],
         why="a results file whose track history has another row count than its time column is read"),
    dict(name="xpic_smoothing_drops_the_boundary", file="pmpm/core/transfers.py",
         original="        return self._apply_bc(w, out)\n", replacement="        return out\n",
         tests=[[TRANSFERS + "::test_xpic_keeps_a_moving_boundarys_velocity"]],
         why="XPIC's smoothing pass loses the prescribed (moving) boundary velocities"),
    dict(name="xpic_smoothing_not_summed_across_ranks", file="pmpm/core/transfers.py",
         original="        ctx.sum_halo(out)\n", replacement="        pass  # mutated: no halo sum\n",
         tests=[mpi(2, "tests/mpi/test_xpic_boundary_mpi.py"), mpi(3, "tests/mpi/test_xpic_boundary_mpi.py")],
         why="XPIC's smoothing pass not summed across the slab boundaries"),
    dict(name="xpic_coefficient_sign", file="pmpm/core/transfers.py",
         original="return [(-1) ** (k + 1) * comb(order, k) for k in range(1, order + 1)]",
         replacement="return [(-1) ** k * comb(order, k) for k in range(1, order + 1)]",
         tests=[["tests/unit/test_xpic.py::test_coefficients"]],
         why="XPIC(m)'s coefficients with the wrong alternating sign"),
    dict(name="apic_usf_skips_the_force_pass", file="pmpm/core/transfers.py",
         original="            return FLIP.p2g(self, ctx, False)\n", replacement="            return None\n",
         tests=[[TRANSFERS + "::test_apic_under_usf_runs_the_bar"]],
         why="APIC under USF skips its force pass (no internal force reaches the grid)"),
    dict(name="waiting_timer_slack_unset", file="decomposition/waiting.py",
         original="    if not _slack_set:\n        _fine_timer()\n", replacement="    pass  # mutated: no fine timer\n",
         tests=[[TRANSFERS + "::test_the_first_nap_sets_a_fine_timer_slack"]],
         why="a wait between ranks naps with the default 50 us timer slack"),
    dict(name="waiting_timer_slack_value", file="decomposition/waiting.py",
         original="prctl(_PR_SET_TIMERSLACK, 1000, 0, 0, 0)", replacement="prctl(_PR_SET_TIMERSLACK, 50000, 0, 0, 0)",
         tests=[[TRANSFERS + "::test_the_first_nap_sets_a_fine_timer_slack"]],
         why="the timer slack set to Linux's default instead of 1 us"),
]


def _pytest_argv(cmd):
    """argv of one test command (see the module docstring)."""
    if cmd and isinstance(cmd[0], tuple):
        n = cmd[0][1]
        return ["mpirun", "-n", str(n), "--oversubscribe", "--bind-to", "none",
                sys.executable, "-m", "pytest", *PYTEST, *cmd[1:]]
    return [sys.executable, "-m", "pytest", *PYTEST, *cmd]


def _label(cmd):
    if cmd and isinstance(cmd[0], tuple):
        return f"mpirun -n {cmd[0][1]} " + " ".join(cmd[1:])
    return " ".join(cmd)


def check_snippets(selected, root=ROOT):
    """Names and reasons of the mutations whose snippet is not exactly once in its file."""
    bad = []
    for m in selected:
        path = root / m["file"]
        if not path.is_file():
            bad.append((m["name"], f"{m['file']} does not exist"))
            continue
        count = path.read_text().count(m["original"])
        if count != 1:
            bad.append((m["name"], f"snippet found {count} times in {m['file']} (must be exactly once)"))
    return bad


def _copy_tree(dest):
    patterns = shutil.ignore_patterns(".git", ".venv", "__pycache__", "*.pyc", ".pytest_cache",
                                      "*_results", "*.egg-info")

    def ignore(folder, names):
        # a run's output folder "results" at the top, never the package pmpm/results
        top = {"results"} & set(names) if pathlib.Path(folder) == ROOT else set()
        return patterns(folder, names) | top

    shutil.copytree(ROOT, dest, ignore=ignore, symlinks=True)


def _env(tree, cache):
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env["NUMBA_CACHE_DIR"] = str(cache)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    return env


def _run(cmd, tree, env, log):
    """Exit code of one test command in the copy ("timeout" after TIMEOUT_S) and its seconds."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(_pytest_argv(cmd), cwd=tree, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=TIMEOUT_S)
        code, out = proc.returncode, proc.stdout
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout or ""
        code, out = "timeout", out.decode(errors="replace") if isinstance(out, bytes) else out
    log.write(f"$ {_label(cmd)}  -> {code}\n{out}\n")
    log.flush()
    return code, time.perf_counter() - t0


def _status(codes):
    """killed (a test failed or hung), survived (all passed) or error (the list is wrong)."""
    if any(c == 1 or c == "timeout" for c in codes):
        return "killed"
    if all(c == 0 for c in codes):
        return "survived"
    return "error"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fast", action="store_true", help="only the CI subset")
    ap.add_argument("--only", action="append", default=[], metavar="NAME", help="only this mutation (repeatable)")
    ap.add_argument("--list", action="store_true", help="print the mutations and their tests, run nothing")
    ap.add_argument("--no-baseline", action="store_true", help="skip the unmutated run of the killing tests")
    ap.add_argument("--log", default=None, help="write the tests' output here (default: in the scratch dir, removed)")
    args = ap.parse_args(argv)

    selected = MUTATIONS
    if args.only:
        unknown = sorted(set(args.only) - {m["name"] for m in MUTATIONS})
        if unknown:
            print(f"mutate: unknown mutation(s): {', '.join(unknown)}", file=sys.stderr)
            return 2
        selected = [m for m in MUTATIONS if m["name"] in args.only]
    elif args.fast:
        selected = [m for m in MUTATIONS if m.get("fast")]

    bad = check_snippets(selected)
    if bad:
        for name, reason in bad:
            print(f"mutate: error: {name}: {reason}", file=sys.stderr)
        return 2
    if args.list:
        for m in selected:
            print(f"{m['name']:36s} {m['file']:45s} {'; '.join(_label(c) for c in m['tests'])}")
        return 0

    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pmpm-mutate-") as scratch:
        scratch = pathlib.Path(scratch)
        tree, cache = scratch / "tree", scratch / "numba-cache"
        _copy_tree(tree)
        env = _env(tree, cache)
        log = open(args.log or scratch / "mutate.log", "w")
        print(f"mutate: {len(selected)} mutation(s) in {tree}", flush=True)
        baseline_failed = []
        if not args.no_baseline:
            seen = []
            for m in selected:
                for cmd in m["tests"]:
                    if cmd not in seen:
                        seen.append(cmd)
            for cmd in seen:
                code, secs = _run(cmd, tree, env, log)
                print(f"  baseline {_label(cmd)}: {'passes' if code == 0 else f'FAILS ({code})'} ({secs:.0f} s)", flush=True)
                if code != 0:
                    baseline_failed.append(_label(cmd))
            if baseline_failed:
                print("mutate: error: killing tests fail without any mutation: " + "; ".join(baseline_failed),
                      file=sys.stderr)
                return 2
        rows = []
        for m in selected:
            path = tree / m["file"]
            pristine = ROOT / m["file"]
            text = path.read_text()
            path.write_text(text.replace(m["original"], m["replacement"], 1))
            try:
                codes, secs = [], 0.0
                for cmd in m["tests"]:
                    code, dt = _run(cmd, tree, env, log)
                    codes.append(code)
                    secs += dt
                    if code == 1 or code == "timeout":
                        break  # killed: the other commands need not run
            finally:
                shutil.copy2(pristine, path)  # the original text and time stamp
            status = _status(codes)
            rows.append({"name": m["name"], "file": m["file"], "tests": [_label(c) for c in m["tests"]],
                         "status": status, "codes": codes, "seconds": round(secs, 1)})
            print(f"  {m['name']}: {status} ({secs:.0f} s)", flush=True)
        log.close()

    width = max(len(r["name"]) for r in rows)
    print()
    print(f"| {'mutation':{width}s} | killed by | result | s |")
    print(f"| {'-' * width} | --- | --- | --- |")
    for r in rows:
        print(f"| {r['name']:{width}s} | {'; '.join(r['tests'])} | {r['status']} | {r['seconds']:.0f} |")
    killed = [r["name"] for r in rows if r["status"] == "killed"]
    summary = {"mutations": len(rows), "killed": len(killed),
               "survived": [r["name"] for r in rows if r["status"] == "survived"],
               "errors": [r["name"] for r in rows if r["status"] == "error"],
               "seconds": round(time.perf_counter() - t_start, 1)}
    print(json.dumps(summary))
    return 0 if len(killed) == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
