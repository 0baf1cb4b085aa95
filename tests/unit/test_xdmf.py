"""XDMF sidecar and VTU export of a small results file (serial).

The sidecar is checked against the HDF5 file itself: every DataItem must be a plain HDF
reference (no HyperSlab: ParaView's default reader and meshio do not read those) to an
existing dataset with the stated Dimensions and number type, holding exactly the frame data
its Attribute (or Geometry) claims to be. meshio's XDMF time-series reader, a real client,
must then give the same times and arrays as h5py.

Every test runs on a file of the current layout and on the same file written in the layout of
pmpm before issue 40 (``pmpm-results-2``: ids and constants in every frame, float64,
uncompressed; :func:`pmpm.io.legacy.write_layout2`), which pmpm still reads; the expected values
come through :func:`pmpm.io.layout.frame_fields`, the one reader of both.
"""

import os
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest
from mpi4py import MPI

from pmpm.io import OutputFile, export, write_xdmf
from pmpm.io.layout import frame_fields
from pmpm.io.legacy import write_layout2
from pmpm.io.xdmf import xdmf_number_type

N_TOTAL = 7
MISSING = 5
FRAME_FIELDS = {
    "x": ((2,), "f8"),
    "v": ((2,), "f8"),
    "stress": ((4,), "f8"),
    "strain": ((3,), "f8"),
    "mat": ((), "i4"),
    "eps_p_eq": ((), "f8"),
}
TIMES = [0.0, 0.125, 0.25]


def particles(frame, ids):
    """Deterministic particle fields of one frame."""
    f = ids.astype(float) + 10.0 * frame
    return {
        "id": ids,
        "x": np.stack([f, 0.5 * f], axis=1),
        "v": np.stack([-f, f], axis=1),
        "stress": f[:, None] * np.array([1.0, 2.0, 3.0, 4.0]),
        "strain": f[:, None] * np.array([0.1, 0.2, 0.3]),
        "mat": (ids % 2).astype(np.int32),
        "eps_p_eq": 1e-3 * f,
    }


@pytest.fixture(params=["current", "old"])
def results(tmp_path, request):
    """A results file with three frames; particle MISSING is removed after frame 0; in the
    current layout or in the old one."""
    path = tmp_path / "run" / "res.h5"
    path.parent.mkdir()
    ids = np.arange(N_TOTAL, dtype=np.int64)[::-1].copy()
    with OutputFile(path, MPI.COMM_SELF, {"scene": "{}"}, N_TOTAL, FRAME_FIELDS, [], [],
                    ["time"]) as out:
        for frame, time in enumerate(TIMES):
            alive = ids if frame == 0 else ids[ids != MISSING]
            out.write_frame(time, frame, particles(frame, alive))
    if request.param == "old":
        old = path.parent / "old.h5"
        write_layout2(path, old, views=False)
        os.replace(old, path)
    return str(path)


def _ints(text):
    return [int(v) for v in text.split()]


def _heavy_dataset(item, xdmf_dir, f):
    """Check one HDF DataItem against the file and return its dataset."""
    file_name, dset_path = item.text.strip().split(":")
    assert os.path.samefile(os.path.join(xdmf_dir, file_name), f.filename)
    assert dset_path in f, dset_path
    dset = f[dset_path]
    assert _ints(item.get("Dimensions")) == list(dset.shape)
    assert (item.get("NumberType"), item.get("Precision")) == xdmf_number_type(dset.dtype)
    return dset


def _evaluate(item, xdmf_dir, f):
    """Return the values a plain HDF DataItem stands for."""
    assert item.get("ItemType") is None and item.get("Format") == "HDF", item.attrib
    assert len(item) == 0  # no nested items (HyperSlab, Function)
    return _heavy_dataset(item, xdmf_dir, f)[()]


def _expected(f, frame, name):
    """The frame data an Attribute named ``name`` should hold."""
    frames = frame_fields(f)
    if name in frames:
        return frames[name][frame]
    for field, dset in frames.items():
        comps = [c.decode() if isinstance(c, bytes) else c for c in dset.attrs.get("components", [])]
        if name in comps:
            return dset[frame][:, comps.index(name)]
    raise AssertionError(f"attribute {name} matches no frame field")


