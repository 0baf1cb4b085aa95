"""The Python API (pmpm.run, pmpm.load_results): the examples of docs/api.md, run as written,
and the properties they rest on checked against theory and the results file.

The bar of cases/bar.toml (closed form in its header) runs for short end times, a few seconds
each once the kernels are compiled.
"""
import os
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

import pmpm
from pmpm.errors import ConfigError

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "api.md"


@pytest.fixture
def in_copy(tmp_path, monkeypatch):
    """A working folder with cases/bar.toml, as the docs' examples expect (the repo's root)."""
    (tmp_path / "cases").mkdir()
    shutil.copy(REPO / "cases" / "bar.toml", tmp_path / "cases")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_examples_of_docs_api_md_run(in_copy):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) >= 5
    namespace = {}
    for k, block in enumerate(blocks):
        exec(compile(block, f"docs/api.md, python block {k + 1}", "exec"), namespace)
    assert os.path.isfile(in_copy / "bar_api" / "bar.h5")


@pytest.mark.parametrize("precision", ["double", "single"])
def test_in_memory_and_written_results_agree(in_copy, precision):
    """write=False keeps what write=True writes: the same histories, energies and frames; at
    output.precision = "single" the file's changing float fields are the in-memory float64 values
    rounded to the nearest float32 (IEEE round to nearest: exactly ``np.float32(value)``), the
    constants (x0, m, ...) and everything else unchanged."""
    over = {"solver.end_time": 1.0, "output.directory": "out", "output.precision": precision,
            "output.fields": ["x", "x0", "v", "m", "stress", "strain", "mat"]}
    mem = pmpm.run("cases/bar.toml", overrides=over, dataframes=False)
    disk = pmpm.run("cases/bar.toml", overrides=over, write=True, dataframes=False)
    assert mem.path is None and disk.path == os.path.join("out", "bar.h5")
    assert mem.track_ids == disk.track_ids
    for track in ("middle", "free_end"):
        np.testing.assert_array_equal(mem.histories[track], disk.histories[track])
    np.testing.assert_array_equal(mem.energies, disk.energies)
    np.testing.assert_array_equal(mem.frame_times, disk.frame_times)
    assert sorted(mem.frames) == sorted(disk.frames)
    rounded = {"x", "v", "stress", "strain"} if precision == "single" else set()
    for name in mem.frames:
        want = mem.frames[name].astype(np.float32) if name in rounded else mem.frames[name]
        assert disk.frames[name].dtype == want.dtype, name
        np.testing.assert_array_equal(want, disk.frames[name])
    with h5py.File(disk.path, "r") as f:
        # the id the file stores for a track is the particle whose x0 is nearest the point
        x0 = f["frames/x"][0]
        tip = np.argmin(np.sum((x0 - [25.0, 0.25]) ** 2, axis=1))
        assert f["history/free_end"].attrs["particle_id"] == tip == mem.track_ids["free_end"]
        assert list(f["history/free_end"].attrs["units"][:2]) == ["m", "m"]
        assert f["energies/strain_energy"].attrs["units"] == "J"
        assert "ENGINEERING" in f["frames/strain"].attrs["description"]
        # every dataset of a real run's file, views included, names a known SI unit
        units = {}

        def collect(name, obj):  # returns None: visititems stops at the first other value
            if isinstance(obj, h5py.Dataset):
                units[name] = obj.attrs.get("units")

        f.visititems(collect)
        flat = {name: [u] if isinstance(u, str) else list(u) for name, u in units.items() if u is not None}
        assert sorted(set(units) - set(flat)) == []
        assert not [name for name, us in flat.items() if "unknown" in us]
        assert units["frames/stress"] == "Pa" and units["views/frame_00000/sxx"] == "Pa"


def test_frames_are_ordered_by_id(in_copy):
    """Row i of a frame is particle i: the tracked particle's row holds the position and stress
    its history recorded at the same instants (the first and the last frame are also history rows)."""
    res = pmpm.run("cases/bar.toml", overrides={"solver.end_time": 0.5}, dataframes=False)
    assert (res.frames["id"] == np.arange(res.frames["id"].shape[1])).all()
    for track, pid in res.track_ids.items():
        h = res.histories[track]
        for frame, row in ((0, 0), (-1, -1)):
            assert res.frame_times[frame] == h["time"][row]
            np.testing.assert_array_equal(res.frames["x"][frame, pid], [h["x"][row], h["y"][row]])
            np.testing.assert_array_equal(res.frames["stress"][frame, pid, :3],
                                          [h["sxx"][row], h["syy"][row], h["sxy"][row]])
        last = res.frame(-1)
        assert last["id"][pid] == pid and last["sxx"][pid] == h["sxx"][-1]


def test_overrides_match_a_variant(in_copy):
    """An override and a [variants.*] entry with the same dotted key give the same run."""
    text = (in_copy / "cases" / "bar.toml").read_text()
    (in_copy / "cases" / "bar_v.toml").write_text(text + '\n[variants.stiff]\n"materials.bar.E" = 400.0\n')
    over = {"solver.end_time": 0.5}
    by_variant = pmpm.run("cases/bar_v.toml", overrides=over, variant="stiff", dataframes=False)
    by_override = pmpm.run("cases/bar.toml", overrides={**over, "materials.bar.E": 400.0}, dataframes=False)
    np.testing.assert_array_equal(by_variant.histories["free_end"], by_override.histories["free_end"])
    every = pmpm.run("cases/bar_v.toml", overrides=over, dataframes=False)
    assert list(every) == ["stiff"] and every["stiff"].scene.variant == "stiff"


