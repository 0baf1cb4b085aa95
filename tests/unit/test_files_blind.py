"""Files pmpm writes and reads (issue 38): a damped run restarted from its checkpoint ends with
the uninterrupted run's energies, the checkpoint rotation keeps the newer of its two files, an
HDF5 file of another scene is never overwritten, and a results file whose series or frame
fields are inconsistent is refused.

All through the command line in-process (pmpm.cli.main) and pmpm.load_results, on the fixed-free
bar of cases/bar.toml shortened to 1 s (40 steps) with Rayleigh damping.

How each test was shown to fail on its bug (planted, watched fail, restored):
* ``mutate.py --only restart_viscous_work_wrong_name`` (the viscous work read back from the
  checkpoint under a name it was not written with: restarted from zero):
  ``test_a_restarted_damped_run_ends_with_the_uninterrupted_energies`` fails;
* ``mutate.py --only checkpoint_overwrites_the_newer``: ``test_the_next_checkpoint_replaces_the_older_file``
  fails;
* ``mutate.py --only owner_record_not_compared``: ``test_a_file_of_another_scene_is_never_overwritten``
  fails;
* ``mutate.py --only series_lengths_not_compared``, ``--only frame_particle_count_not_checked``
  and ``--only history_rows_not_checked``: the matching case of
  ``test_an_inconsistent_results_file_is_refused`` fails (the product refused all three already:
  no fix was needed in pmpm/io/validate.py).
"""
import contextlib
import hashlib
import io
import os
import shutil

import h5py
import numpy as np
import pytest

import pmpm
from pmpm.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read()
END, CKPT = 1.0, 0.3
DAMPING = "\n[loads]\ndamping = {ratio = 0.05, periods = [10.0, 2.0]}\n"


def _case(folder, name="bar.toml", max_steps=None):
    text = BAR.replace("end_time = 10.0", f"end_time = {END}" + (f"\nmax_steps = {max_steps}" if max_steps else ""))
    text = text.replace("interval = 0.5", f"interval = 0.5\ncheckpoint_interval = {CKPT}")
    text = text.replace("[solver]", DAMPING + "\n[solver]")
    assert "checkpoint_interval" in text and "max_steps" in text or not max_steps
    (folder / name).write_text(text)
    return name