def test_xdmf_references_match_the_hdf5_file(results):
    xdmf = write_xdmf(results)
    assert xdmf.endswith("res.xdmf")
    root = ET.parse(xdmf).getroot()
    assert root.tag == "Xdmf" and root.get("Version") == "3.0"
    collection = root.find("Domain/Grid")
    assert collection.get("GridType") == "Collection" and collection.get("CollectionType") == "Temporal"
    grids = collection.findall("Grid")
    xdmf_dir = os.path.dirname(xdmf)
    with h5py.File(results, "r") as f:
        np.testing.assert_array_equal([float(g.find("Time").get("Value")) for g in grids],
                                      f["frames/time"][()])
        for frame, grid in enumerate(grids):
            topo = grid.find("Topology")
            assert topo.get("TopologyType") == "Polyvertex" and int(topo.get("NumberOfElements")) == N_TOTAL
            np.testing.assert_array_equal(_evaluate(topo.find("DataItem"), xdmf_dir, f), np.arange(N_TOTAL))
            geom = grid.find("Geometry")
            assert geom.get("GeometryType") == "XY"
            np.testing.assert_array_equal(_evaluate(geom.find("DataItem"), xdmf_dir, f), f["frames/x"][frame])
            names = []
            for attr in grid.findall("Attribute"):
                names.append(attr.get("Name"))
                got = _evaluate(attr.find("DataItem"), xdmf_dir, f)
                want = _expected(f, frame, attr.get("Name"))
                if "/views/" not in attr.find("DataItem").text:
                    # layout 3: constants and ids are referenced once for every frame, so a
                    # removed particle (NaN position: not drawn) shows its values there
                    alive = np.isfinite(frame_fields(f)["x"][frame][:, 0])
                    got, want = got[alive], want[alive]
                np.testing.assert_array_equal(got, want)
                kind = {1: "Scalar", 2: "Vector"}[got.ndim if got.ndim == 1 else got.shape[1]]
                assert attr.get("AttributeType") == kind and attr.get("Center") == "Node"
            assert {"sxx", "syy", "sxy", "szz", "exx", "eyy", "gxy", "v", "x", "mat"} <= set(names)
    assert "HyperSlab" not in open(xdmf).read()
    # The removed particle reads NaN from frame 1 on
    with h5py.File(results, "r") as f:
        stored = frame_fields(f)
        assert np.isnan(stored["x"][1][MISSING]).all() and stored["mat"][2][MISSING] == -1
        assert stored["id"][2][MISSING] == -1 and stored["id"][0][MISSING] == MISSING


def test_meshio_reads_the_sidecar(results):
    xdmf = write_xdmf(results)
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader, h5py.File(results, "r") as f:
        points, cells = reader.read_points_cells()
        assert cells[0].type == "vertex" and len(cells[0].data) == N_TOTAL
        np.testing.assert_array_equal(points, f["frames/x"][0])
        assert reader.num_steps == len(TIMES)
        for frame in range(reader.num_steps):
            t, point_data, _ = reader.read_data(frame)
            assert t == f["frames/time"][frame]
            np.testing.assert_array_equal(point_data["x"], f["frames/x"][frame])
            np.testing.assert_array_equal(point_data["sxy"], f["frames/stress"][frame, :, 2])
            np.testing.assert_array_equal(point_data["gxy"], f["frames/strain"][frame, :, 2])
            alive = np.isfinite(f["frames/x"][frame][:, 0])  # a constant: drawn particles' rows
            np.testing.assert_array_equal(point_data["mat"][alive], frame_fields(f)["mat"][frame][alive])


def test_views_follow_a_restart(results):
    """Views are rebuilt from scratch: after frames are dropped and others written, each view
    reads its own frame's data (a stale mapping would read the old or the fill values)."""
    write_xdmf(results)
    with h5py.File(results, "r") as f:
        old = f.attrs["layout"] != "pmpm-results-3"
    if old:  # a restart never appends to a file of the old layout: refused in one line
        with pytest.raises(ValueError, match=r"^written by an older pmpm \(layout 'pmpm-results-2'\); a "
                                             r"restart appends only to 'pmpm-results-3' files"):
            OutputFile(results, MPI.COMM_SELF, {"scene": "{}"}, N_TOTAL, FRAME_FIELDS, [], [], ["time"],
                       append=True, truncate_after=TIMES[1])
        return
    with OutputFile(results, MPI.COMM_SELF, {"scene": "{}"}, N_TOTAL, FRAME_FIELDS, [], [], ["time"],
                    append=True, truncate_after=TIMES[1]) as out:
        out.write_frame(0.5, 9, particles(7, np.arange(N_TOTAL)))
    write_xdmf(results)
    with h5py.File(results, "r") as f:
        assert sorted(f["views"]) == ["frame_00000", "frame_00001", "frame_00002"]
        np.testing.assert_array_equal(f["views/frame_00002/szz"][()], f["frames/stress"][2, :, 3])
        assert f["frames/stress"][2, 0, 3] == 4.0 * 70.0  # particles(7): f = id + 70, szz = 4 f
        assert f["views/frame_00002"].attrs["time"] == 0.5