def test_bad_input(in_copy):
    with pytest.raises(ConfigError, match="overrides.bodies.7.lower"):
        pmpm.run("cases/bar.toml", overrides={"bodies.7.lower": [0, 0]})
    with pytest.raises(ConfigError, match="no variant 'x'"):
        pmpm.run("cases/bar.toml", variant="x")
    scene = pmpm.load_scene("cases/bar.toml")[0]
    with pytest.raises(TypeError, match="overrides need"):
        pmpm.run(scene, overrides={"solver.cfl": 0.3})
    with pytest.raises(ValueError, match="not a pmpm results file"):
        with h5py.File(in_copy / "x.h5", "w") as f:
            f["a"] = 1
        pmpm.load_results(in_copy / "x.h5")


def test_pandas_tables_when_installed(in_copy):
    pandas = pytest.importorskip("pandas", reason="pandas is optional; without it tables are numpy")
    res = pmpm.run("cases/bar.toml", overrides={"solver.end_time": 0.5})
    assert isinstance(res.energies, pandas.DataFrame) and isinstance(res.frame(-1), pandas.DataFrame)


def test_progress_true_without_tqdm_writes_a_line(in_copy, capsys, monkeypatch):
    import builtins
    real_import = builtins.__import__

    def no_tqdm(name, *args, **kwargs):
        if name.startswith("tqdm"):
            raise ImportError("no tqdm here")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_tqdm)
    pmpm.run("cases/bar.toml", overrides={"solver.end_time": 0.5}, progress=True, dataframes=False)
    err = capsys.readouterr().err
    assert err.endswith("(100.0%)\n") and "of 0.5 s" in err


def test_a_run_without_positions_writes_no_sidecar(in_copy):
    res = pmpm.run("cases/bar.toml", overrides={"solver.end_time": 0.2, "output.fields": ["stress"],
                                                "output.directory": "nox"}, write=True, dataframes=False)
    assert sorted(os.listdir(in_copy / "nox")) == ["bar.h5"] and sorted(res.frames) == ["id", "stress"]


def test_progress_true_uses_tqdm_when_installed(in_copy, monkeypatch):
    """With tqdm importable (here a recording stand-in for tqdm.auto.tqdm), progress=True feeds
    one bar per run with simulated seconds up to the end time, then closes it."""
    import sys
    import types

    bars = []

    class Bar:
        def __init__(self, total, **kwargs):
            self.total, self.n, self.closed = total, 0.0, False
            bars.append(self)

        def update(self, k):
            self.n += k

        def close(self):
            self.closed = True

    auto = types.ModuleType("tqdm.auto")
    auto.tqdm = Bar
    monkeypatch.setitem(sys.modules, "tqdm", types.ModuleType("tqdm"))
    monkeypatch.setitem(sys.modules, "tqdm.auto", auto)
    text = (in_copy / "cases" / "bar.toml").read_text()
    (in_copy / "cases" / "two.toml").write_text(text + "\n[variants.a]\n[variants.b]\n")
    pmpm.run("cases/two.toml", overrides={"solver.end_time": 0.5}, progress=True, dataframes=False)
    assert len(bars) == 2 and all(b.closed and b.total == 0.5 for b in bars)
    assert all(b.n == pytest.approx(0.5, rel=1e-9) for b in bars)  # rounding of the summed updates


def test_tables_go_through_pandas_when_importable(in_copy, monkeypatch):
    """A stand-in pandas (pandas itself is optional and absent here): every table is built by
    pandas.DataFrame from the same columns the numpy tables hold."""
    import sys
    import types

    class DataFrame(dict):
        pass

    fake = types.ModuleType("pandas")
    fake.DataFrame = DataFrame
    monkeypatch.setitem(sys.modules, "pandas", fake)
    over = {"solver.end_time": 0.2}
    res = pmpm.run("cases/bar.toml", overrides=over)
    ref = pmpm.run("cases/bar.toml", overrides=over, dataframes=False)
    assert isinstance(res.energies, DataFrame) and isinstance(res.histories["middle"], DataFrame)
    assert list(res.energies) == list(ref.energies.dtype.names)
    np.testing.assert_array_equal(res.energies["strain_energy"], ref.energies["strain_energy"])
    frame = res.frame(-1)
    assert isinstance(frame, DataFrame) and list(frame) == list(ref.frame(-1).dtype.names)


def test_sections_and_reactions_in_memory_and_from_the_file(in_copy):
    """A scene's section cut and reactions (pmpm/results) reach the Result, the same in memory as
    read back from the file; the fixed end's reaction balances the bar's axial force there."""
    text = (in_copy / "cases" / "bar.toml").read_text()
    text = text.replace('fields = ["x", "v", "stress", "strain"]',
                        'fields = ["x", "v", "stress", "strain"]\nreactions = true')
    text = text.replace('name = "fixed end"', 'name = "fixed_end"')  # reactions name files
    text += '\n[[output.section]]\nname = "middle"\nsegment = [[12.5, 0.0], [12.5, 0.5]]\n'
    (in_copy / "cases" / "cut.toml").write_text(text)
    over = {"solver.end_time": 0.5, "output.directory": "cut"}
    mem = pmpm.run("cases/cut.toml", overrides=over, dataframes=False)
    disk = pmpm.run("cases/cut.toml", overrides=over, write=True, dataframes=False)
    assert list(mem.sections) == ["middle"] and list(disk.sections) == ["middle"]
    assert list(mem.reactions) == list(disk.reactions) and len(mem.reactions) == 1
    for kind in ("sections", "reactions"):
        for name, table in getattr(mem, kind).items():
            other = getattr(disk, kind)[name]
            assert table.dtype.names == other.dtype.names
            for column in table.dtype.names:
                np.testing.assert_array_equal(table[column], other[column])
    assert np.ptp(mem.sections["middle"]["N"]) > 0  # the vibrating bar carries a varying axial force
