"""A restart must continue the same run: a checkpoint of another material model (a plastic
model's back stress missing from an elastic run's checkpoint), or an output file whose frames
have other fields (the plastic strain tensor asked for only on restart), is refused with one
line naming the key that differs and exit code 2, before anything is written (pmpm/runner.py;
the scene record in each checkpoint, pmpm/scene/fingerprint.py)."""
import contextlib
import io
import os

from pmpm.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read()
PLASTIC = '''[materials.bar]
type = "smooth_vonmises"
E = 100.0
nu = 0.0
density = 1.0
yield_stress = 0.05
hardening = 0.05
'''


def _case(tmp_path, name, end, fields, plastic=True):
    text = BAR.replace("end_time = 10.0", f"end_time = {end}").replace(
        "interval = 0.5", "interval = 0.5\ncheckpoint_interval = 1.0").replace(
        'fields = ["x", "v", "stress", "strain"]', f"fields = {fields}")
    if plastic:
        text = text.replace('[materials.bar]\ntype = "linear_elastic"\nE = 100.0\nnu = 0.0\ndensity = 1.0\n', PLASTIC)
        assert "smooth_vonmises" in text
    (tmp_path / name).write_text(text)
    return str(tmp_path / name)


def _main(argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main(argv)
    return code, out.getvalue()


def test_other_output_fields_on_restart_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    first = _case(tmp_path, "bar.toml", 2.0, '["x", "v", "stress"]')
    assert _main([first, "--no-plots"])[0] == 0
    before = os.path.getsize("bar_results/bar.h5")
    again = _case(tmp_path, "bar.toml", 3.0, '["x", "v", "stress", "eps_p"]')
    code, text = _main([again, "--restart", "bar_results/bar.h5", "--no-plots"])
    assert code == 2
    # refused by the scene record of the checkpoint, naming the key that changed
    assert "output.fields: differs from the scene of the checkpoint" in text, text
    assert os.path.getsize("bar_results/bar.h5") == before


def test_a_field_the_step_reads_refuses_the_restart(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    elastic = _case(tmp_path, "bar.toml", 2.0, '["x", "v", "stress"]', plastic=False)
    assert _main([elastic, "--no-plots"])[0] == 0
    plastic = _case(tmp_path, "bar.toml", 3.0, '["x", "v", "stress"]')
    code, text = _main([plastic, "--restart", "bar_results/bar.h5", "--no-plots"])
    assert code == 2
    # refused by the scene record of the checkpoint, naming the first material key that differs
    assert "materials.bar." in text and "differs from the scene of the checkpoint" in text, text
