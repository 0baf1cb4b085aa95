"""The benchmark commands run and say what they claim (their figures are not asserted: timings
belong in benchmarks, not tests)."""
import contextlib
import io
import json

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.core import kernels as K
from pmpm.benchmarks.block import YIELD_AFTER_STEPS, block_scene
from pmpm.cli import main
from pmpm.build import build_solver


def _run(argv):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    text = buf.getvalue()
    return code, text, json.loads(text.strip().splitlines()[-1])


def test_throughput_prints_rates_memory_bandwidth_and_phases():
    original = K.p2g
    code, text, summary = _run(["bench", "throughput", "--particles", "3000", "--steps", "2",
                                "--repeat", "1", "--phases"])
    assert code == 0
    assert summary["particle_steps_per_s"] > 0
    # peak RSS growth (bytes_per_particle) is not asserted: at 3000 particles the allocator may
    # serve the problem from pages an earlier test freed, so any value >= 0 is possible. The
    # arrays of the elastic block are exactly the core fields (pmpm/core/particles.py
    # CORE_FIELDS: id 8, x 16, x0 16, v 16, m 8, vol 8, stress 32, mat 4, body 4 = 112 bytes):
    # a field the scene does not need costs nothing (docs/effects.md)
    from pmpm.core.particles import CORE_FIELDS
    core = sum(np.dtype(dt).itemsize * int(np.prod(shape)) for shape, dt in CORE_FIELDS.values())
    assert summary["array_bytes_per_particle"] == core
    assert 0 < summary["fraction_of_bandwidth_floor"] < 1
    phases = summary["phases_ns"]
    for name in ("p2g", "g2p_velocity", "g2p_kinematics", "update_stress", "other"):
        assert phases[name] > 0, name
    assert "where the time goes" in text
    assert K.p2g is original  # the profiler put the kernels back


def test_effects_prints_every_effect():
    code, text, summary = _run(["bench", "effects", "--particles", "2000", "--steps", "1",
                                "--repeat", "1"])
    assert code == 0
    assert set(summary["effects"]) == {"none", "gravity", "force (step)", "damping", "Rayleigh damping (ratio)",
                                       "ground motion",
                                       "large rotations", "large rotations (Green-Naghdi)",
                                       "deformation gradient kept", "plasticity (smooth_vonmises)",
                                       "plasticity (bilinear_vonmises)", "fracture (bilinear_vonmises)",
                                       "fracture (smooth_vonmises)", "hyperelasticity (neo_hookean)"}
    # the figures: each overhead is the effect's time over the bare block's, less one, as printed
    effects = summary["effects"]
    base = effects["none"]["ns_per_particle_step"]
    for name, row in effects.items():
        assert row["ns_per_particle_step"] > 0, name
        assert row["overhead"] == pytest.approx(row["ns_per_particle_step"] / base - 1, rel=1e-12, abs=1e-12)
        line = next(ln for ln in text.splitlines() if ln.startswith(name + " "))
        assert line.split()[-2] == f"{100 * row['overhead']:.1f}%", line


def test_each_effect_scene_differs_from_the_bare_block_by_its_effect_only(tmp_path):
    """What `bench effects` times: each scene is the bare block with exactly the keys of its
    effect changed (else its overhead would be that of something else)."""
    from pmpm.benchmarks.throughput import _effect_scenes
    record = tmp_path / "record.txt"
    np.savetxt(record, np.column_stack([np.linspace(0, 1, 5), np.zeros(5)]))
    scenes = {k: v.to_dict() for k, v in _effect_scenes(2000, str(record)).items()}

    def flat(d, prefix=""):
        out = {}
        for k, v in d.items():
            out.update(flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
        return out

    bare = flat(scenes.pop("none"))
    changed = {name: sorted(k for k in set(bare) | set(flat(d)) if bare.get(k) != flat(d).get(k))
               for name, d in scenes.items()}
    expect = {"gravity": ["loads.gravity"], "force (step)": ["loads.forces"], "damping": ["loads.damping"],
              "ground motion": ["loads.ground_motion"], "large rotations": ["solver.large_rotations"],
              "large rotations (Green-Naghdi)": ["solver.large_rotations", "solver.objective_rate"],
              "deformation gradient kept": ["output.fields"]}
    for name, keys in expect.items():
        assert all(any(c.startswith(k) for k in keys) for c in changed[name]) and changed[name], (name, changed[name])
    for name in ("plasticity (smooth_vonmises)", "plasticity (bilinear_vonmises)", "hyperelasticity (neo_hookean)"):
        assert changed[name] and all(c.startswith("materials.") for c in changed[name]), (name, changed[name])
    # the fracture variants differ from their plasticity variant by the fracture table only
    for kind in ("bilinear_vonmises", "smooth_vonmises"):
        plastic = flat(scenes[f"plasticity ({kind})"])
        frac = flat(scenes[f"fracture ({kind})"])
        diff = sorted(k for k in set(plastic) | set(frac) if plastic.get(k) != frac.get(k))
        assert diff and all(k.startswith("materials.m.fracture.") for k in diff), (kind, diff)


@pytest.mark.parametrize("material", ["smooth_vonmises", "bilinear_vonmises"])
def test_the_plastic_block_yields_before_timing(material):
    """block_scene sets the yield stress to the von Mises stress of the block's shear after
    YIELD_AFTER_STEPS steps (Phi = sqrt(3) G gamma, uniform shear), and the benchmarks run that
    many steps before timing: when timing starts most particles are within 10% of the yield
    surface, and their increments fit one sub-step of the smooth model (0.1 of the yield
    strain). (The block's shear is not uniform: waves from the clamp; hence "most".)"""
    s = build_solver(block_scene(50000, material=material), MPI.COMM_SELF)
    for _ in range(YIELD_AFTER_STEPS):
        s.step()
    sy = s.materials[0].yield_stress
    t = s.particles["stress"] - s.particles["back_stress"]
    phi = np.sqrt(t[:, 0] ** 2 - t[:, 0] * t[:, 1] + t[:, 1] ** 2 + 3 * t[:, 2] ** 2)
    assert np.mean(phi > 0.9 * sy) > 0.6
    assert np.mean(np.abs(s._de).max(axis=1) <= 0.1 * sy / s.materials[0].E) > 0.99


def test_throughput_takes_neo_hookean_and_track_F():
    """--material neo_hookean keeps F (the model needs it); --track-F keeps it for the elastic
    block, which otherwise does not: the summary says which."""
    code, _, summary = _run(["bench", "throughput", "--particles", "2000", "--steps", "1",
                             "--repeat", "1", "--material", "neo_hookean"])
    assert code == 0 and summary["material"] == "neo_hookean" and summary["track_F"] is True
    code, _, plain = _run(["bench", "throughput", "--particles", "2000", "--steps", "1", "--repeat", "1"])
    code_f, _, forced = _run(["bench", "throughput", "--particles", "2000", "--steps", "1",
                              "--repeat", "1", "--track-F"])
    assert (code, code_f, plain["track_F"], forced["track_F"]) == (0, 0, False, True)
    # F (40 B) and vol0 (8 B) read and F written by the kinematics: 88 B more per particle-step
    assert forced["bytes_moved_per_particle_step"] - plain["bytes_moved_per_particle_step"] == \
        pytest.approx(88.0, abs=1.0)
