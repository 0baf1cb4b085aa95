"""Files that crash libhdf5, and FIFOs, at every read entry point (issue 35, deliverable 2): one
line ``pmpm: error: ...``, exit 2, never a hang, a segmentation fault or a stack dump.

- ``pmpm plot``, ``pmpm export``, :func:`pmpm.load_results` and ``--restart`` (a results file, an
  explicit checkpoint, the newer checkpoint in the folder) on an HDF5 file crafted to crash
  libhdf5, and on a FIFO;
- a mesh that pulls in a FIFO (an Abaqus ``*INCLUDE``, an XDMF ``Binary`` or ``HDF`` data item)
  or a crashing HDF5 file (an XDMF ``HDF`` data item).

Every read goes through pmpm.io.validate.check_hdf5_readable (a regular file, first opened in a
forked child). Shown to fail before the fix: the forked child's crash printed Open MPI's 33-line
stack dump (Open MPI's SIGSEGV handler, installed once mpi4py initialised MPI) after the one line,
so plot / export / --restart gave 36 lines; an explicit crashing checkpoint gave a warning line
and the error line; an Abaqus ``*INCLUDE`` of a FIFO and an XDMF Binary data item of a FIFO hung
until the timeout, an XDMF HDF data item of a crashing file killed the run (SIGSEGV).

The crashing file is crafted here, not stored: one byte after the ``layout`` attribute's name (its
variable-length string's heap reference) set so that reading the attribute dereferences garbage
(H5T__conv_vlen -> H5F_addr_decode); the search checks in a bare forked child that the file does
crash libhdf5, so the test never passes on a file that is merely unreadable.
"""
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BAR = (open(os.path.join(ROOT, "cases", "bar.toml")).read().replace("end_time = 10.0", "end_time = 1.2")
       .replace("interval = 0.5\n", "interval = 0.5\ncheckpoint_interval = 0.4\n", 1))
TIMEOUT = 120


def _pmpm(cwd, *args, code=None):
    env = dict(os.environ, PYTHONPATH=ROOT)
    argv = [sys.executable, "-c", code] if code else [sys.executable, "-m", "pmpm.cli", *args]
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT)


