"""The write gate itself (pmpm.io.ownership.check_target, replace_into, the manifest's schema)
and the checkpoint written whole with its ownership record (pmpm.io.checkpoint).

Shown to fail before the fix: without check_target a FIFO, a link or a hard link of the scene
passed ``check_owned``'s callers that write new files; a manifest nested 5000 deep raised
RecursionError (a traceback); a checkpoint cut short was left at its name with no
``pmpm_owner`` record (the restart then refused pmpm's own file).
"""
import errno
import os

import numpy as np
import pytest
from mpi4py import MPI

from pmpm.io import ownership
from pmpm.io.ownership import ForeignFileError


def test_gate_refuses_links_special_files_and_the_scene(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "real").mkdir()
    os.symlink(tmp_path / "real", out / "sub")
    with pytest.raises(ForeignFileError, match="sub: is a symbolic link"):
        ownership.check_target(str(out / "sub" / "a.vtu"), root=str(out))
    os.symlink(tmp_path / "nowhere", out / "dangling.png")
    with pytest.raises(ForeignFileError, match="dangling.png: is a symbolic link"):
        ownership.check_target(str(out / "dangling.png"))
    os.mkfifo(out / "fifo.csv")
    with pytest.raises(ForeignFileError, match="fifo.csv: is a special file"):
        ownership.check_target(str(out / "fifo.csv"))
    scene = tmp_path / "case.toml"
    scene.write_text("x = 1\n")
    os.link(scene, out / "case.h5")
    ownership.protect_input(str(scene))
    try:
        with pytest.raises(ForeignFileError, match="input of this run"):
            ownership.check_target(str(out / "case.h5"))
        with pytest.raises(ForeignFileError):
            ownership.check_owned(str(out / "case.h5"), "case")
    finally:
        ownership._PROTECTED.clear()
    ownership.check_target(str(out / "new.csv"), root=str(out))  # a fresh name passes


def test_replace_into_leaves_the_old_file_on_a_full_disk(tmp_path):
    path = tmp_path / "expanded.toml"
    path.write_text("old\n")

    def full(fh):
        fh.write("new, partly")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(OSError):
        ownership.replace_into(str(path), full)
    assert path.read_text() == "old\n"
    assert os.listdir(tmp_path) == ["expanded.toml"]  # the temporary removed
    ownership.replace_into(str(path), lambda fh: fh.write("new\n"))
    assert path.read_text() == "new\n"


@pytest.mark.parametrize("shape", ["garbage", "deep", "folder", "link", "fifo", "huge", "other"])
def test_manifest_of_any_wrong_shape_is_one_line(tmp_path, shape):
    m = tmp_path / ownership.MANIFEST
    if shape == "garbage":
        m.write_bytes(b"\x00\xff{not json")
    elif shape == "deep":
        m.write_text("[" * 5000 + "]" * 5000)
    elif shape == "folder":
        m.mkdir()
    elif shape == "link":
        (tmp_path / "real.json").write_text('{"format": "pmpm-files-1", "files": {}}')
        os.symlink(tmp_path / "real.json", m)
    elif shape == "fifo":
        os.mkfifo(m)  # must not hang: never opened
    elif shape == "huge":
        with open(m, "wb") as fh:
            fh.truncate(ownership.MAX_MANIFEST_BYTES + 1)
    else:
        m.write_text('{"format": "something-else", "files": {}}')
    with pytest.raises(ForeignFileError, match="pmpm-files.json") as exc:
        ownership.check_manifest(str(tmp_path))
    assert "\n" not in str(exc.value)


def test_checkpoint_cut_short_is_absent_not_ownerless(tmp_path, monkeypatch):
    from pmpm.io import checkpoint
    comm = MPI.COMM_SELF
    base = str(tmp_path / "case")
    fields = {"id": np.arange(4, dtype=np.int64), "x": np.ones((4, 2))}
    first = checkpoint.write_checkpoint(base, comm, 0.1, 1, fields, {"pmpm_owner": "case"})
    assert ownership.hdf5_owner(first) == "case"
    real = checkpoint._write_file

    def killed(path, *args):  # the file begun, then the process dies (an exception stands for it)
        import h5py
        with h5py.File(path, "w-") as f:
            f.create_group("particles")
        raise OSError(errno.EIO, "killed while writing")

    monkeypatch.setattr(checkpoint, "_write_file", killed)
    with pytest.raises(Exception):
        checkpoint.write_checkpoint(base, comm, 0.2, 2, fields, {"pmpm_owner": "case"})
    monkeypatch.setattr(checkpoint, "_write_file", real)
    second = checkpoint.checkpoint_paths(base)[1]
    assert not os.path.exists(second)  # was left there, without its pmpm_owner record
    assert ownership.hdf5_owner(first) == "case"
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".pmpm-tmp")]
    again = checkpoint.write_checkpoint(base, comm, 0.2, 2, fields, {"pmpm_owner": "case"})
    assert again == second and ownership.hdf5_owner(second) == "case"


def test_a_deleted_input_protects_nothing(tmp_path):
    """A long process (the API, the generated suite) runs many scenes: once a scene file is
    deleted, its inode may be given to a new output file, which must not be refused."""
    for k in range(20):  # a few rounds: the file system tends to hand the freed inode back
        scene = tmp_path / f"s{k}.toml"
        scene.write_text("x = 1\n")
        ownership.protect_input(str(scene))
        os.remove(scene)
        out = tmp_path / f"out{k}.csv"
        out.write_text("pmpm's\n")
        ownership.check_target(str(out))
    ownership._PROTECTED.clear()


def test_a_run_claims_its_names(tmp_path):
    """Deliverable 3: a live claim refuses a second run; a dead process's claim is taken over;
    the claim of this process is its own; a claim that is not pmpm's is refused. Before the
    claim existed, nothing stopped the second run until it met the first's files."""
    import subprocess
    import sys
    import time
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        path = tmp_path / ".beam_x.pmpm-claim"
        path.write_text('{"format": "pmpm-claim-1", "pid": %d, "host": "%s"}' % (other.pid, __import__("socket").gethostname()))
        with pytest.raises(ForeignFileError, match="another pmpm run"):
            ownership.claim_run(str(tmp_path), "beam_x")
    finally:
        other.kill()
        other.wait()
    time.sleep(0.1)
    assert ownership.claim_run(str(tmp_path), "beam_x") == str(path)  # the dead run's claim
    assert ownership.claim_run(str(tmp_path), "beam_x") == str(path)  # ours: again is fine
    ownership.release_claims()
    assert not path.exists()
    path.write_text("garbage")
    with pytest.raises(ForeignFileError, match="not a claim"):
        ownership.claim_run(str(tmp_path), "beam_x")
    path.unlink()
    os.symlink(tmp_path / "elsewhere", path)
    with pytest.raises(ForeignFileError):
        ownership.claim_run(str(tmp_path), "beam_x")
    assert not (tmp_path / "elsewhere").exists()