def _main(argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main(argv)
    return code, out.getvalue()


def _sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@pytest.fixture(scope="module")
def full(tmp_path_factory):
    """The uninterrupted damped run (its folder)."""
    folder = tmp_path_factory.mktemp("full")
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        code, text = _main([_case(folder), "--no-plots", "-q"])
    finally:
        os.chdir(cwd)
    assert code == 0, text
    return folder


def _energies(path):
    with h5py.File(path, "r") as f:
        return {k: f["energies"][k][:] for k in f["energies"]}


def test_a_restarted_damped_run_ends_with_the_uninterrupted_energies(full, tmp_path, monkeypatch):
    """Stopped after 17 steps (max_steps, which ends a run with a checkpoint), then continued with
    --restart to the end time: every energy row, the viscous work of Rayleigh damping and the mass
    part's work among them, equals the uninterrupted run's to round-off (the restart reads the
    state back exactly; 1e-12 of the initial energy, the bar's rho L t v0^2 / 4)."""
    monkeypatch.chdir(tmp_path)
    code, text = _main([_case(tmp_path, max_steps=17), "--no-plots", "-q"])
    assert code == 0, text
    code, text = _main([_case(tmp_path), "--restart", "bar_results/bar.h5", "--no-plots"])
    assert code == 0, text
    assert "restarted from" in text
    a, b = _energies(full / "bar_results" / "bar.h5"), _energies(tmp_path / "bar_results" / "bar.h5")
    e0 = 1.0 * 25.0 * 0.5 * 0.1 ** 2 / 4
    assert a["viscous_damping_work"][-1] > 1e-3 * e0 and a["damping_work"][-1] > 1e-3 * e0
    np.testing.assert_allclose(b["time"], a["time"], rtol=0, atol=1e-12)
    for name in ("kinetic", "strain_energy", "damping_work", "viscous_damping_work", "internal_work",
                 "external_work", "total", "numerical_loss"):
        np.testing.assert_allclose(b[name], a[name], rtol=0, atol=1e-12 * e0, err_msg=name)


def test_the_next_checkpoint_replaces_the_older_file(full):
    """Checkpoints every 0.3 s and one at the end (1 s): four writes into two files, each
    replacing the older, so the files hold the last two states: the end and the one written
    at or just after 0.9 s (never the first ones). A crash while the next one is written then
    loses at most one interval."""
    times = []
    for k in (0, 1):
        with h5py.File(full / "bar_results" / f"bar.ckpt{k}.h5", "r") as f:
            assert bool(f.attrs["complete"])
            times.append(float(f.attrs["time"]))
    older, newer = sorted(times)
    assert newer == pytest.approx(END, abs=1e-12)
    assert 3 * CKPT - 1e-12 <= older < END


@pytest.mark.parametrize("source,target,record_only", [("bar.h5", "b.h5", False), ("bar.h5", "b.h5", True),
                                                       ("bar.ckpt0.h5", "b.ckpt0.h5", True)])
def test_a_file_of_another_scene_is_never_overwritten(full, tmp_path, monkeypatch, source, target, record_only):
    """Scene b.toml's results or checkpoint name holds a file scene bar.toml wrote: a fresh run of
    b refuses with one line naming the file, exit 2, and the file keeps its bytes. Two guards
    see it: the run's check of the scene file recorded in the file (pmpm/runner.py) and the owner
    record every pmpm HDF5 file carries (pmpm/io/ownership.py, ``pmpm_owner``). ``record_only``:
    the file's scene-file record is gone (``scene_file`` of a results file, the ``attrs`` table
    of a checkpoint), so only its owner record, "bar", tells it is another scene's."""
    monkeypatch.chdir(tmp_path)
    name = _case(tmp_path, name="b.toml")
    os.makedirs("b_results")
    path = os.path.join("b_results", target)
    shutil.copy(full / "bar_results" / source, path)
    if record_only:
        with h5py.File(path, "r+") as f:
            assert f.attrs["pmpm_owner"] == "bar"
            del f.attrs["scene_file" if target == "b.h5" else "attrs"]
    before = _sha(path)
    code, text = _main([name, "--no-plots", "-q"])
    assert code == 2, text
    lines = [ln for ln in text.splitlines() if ln.startswith("pmpm: error:")]
    assert len(lines) == 1 and target in lines[0], text
    if record_only:
        assert "'bar'" in lines[0], text
    assert _sha(path) == before


def _damaged(src, folder, how):
    path = folder / f"{how}.h5"
    shutil.copy(src, path)
    with h5py.File(path, "r+") as f:
        if how == "energy_column_short":
            kin = f["energies/kinetic"][:-1]
            del f["energies/kinetic"]
            f["energies/kinetic"] = kin
        elif how == "history_rows_short":
            rows = f["history/middle"][:-1]
            attrs = dict(f["history/middle"].attrs)
            del f["history/middle"]
            f["history/middle"] = rows
            f["history/middle"].attrs.update(attrs)
        elif how == "frame_particles_short":
            stress = f["frames/stress"][:, :-1]
            del f["frames/stress"]
            f["frames/stress"] = stress
    return path


@pytest.mark.parametrize("how,reason", [("energy_column_short", "different lengths"),
                                        ("history_rows_short", "/history/middle has shape"),
                                        ("frame_particles_short", "/frames/stress has shape")])
def test_an_inconsistent_results_file_is_refused(full, tmp_path, how, reason):
    """One energy column a row short, one track's history a row short of the time column, the
    stress frames with one particle fewer than the file's n_total: pmpm.load_results refuses
    each with a ValueError naming the file and the dataset, before anything is read."""
    path = _damaged(full / "bar_results" / "bar.h5", tmp_path, how)
    with pytest.raises(ValueError) as info:
        pmpm.load_results(path)
    assert str(path) in str(info.value) and reason in str(info.value), str(info.value)
    # the command line says the same in one line, exit 2
    code, text = _main(["plot", str(path), "--outdir", str(tmp_path / "plots")])
    assert code == 2 and reason in text, text
