"""``pmpm bench profile``: a scene's step phase by phase with its output, against the block."""
import contextlib
import io
import json
import os

from pmpm.cli import main

SCENE = """
title = "profile test"
particles_per_cell = 2
[grid]
origin = [0.0, 0.0]
cell_size = 0.05
cells = [16, 12]
[materials.steel]
type = "linear_elastic"
E = 200e9
nu = 0.3
density = 7850.0
[[bodies]]
shape = "rectangle"
material = "steel"
lower = [0.1, 0.0]
upper = [0.5, 0.4]
velocity = ["1.0 * y", 0.0]
[[boundary]]
type = "fixed"
lower = [0.0, 0.0]
upper = [0.8, 0.0]
[solver]
end_time = 1.0
[output]
interval = 2e-5
history_interval = 5e-6
fields = ["x", "v", "stress"]
[[output.track]]
name = "top"
point = [0.3, 0.4]
"""


def test_profile_prints_phases_of_the_step_and_the_output(tmp_path, monkeypatch):
    scene = tmp_path / "small.toml"
    scene.write_text(SCENE)
    monkeypatch.chdir(tmp_path)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["bench", "profile", str(scene), "--rounds", "2",
                     "--particles", "2000", "--block-steps", "4", "--block-chunks", "3"])
    assert code == 0
    out = json.loads(buf.getvalue().strip().splitlines()[-1])
    phases = out["phases_ns"]
    for name in ("reset_grid", "particles_to_grid", "update_grid", "grid_to_particles", "update_strain",
                 "update_stress", "record_history", "write_frame", "snapshot", "step: other", "loop: other"):
        assert name in phases, name
    assert phases["write_frame"]["block_ns"] == 0 and phases["particles_to_grid"]["block_ns"] > 0
    # the default run is one frame interval of the scene: about interval / dt steps
    assert out["steps"] >= 10 and len(out["ratio_per_round"]) == 2 and out["ratio"] > 0
    # the phases (wall) add up to no more than the run's whole wall time per particle-step
    assert sum(v["case_ns"] for v in phases.values()) > 0
    # it wrote nothing where it ran: its output went into a temporary folder, removed
    assert sorted(os.listdir(tmp_path)) == ["small.toml"]


def test_profile_refuses_a_bad_scene_or_variant_in_one_line(tmp_path, capsys):
    scene = tmp_path / "small.toml"
    scene.write_text(SCENE)
    assert main(["bench", "profile", str(tmp_path / "missing.toml")]) == 2
    assert main(["bench", "profile", str(scene), "--variant", "nosuch"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("pmpm: error: bench profile: ") for line in err)
