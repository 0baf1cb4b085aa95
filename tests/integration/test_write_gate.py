"""Every path pmpm writes goes through one gate (pmpm.io.ownership, issue 35 deliverable 1).

Through the real command line, as a user or an attacker would set the output folder up:

- the XDMF sidecar's temporary: a user's ``bar.xdmf.tmp``, a link of that name to a file outside
  the folder, a dangling link: none is opened, written or removed (the temporary is fresh and
  created exclusively);
- ``pmpm export``: ``<case>_vtu`` a link to a folder outside, or a user's folder: refused, nothing
  written there;
- ``pmpm bench accuracy --from-csv ... --outdir DIR``: a user's ``accuracy.md``, a link at
  ``accuracy.png``: refused before anything is written, the files intact;
- ``pmpm expand case.toml -o FILE`` where FILE is the scene under another name (a symbolic link,
  a hard link, a path through a linked folder): refused, the scene intact.

Each was shown to fail before the fix (the sidecar's temporary was ``open(<case>.xdmf.tmp, "w")``,
export followed the link, accuracy used a plain open, expand compared ``abspath`` only): the user's
files were overwritten, removed or written outside the folder and the command exited 0.
"""
import csv
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = open(os.path.join(ROOT, "cases", "bar.toml")).read().replace("end_time = 10.0", "end_time = 1.0")
PORTAL = os.path.join(ROOT, "cases", "portal_frame.toml")


def _pmpm(cwd, *args, timeout=600):
    env = dict(os.environ, PYTHONPATH=ROOT)
    return subprocess.run([sys.executable, "-m", "pmpm.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def _one_line(r, *words):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pmpm: error: "), r.stderr
    for w in words:
        assert w in lines[0], lines[0]


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    """One short run of the bar (results in bar_results/), the user's files laid out first."""
    tmp = tmp_path_factory.mktemp("gate")
    (tmp / "bar.toml").write_text(BAR)
    out = tmp / "bar_results"
    out.mkdir()
    (tmp / "outside").mkdir()
    (tmp / "outside" / "precious.txt").write_text("the user's\n")
    # a user's file at the sidecar's old temporary name (links to it: the test below)
    (out / "bar.xdmf.tmp").write_text("mine\n")
    r = _pmpm(tmp, "bar.toml", "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
    return tmp, out


def test_xdmf_temporary_never_opens_a_users_file(bar_run):
    tmp, out = bar_run
    assert (out / "bar.xdmf.tmp").read_text() == "mine\n"  # was overwritten, then renamed away
    assert (out / "bar.xdmf").read_text().splitlines()[1].startswith("<!-- pmpm sidecar of")
    assert not [n for n in os.listdir(out) if n.endswith(".pmpm-tmp")]  # no temporary left


@pytest.mark.parametrize("dangling", [False, True])
def test_xdmf_temporary_never_written_through_a_link(tmp_path, dangling):
    (tmp_path / "bar.toml").write_text(BAR)
    out = tmp_path / "bar_results"
    out.mkdir()
    outside = tmp_path / "outside.txt"
    if not dangling:
        outside.write_text("keep\n")
    os.symlink(outside, out / "bar.xdmf.tmp")
    r = _pmpm(tmp_path, "bar.toml", "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
    assert os.path.islink(out / "bar.xdmf.tmp")
    if dangling:
        assert not outside.exists()  # the run created a file outside the folder
    else:
        assert outside.read_text() == "keep\n"


def test_export_refuses_a_linked_vtu_folder(bar_run):
    tmp, out = bar_run
    target = tmp / "elsewhere"
    target.mkdir()
    os.symlink(target, out / "bar_vtu")
    try:
        r = _pmpm(tmp, "export", str(out / "bar.h5"))
        _one_line(r, "bar_vtu", "link")
        assert os.listdir(target) == []
    finally:
        os.remove(out / "bar_vtu")


def test_export_refuses_a_folder_pmpm_did_not_make(bar_run):
    tmp, out = bar_run
    mine = out / "bar_vtu"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine\n")
    try:
        r = _pmpm(tmp, "export", str(out / "bar.h5"))
        _one_line(r, "bar_vtu")
        assert sorted(os.listdir(mine)) == ["notes.txt"]
    finally:
        os.remove(mine / "notes.txt")
        os.rmdir(mine)
    r = _pmpm(tmp, "export", str(out / "bar.h5"))  # a folder pmpm makes itself is fine, twice
    assert r.returncode == 0, r.stderr
    r = _pmpm(tmp, "export", str(out / "bar.h5"))
    assert r.returncode == 0, r.stderr


def _accuracy_csv(path):
    """A small accuracy.csv of the sweep's columns: two bar runs (no frame: no reference)."""
    from studies.accuracy import CSV_COLUMNS
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
        w.writeheader()
        for h, err in ((1.0, 4e-3), (0.5, 1e-3)):
            w.writerow({"problem": "bar", "shape": "cubic", "ppc": 2, "scheme": "musl", "cell_size": h,
                        "particles": int(50 / h), "steps": 100, "wall_s": 1.0 / h, "cpu_s": 1.0 / h,
                        "error": err, "peak_mm": "", "t_peak_s": "", "peak_track_mm": "", "pareto": "",
                        "status": "ok"})


def test_accuracy_from_csv_refuses_users_files_and_links(tmp_path):
    src = tmp_path / "accuracy.csv"
    _accuracy_csv(src)
    outdir = tmp_path / "report"
    outdir.mkdir()
    (outdir / "accuracy.md").write_text("my notes\n")
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(outdir))
    _one_line(r, "accuracy.md")
    assert (outdir / "accuracy.md").read_text() == "my notes\n"
    assert sorted(os.listdir(outdir)) == ["accuracy.md"]  # nothing else written first
    os.remove(outdir / "accuracy.md")
    outside = tmp_path / "outside.png"
    outside.write_bytes(b"keep")
    os.symlink(outside, outdir / "accuracy.png")
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(outdir))
    _one_line(r, "accuracy.png", "link")
    assert outside.read_bytes() == b"keep"
    os.remove(outdir / "accuracy.png")
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(outdir))
    assert r.returncode == 0, r.stderr
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(outdir))
    assert r.returncode == 0, r.stderr  # its own files, rewritten
    # redone in place: the CSV it reads is never rewritten
    before = src.read_bytes()
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert src.read_bytes() == before


