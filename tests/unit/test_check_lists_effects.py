"""``pmpm case.toml --check`` builds each run as it would start and lists the effects it switches
on (issue 36: the run header's ``effect on:`` lines come from the effects, and --check shows
them without running), and it applies the start's own checks (a body the grid cannot
place is bad input there, exit 2, as at the start of the run).

The expected lines are computed here from the scene's numbers, not read from pmpm: Rayleigh's
a0 = 2 xi w1 w2 / (w1 + w2) and a1 = 2 xi / (w1 + w2) (docs/scenes.md), the gravity vector.
Shown to fail: with the --check branch of pmpm/cli.py returning before it builds the runs (the
code before this test), the first test finds no ``effect on:`` line and the second exits 0.
"""
import math
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read()


def _check(tmp_path, text):
    (tmp_path / "bar.toml").write_text(text)
    r = subprocess.run([sys.executable, "-m", "pmpm.cli", "bar.toml", "--check"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=ROOT))
    return r


def test_check_lists_the_effects_the_scene_names(tmp_path):
    xi, T1, T2 = 0.05, 10.0, 2.5
    text = BAR.replace("[solver]", f"[loads]\ngravity = [0.0, -0.3]\ndamping = {{ ratio = {xi}, periods = [{T1}, {T2}] }}\n\n[solver]")
    r = _check(tmp_path, text)
    assert r.returncode == 0, r.stderr
    lines = [ln.strip()[len("effect on: "):] for ln in r.stdout.splitlines() if ln.strip().startswith("effect on: ")]
    w1, w2 = 2 * math.pi / T1, 2 * math.pi / T2
    a0, a1 = 2 * xi * w1 * w2 / (w1 + w2), 2 * xi / (w1 + w2)
    rayleigh = [ln for ln in lines if ln.startswith("Rayleigh damping")]
    assert len(rayleigh) == 1, lines
    assert f"a0 = {a0:.4g} 1/s" in rayleigh[0] and f"a1 = {a1:.4g} s" in rayleigh[0], rayleigh
    assert any("gravity" in ln and "-0.3" in ln for ln in lines), lines
    # the run's size line: the bar's 25 x 0.5 at 2 particles per cell direction on 0.5 cells
    assert "bar: 200 particles, grid 54 x 3 cells of 0.5, explicit integrator" in r.stdout, r.stdout
    # nothing written by a check
    assert sorted(os.listdir(tmp_path)) == ["bar.toml"]


def test_check_refuses_what_the_start_of_the_run_refuses(tmp_path):
    # a body longer than the grid: valid as TOML and in every key alone, refused when its
    # points are placed (which --check did not do before it built the runs: it said "valid")
    text = BAR.replace("upper = [25.0, 0.5]", "upper = [40.0, 0.5]").replace("cells = [54, 3]", "cells = [30, 3]")
    r = _check(tmp_path, text)
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pmpm: error: ") and "bodies[0]" in lines[0], r.stderr
    assert sorted(os.listdir(tmp_path)) == ["bar.toml"]