def test_xdmf_skips_frames_cut_short(results, tmp_path):
    with h5py.File(results, "r+") as f:
        for dset in f["frames"].values():
            dset.resize(dset.shape[0] + 1, axis=0)  # time stays NaN
    target = tmp_path / "elsewhere" / "side.xdmf"
    target.parent.mkdir()
    write_xdmf(results, target)
    grids = ET.parse(target).getroot().findall("Domain/Grid/Grid")
    assert len(grids) == len(TIMES)
    # The file name is relative to the sidecar
    assert grids[0].find("Geometry/DataItem[@Format='HDF']").text.startswith("../run/res.h5:")


def test_export_vtu_round_trip(results, tmp_path):
    paths = export(results, "vtu", tmp_path / "vtu")
    assert len(paths) == len(TIMES) + 1 and paths[-1].endswith("res.pvd")
    entries = ET.parse(paths[-1]).getroot().findall("Collection/DataSet")
    assert [float(e.get("timestep")) for e in entries] == TIMES
    with h5py.File(results, "r") as f:
        for frame, path in enumerate(paths[:-1]):
            assert os.path.basename(path) == entries[frame].get("file")
            mesh = meshio.read(path)
            x = f["frames/x"][frame]
            alive = np.flatnonzero(np.isfinite(x[:, 0]))
            assert len(alive) == (N_TOTAL if frame == 0 else N_TOTAL - 1)
            np.testing.assert_array_equal(mesh.points[:, :2], x[alive])
            assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == len(alive)
            np.testing.assert_array_equal(mesh.point_data["id"], alive)
            for name in ("x", "v", "mat", "eps_p_eq"):
                np.testing.assert_array_equal(mesh.point_data[name], frame_fields(f)[name][frame][alive])
            # several components: one array each, named
            for k, name in enumerate(("sxx", "syy", "sxy", "szz")):
                np.testing.assert_array_equal(mesh.point_data[name], f["frames/stress"][frame][alive, k])
            np.testing.assert_array_equal(mesh.point_data["gxy"], f["frames/strain"][frame][alive, 2])
            assert "stress" not in mesh.point_data


def test_export_default_folders(results):
    paths = export(results, "vtu")
    folder = os.path.join(os.path.dirname(results), "res_vtu")
    assert all(os.path.dirname(p) == folder for p in paths) and len(paths) == len(TIMES) + 1
    (xdmf,) = export(results, "xdmf")
    assert xdmf == os.path.join(os.path.dirname(results), "res.xdmf")


def test_export_other_formats(results, tmp_path):
    (xdmf,) = export(results, "xdmf", tmp_path / "x")
    assert os.path.exists(xdmf) and ET.parse(xdmf).getroot().tag == "Xdmf"
    with pytest.raises(ValueError, match="unknown export format"):
        export(results, "vtk")


def _pmpm(cwd, *args):
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-m", "pmpm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    return [line.removeprefix("wrote ") for line in proc.stdout.splitlines() if line.startswith("wrote ")]


def test_cli_export_folders_and_outdir(results, tmp_path):
    run_dir = os.path.dirname(results)
    written = _pmpm(tmp_path, "export", results)  # default format vtu, into <stem>_vtu/
    assert {os.path.dirname(p) for p in written} == {os.path.join(run_dir, "res_vtu")}
    assert sorted(os.listdir(run_dir)) == ["res.h5", "res_vtu"]
    written = _pmpm(tmp_path, "export", results, "--format", "xdmf", "-o", "side")
    assert written == [os.path.join("side", "res.xdmf")] and os.path.isfile(tmp_path / "side" / "res.xdmf")
    written = _pmpm(tmp_path, "export", results, "--format", "vtu", "-o", "vtu_here")
    assert {os.path.dirname(p) for p in written} == {"vtu_here"} and len(written) == len(TIMES) + 1
