"""CI's share of the mutation testing (docs/testing.md): every snippet of the mutation list is
still in the source (so the list cannot rot silently), and the fast subset of mutations is
killed: three planted bugs whose killing tests take seconds, one kernel (the volume update), one
of the decomposition (the halo accumulate, under mpirun -n 2) and one of the scene set-up (the
I-section thickness rule). About 25 s; the whole set is ``python tests/mutation/mutate.py``."""
import json
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "mutation"))
import mutate  # noqa: E402


def test_every_mutation_snippet_is_found_once_in_the_source():
    assert mutate.check_snippets(mutate.MUTATIONS) == []


def test_the_list_covers_the_issue():
    names = {m["name"] for m in mutate.MUTATIONS}
    assert len(names) == len(mutate.MUTATIONS) >= 15
    for must in ("jaumann_spin_sign", "musl_strain_from_updated_velocity", "volume_update_without_y_strain",
                 "no_volume_update", "internal_force_sign", "hardening_term", "halo_accumulate_overwrites",
                 "halo_fill_adds", "essential_bc_ignored", "flip_pic_blend_swapped", "cfl_without_particle_speed",
                 "mass_cutoff_ignored", "cubic_gradient_block", "plane_stress_thickness_unscaled",
                 "objective_rate_sign", "musl_second_exchange_dropped"):
        assert must in names
    assert all(m["tests"] and m["original"] != m["replacement"] for m in mutate.MUTATIONS)
    assert sum(1 for m in mutate.MUTATIONS if m.get("fast")) == 3


def test_a_snippet_that_moved_stops_the_driver(tmp_path):
    """The driver's own guard: a snippet not in its file is an error (exit 2), not a survivor."""
    bad = [dict(mutate.MUTATIONS[0], original="this text is in no source file")]
    assert mutate.check_snippets(bad) == [(bad[0]["name"], f"snippet found 0 times in {bad[0]['file']} "
                                                          "(must be exactly once)")]


def test_fast_mutations_are_killed():
    # no baseline run: the killing tests pass unmutated in this same suite
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "mutation" / "mutate.py"), "--fast", "--no-baseline"],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=900)
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    assert proc.returncode == 0 and summary["killed"] == summary["mutations"] == 3, proc.stdout