def _one_line(r, *words):
    assert r.returncode == 2, (r.returncode, r.stdout[-500:], r.stderr[-3000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pmpm: error: "), r.stderr[-3000:]
    for w in words:
        assert w in lines[0], lines[0]


def _crashes(path, name):
    """True if opening ``path`` and reading its root attribute ``name`` kills a bare child."""
    code = f"import h5py\nwith h5py.File({path!r}, 'r') as f: f.attrs.get({name.decode()!r})"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60)
    return r.returncode < 0


def craft_crashing(src, dst, name=b"layout"):
    """Copy ``src`` to ``dst`` with one byte after the attribute ``name`` changed so that libhdf5
    crashes reading the root attributes (searched and confirmed in a child)."""
    raw = open(src, "rb").read()
    at = raw.find(name)
    assert at > 0, name
    for off in range(at, at + 160):
        for value in (72, 31, 255):
            data = bytearray(raw)
            data[off] = value
            with open(dst, "wb") as fh:
                fh.write(bytes(data))
            if _crashes(dst, name):
                return dst
    raise AssertionError(f"no single byte after {name!r} crashes libhdf5: craft another file")


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("crash")
    (tmp / "bar.toml").write_text(BAR)
    r = _pmpm(tmp, "bar.toml", "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
    out = tmp / "bar_results"
    assert (out / "bar.ckpt0.h5").exists() and (out / "bar.ckpt1.h5").exists()
    crash = craft_crashing(str(out / "bar.h5"), str(tmp / "crash.h5"))
    return tmp, crash


def _copy_run(bar_run, tmp_path):
    import shutil
    src, crash = bar_run
    shutil.copy(src / "bar.toml", tmp_path / "bar.toml")
    shutil.copytree(src / "bar_results", tmp_path / "bar_results")
    return crash


@pytest.mark.parametrize("kind", ["crash", "fifo"])
@pytest.mark.parametrize("entry", ["plot", "export", "export-xdmf", "load_results"])
def test_a_crashing_file_or_a_fifo_given_to_a_reader_is_one_line(bar_run, tmp_path, kind, entry):
    _copy_run(bar_run, tmp_path)
    target = tmp_path / "given.h5"
    if kind == "crash":
        import shutil
        shutil.copy(bar_run[1], target)
    else:
        os.mkfifo(target)
    if entry == "load_results":
        code = ("import sys, pmpm\ntry:\n    pmpm.load_results('given.h5')\nexcept ValueError as e:\n"
                "    print('pmpm: error: ' + str(e), file=sys.stderr); sys.exit(2)")
        r = _pmpm(tmp_path, code=code)
    else:
        argv = {"plot": ["plot", "given.h5"], "export": ["export", "given.h5"],
                "export-xdmf": ["export", "given.h5", "--format", "xdmf", "-o", "xd"]}[entry]
        r = _pmpm(tmp_path, *argv)
    _one_line(r, "given.h5", "crashed" if kind == "crash" else "FIFO")
    assert not (tmp_path / "given_vtu").exists() and not (tmp_path / "xd").exists()


@pytest.mark.parametrize("where", ["newer_checkpoint", "explicit_checkpoint", "results_file",
                                   "fifo_checkpoint", "fifo_explicit"])
def test_restart_from_a_crashing_file_or_a_fifo_is_one_line(bar_run, tmp_path, where):
    crash = _copy_run(bar_run, tmp_path)
    out = tmp_path / "bar_results"
    data = out / "bar.ckpt1.h5"
    arg = "bar_results/bar.h5"
    if where == "newer_checkpoint":
        craft_crashing(str(data), str(data))  # the newer of the two (step of ckpt1 > ckpt0)
    elif where == "explicit_checkpoint":
        craft_crashing(str(data), str(tmp_path / "x.ckpt0.h5"))
        arg = "x.ckpt0.h5"
    elif where == "results_file":
        import shutil
        shutil.copy(crash, out / "bar.h5")
    elif where == "fifo_checkpoint":
        data.unlink()
        os.mkfifo(data)
    else:
        os.mkfifo(tmp_path / "y.ckpt0.h5")
        arg = "y.ckpt0.h5"
    before = sorted(os.listdir(out))
    r = _pmpm(tmp_path, "bar.toml", "--restart", arg, "--no-plots", "-q")
    _one_line(r)
    assert sorted(os.listdir(out)) == before


def _mesh_scene(tmp_path, mesh_file):
    (tmp_path / "case.toml").write_text(f"""
thickness = 0.02
[grid]
cell_size = 0.25
cells = [16, 10]
[materials.m]
type = "linear_elastic"
E = 1.0
nu = 0.3
density = 1.0
[[bodies]]
shape = "mesh"
material = "m"
file = "{mesh_file}"
[solver]
end_time = 1.0
max_steps = 1
""")


ABAQUS = """*NODE
1, 0.5, 0.5
2, 1.5, 0.5
3, 1.5, 1.5
*ELEMENT, TYPE=CPS3
1, 1, 2, 3
*INCLUDE, INPUT={include}
"""

XDMF = """<?xml version="1.0"?>
<Xdmf Version="3.0"><Domain><Grid Name="mesh" GridType="Uniform">
<Topology TopologyType="Triangle" NumberOfElements="1">
<DataItem Dimensions="1 3" NumberType="Int" Format="XML">0 1 2</DataItem></Topology>
<Geometry GeometryType="XY">{geometry}</Geometry>
</Grid></Domain></Xdmf>
"""


@pytest.mark.parametrize("case", ["abaqus_include_fifo", "xdmf_binary_fifo", "xdmf_hdf_fifo",
                                  "xdmf_hdf_crash", "abaqus_include_loop"])
def test_a_file_a_mesh_pulls_in_is_checked_before_it_is_opened(bar_run, tmp_path, case):
    if case.startswith("abaqus"):
        include = "more.inp"
        if case.endswith("fifo"):
            os.mkfifo(tmp_path / include)
        else:  # more.inp includes part.inp, which includes more.inp: meshio would recurse
            (tmp_path / include).write_text("*INCLUDE, INPUT=part.inp\n")
        (tmp_path / "part.inp").write_text(ABAQUS.format(include=include))
        _mesh_scene(tmp_path, "part.inp")
        named = include if case.endswith("fifo") else "inp"
    else:
        if case == "xdmf_binary_fifo":
            os.mkfifo(tmp_path / "geo.bin")
            item = (f'<DataItem Dimensions="3 2" NumberType="Float" Precision="8" Format="Binary">'
                    f'{tmp_path}/geo.bin</DataItem>')
            named = "geo.bin"
        else:
            if case == "xdmf_hdf_fifo":
                os.mkfifo(tmp_path / "geo.h5")
            else:
                with h5py.File(tmp_path / "good.h5", "w") as f:
                    f.attrs["layout"] = "a variable-length string to corrupt"
                    f["geo"] = np.array([[0.5, 0.5], [1.5, 0.5], [1.5, 1.5]])
                craft_crashing(str(tmp_path / "good.h5"), str(tmp_path / "geo.h5"))
            item = '<DataItem Dimensions="3 2" NumberType="Float" Precision="8" Format="HDF">geo.h5:/geo</DataItem>'
            named = "geo.h5"
        (tmp_path / "part.xdmf").write_text(XDMF.format(geometry=item))
        _mesh_scene(tmp_path, "part.xdmf")
    r = _pmpm(tmp_path, "case.toml", "--no-plots", "-q")  # --check does not read meshes
    _one_line(r, named)
    assert not (tmp_path / "case_results").exists()


def test_a_mesh_with_a_regular_include_still_reads(tmp_path):
    """The check refuses only what it must: an Abaqus file whose include is a regular file."""
    (tmp_path / "more.inp").write_text("** nothing but a comment\n")
    (tmp_path / "part.inp").write_text(ABAQUS.format(include="more.inp"))
    _mesh_scene(tmp_path, "part.inp")
    r = _pmpm(tmp_path, "case.toml", "--no-plots", "-q")
    assert r.returncode == 0, r.stderr