@pytest.mark.parametrize("how", ["symlink", "hardlink", "linked_folder"])
def test_expand_never_overwrites_its_scene(tmp_path, how):
    scene = tmp_path / "frame.toml"
    scene.write_text(open(PORTAL).read())
    before = scene.read_bytes()
    if how == "symlink":
        os.symlink(scene, tmp_path / "other.toml")
        target = "other.toml"
    elif how == "hardlink":
        os.link(scene, tmp_path / "other.toml")
        target = "other.toml"
    else:
        os.symlink(tmp_path, tmp_path / "via")
        target = os.path.join("via", "frame.toml")
    r = _pmpm(tmp_path, "expand", "frame.toml", "-o", target)
    _one_line(r, target)
    assert scene.read_bytes() == before


def test_expand_refuses_a_fifo_and_writes_atomically(tmp_path):
    scene = tmp_path / "frame.toml"
    scene.write_text(open(PORTAL).read())
    os.mkfifo(tmp_path / "pipe.toml")
    r = _pmpm(tmp_path, "expand", "frame.toml", "-o", "pipe.toml", timeout=60)  # hung before
    _one_line(r, "pipe.toml")
    (tmp_path / "old.toml").write_text("old\n")
    r = _pmpm(tmp_path, "expand", "frame.toml", "-o", "old.toml")
    assert r.returncode == 0, r.stderr
    assert "[[bodies]]" in (tmp_path / "old.toml").read_text()
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".pmpm-tmp")]


# -- one line, exit 2, before anything is written (issue 35: these printed tracebacks) ----------

@pytest.mark.parametrize("kind", ["missing_column", "not_a_number", "binary", "dev_zero", "folder",
                                  "missing", "fifo", "outdir_is_a_file"])
