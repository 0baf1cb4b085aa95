"""Every write to a full disk ends in one line, with the earlier files intact (issue 35,
deliverable 6): the results of a run, a checkpoint of a restart, ``pmpm plot``'s PNGs and
``pmpm expand -o``.

The disk is a real one: a tmpfs of 4 MB mounted for this module (the test runs as root in CI,
where mounting is allowed; without the right to mount it fails, it does not skip), filled by a
file to within a few kB of its end, so every write meets ENOSPC as on a full partition. Each case
checks the exit code, exactly one line ``pmpm: error: ...``, and the SHA-256 of every file that
was there before (a plot or expand over an earlier file keeps it whole: they write a temporary and
rename; a restart's checkpoint goes to a temporary too, so both earlier checkpoints stay).

Shown to fail (scratch edits, restored): with pmpm.io.ownership.replace_into writing in place
instead of into a temporary, the expand case lost the earlier out.toml; with Writes.abort not
putting back the old copies it had set aside, the plot case lost the earlier PNGs.
A file size limit (``ulimit -f``, RLIMIT_FSIZE) is the other way a write is cut short: set
before MPI_Init it stops Open MPI's PMIx (nothing pmpm can do), set after it a write past it
fails with EFBIG inside HDF5, which then crashed closing the file (a segmentation fault). pmpm
refuses such a write before it starts, as for a full disk; the last test sets the limit after
MPI_Init and was shown to fail (exit -11, libhdf5's H5F__close_cb) before
pmpm.runner._over_file_size_limit existed.
"""
import hashlib
import os
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = (open(os.path.join(ROOT, "cases", "bar.toml")).read().replace("end_time = 10.0", "end_time = 2.0{max_steps}")
       .replace("interval = 0.5\n", "interval = 0.5\ncheckpoint_interval = 0.3\n", 1))
FRAME = os.path.join(ROOT, "cases", "frame_3storey.toml")
#: bytes left free on the filled disk: less than any file the cases write (the smallest, a
#: checkpoint of the bar, is 37 kB; the expanded frame scene is larger than 8 kB too)
LEFT = 4096


def _pmpm(cwd, *args, timeout=300):
    env = dict(os.environ, PYTHONPATH=ROOT)
    return subprocess.run([sys.executable, "-m", "pmpm.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _one_line(r):
    assert r.returncode in (2, 4), (r.returncode, r.stdout[-500:], r.stderr[-3000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pmpm: error: "), r.stderr[-3000:]
    return lines[0]


def _sums(folder):
    out = {}
    for base, _dirs, files in os.walk(folder):
        for name in files:
            if name == "filler":
                continue
            path = os.path.join(base, name)
            with open(path, "rb") as fh:
                out[os.path.relpath(path, folder)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def _fill(folder):
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(os.path.join(folder, "filler"), "wb") as fh:
        fh.write(b"\0" * max(0, free - LEFT))
    st = os.statvfs(folder)
    assert st.f_bavail * st.f_frsize <= LEFT + st.f_frsize


@pytest.fixture
def disk(tmp_path):
    """A fresh 4 MB tmpfs (unmounted after the test)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mount)],
                       capture_output=True, text=True)
    assert r.returncode == 0, f"cannot mount a tmpfs (run as root): {r.stderr}"
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def test_a_run_onto_a_full_disk_says_one_line(disk):
    (disk / "bar.toml").write_text(BAR.format(max_steps=""))
    (disk / "bar_results").mkdir()
    (disk / "bar_results" / "notes.txt").write_text("the user's\n")
    _fill(disk)
    before = _sums(disk)
    line = _one_line(_pmpm(disk, "bar.toml", "-q"))
    assert "No space left on device" in line, line
    after = _sums(disk)
    assert {k: after.get(k) for k in before} == before


def test_a_restart_whose_checkpoint_meets_a_full_disk_keeps_both_checkpoints(disk):
    (disk / "bar.toml").write_text(BAR.format(max_steps="\nmax_steps = 40"))  # t ~ 1 s, 3 checkpoints
    r = _pmpm(disk, "bar.toml", "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
    (disk / "bar.toml").write_text(BAR.format(max_steps=""))
    _fill(disk)
    out = disk / "bar_results"
    before = {k: v for k, v in _sums(disk).items() if ".ckpt" in k}
    assert len(before) == 2
    line = _one_line(_pmpm(disk, "bar.toml", "--restart", "bar_results/bar.h5", "--no-plots", "-q"))
    assert "No space left on device" in line, line
    assert {k: v for k, v in _sums(disk).items() if ".ckpt" in k} == before
    assert not [n for n in os.listdir(out) if n.endswith(".pmpm-tmp")]  # the temporary removed
    # the results file still reads up to the restart
    from pmpm.io import check_results_file
    check_results_file(str(out / "bar.h5"))


def test_plots_onto_a_full_disk_keep_the_earlier_plots(disk):
    (disk / "bar.toml").write_text(BAR.format(max_steps=""))
    r = _pmpm(disk, "bar.toml", "-q")  # the run's plots: the earlier files
    assert r.returncode == 0, r.stderr
    pngs = [n for n in os.listdir(disk / "bar_results") if n.endswith(".png")]
    assert pngs
    _fill(disk)
    before = _sums(disk)
    line = _one_line(_pmpm(disk, "plot", "bar_results/bar.h5"))
    assert "No space left on device" in line, line
    assert _sums(disk) == before


def test_expand_onto_a_full_disk_keeps_the_earlier_file(disk):
    shutil.copy(FRAME, disk / "frame.toml")
    r = _pmpm(disk, "expand", "frame.toml", "--variant", "elastic", "-o", "out.toml")
    assert r.returncode == 0, r.stderr
    assert os.path.getsize(disk / "out.toml") > 2 * LEFT
    (disk / "out.toml").write_text("# the user's earlier expansion\n")
    _fill(disk)
    before = _sums(disk)
    line = _one_line(_pmpm(disk, "expand", "frame.toml", "--variant", "elastic", "-o", "out.toml"))
    assert "out.toml" in line and "No space left on device" in line, line
    assert _sums(disk) == before


@pytest.mark.parametrize("limit", [200_000, 330_000])
def test_a_run_past_the_file_size_limit_says_one_line(tmp_path, limit):
    # the bar's results file grows to 292 kB (single-precision frames); the limits cut it after
    # its first frame (which allocates the tables' first chunks, about 240 kB) and near its end
    (tmp_path / "bar.toml").write_text(BAR.format(max_steps=""))
    code = ("import resource, sys\n"
            "from mpi4py import MPI  # MPI_Init first: PMIx itself needs larger files\n"
            f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))\n"
            "from pmpm.cli import main\n"
            "sys.exit(main(['bar.toml', '-q', '--no-plots']))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300, env=dict(os.environ, PYTHONPATH=ROOT))
    line = _one_line(r)
    assert "File too large" in line and "bar.h5" in line, line
    out = tmp_path / "bar_results" / "bar.h5"
    assert 0 < os.path.getsize(out) <= limit
    # the frames written before the refused one still read
    import h5py
    from pmpm.io import check_results_file
    check_results_file(str(out))
    with h5py.File(out, "r") as f:
        assert len(f["frames"]) >= 1