def test_accuracy_from_csv_bad_inputs_are_one_line(tmp_path, kind):
    src = tmp_path / "accuracy.csv"
    _accuracy_csv(src)
    outdir = tmp_path / "report"
    text = src.read_text()
    if kind == "missing_column":
        src.write_text(text.replace("cell_size,", "", 1))
    elif kind == "not_a_number":
        src.write_text(text.replace(",0.5,", ",half,", 1))
    elif kind == "binary":
        src.write_bytes(b"\x00\x01\xff\xfe" * 100)
    elif kind == "dev_zero":
        src = "/dev/zero"
    elif kind == "folder":
        src = tmp_path
    elif kind == "missing":
        src = tmp_path / "nothing.csv"
    elif kind == "fifo":
        os.remove(src)
        os.mkfifo(src)
    else:
        outdir.write_text("a file\n")
    r = _pmpm(tmp_path, "bench", "accuracy", "--from-csv", str(src), "--outdir", str(outdir), timeout=120)
    _one_line(r)
    assert kind == "outdir_is_a_file" or not outdir.exists()  # nothing written


@pytest.mark.parametrize("args", [["--case", "bad.toml"], ["--variant", "no_such_variant"]])
def test_bench_ranks_bad_scene_or_variant_is_one_line(tmp_path, args):
    (tmp_path / "bad.toml").write_text("x = \n")
    r = _pmpm(tmp_path, "bench", "ranks", *args, timeout=120)
    _one_line(r)


def test_a_users_capacity_file_stops_a_pushover_before_it_writes(tmp_path):
    import shutil
    shutil.copy(os.path.join(ROOT, "cases", "portal_pushover.toml"), tmp_path)
    out = tmp_path / "portal_pushover_results"
    out.mkdir()
    (out / "portal_pushover_capacity.png").write_bytes(b"the user's plot")
    r = _pmpm(tmp_path, "portal_pushover.toml", "-q", timeout=300)
    _one_line(r, "portal_pushover_capacity.png")
    assert os.listdir(out) == ["portal_pushover_capacity.png"]  # the run wrote nothing


@pytest.mark.parametrize("name", ["bar.h5", "bar.ckpt1.h5"])
def test_a_fifo_at_an_output_name_is_refused_without_hanging(tmp_path, name):
    (tmp_path / "bar.toml").write_text(BAR)
    out = tmp_path / "bar_results"
    out.mkdir()
    os.mkfifo(out / name)
    r = _pmpm(tmp_path, "bar.toml", "--no-plots", "-q", timeout=120)  # hung before: h5py opened it
    _one_line(r, name)
    assert os.listdir(out) == [name]


def test_two_runs_of_the_same_names_into_one_folder(tmp_path):
    """The second of two runs started together is refused by the first's claim, in one line,
    and the first runs to its end (issue 35, deliverable 3). Before the claim, the second
    exited 2 only after it had written files."""
    import time
    # the bar at 0.125 m cells to 10 s: long enough (thousands of steps) to still be running
    (tmp_path / "bar.toml").write_text(BAR.replace("end_time = 1.0", "end_time = 10.0")
                                       .replace("cell_size = 0.5", "cell_size = 0.125")
                                       .replace("cells = [54, 3]", "cells = [216, 12]"))
    env = dict(os.environ, PYTHONPATH=ROOT)
    first = subprocess.Popen([sys.executable, "-m", "pmpm.cli", "bar.toml", "--no-plots", "-q"], cwd=tmp_path,
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    claim = tmp_path / "bar_results" / ".bar.pmpm-claim"
    deadline = time.time() + 120
    while not claim.exists() and first.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert claim.exists(), first.communicate()
    r = _pmpm(tmp_path, "bar.toml", "--no-plots", "-q")
    assert first.poll() is None, "the first run ended before the second started: make it longer"
    _one_line(r, ".bar.pmpm-claim", "another pmpm run")
    out, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    assert not claim.exists()  # released at the end of the run
