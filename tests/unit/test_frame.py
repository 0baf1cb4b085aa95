"""The frame front end (pmpm/scene/frame.py), the W-shape table (sections.py) and the TOML
writer (toml_writer.py): the expansion rules of docs/scenes.md "Frames" on a two-storey,
two-bay frame, the table against the AISC values and the plates' own geometry, the writer's
round trip, and ``pmpm expand``."""
import glob
import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from pmpm.errors import ConfigError
from pmpm.scene.config import load_scene, parse_scene, read_toml
from pmpm.scene.frame import expand_frame, frame_report
from pmpm.scene.sections import lookup, section_names
from pmpm.scene.toml_writer import dumps

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
H = 0.1


def two_storey(**extra):
    """Two bays of 4 m, two storeys of 3 m; W14X90 columns, W18X35 beams; supports on y = 0."""
    nodes = [{"name": f"n{i}{j}", "at": [4.0 * i, 3.0 * j]} for j in range(3) for i in range(3)]
    members = [{"name": f"c{i}{j}", "from": f"n{i}{j}", "to": f"n{i}{j + 1}", "section": "W14x90"}
               for i in range(3) for j in range(2)]
    members += [{"name": f"b{i}{j}", "from": f"n{i}{j}", "to": f"n{i + 1}{j}", "section": "W18x35"}
                for i in range(2) for j in (1, 2)]
    frame = {"material": "steel", "nodes": nodes, "members": members,
             "supports": [{"node": "n00", "type": "fixed"}, {"node": "n10", "type": "pinned"},
                          {"node": "n20", "type": "roller"}],
             "loads": [{"node": "n02", "force": [1e5, 0.0]}]}
    frame.update(extra)
    return {"grid": {"origin": [-1.0, 0.0], "cell_size": H, "cells": [100, 70]},
            "materials": {"steel": {"type": "linear_elastic", "E": 2e11, "nu": 0.3, "density": 7850.0}},
            "frame": frame, "solver": {"end_time": 0.01}}


def _by_name(items):
    return {it["name"]: it for it in items}


def test_w_shapes_table_matches_aisc_v16_values():
    """W12X120 and W16X36 as printed in the AISC Shapes Database v16.0 (in, in^2, in^4, in^3)."""
    p = lookup("W12x120")
    inch = 0.0254
    assert (p["d"], p["bf"], p["tf"], p["tw"]) == pytest.approx((13.1 * inch, 12.3 * inch, 1.11 * inch, 0.71 * inch))
    assert p["A"] == pytest.approx(35.2 * inch ** 2) and p["Ix"] == pytest.approx(1070 * inch ** 4)
    assert p["Zx"] == pytest.approx(186 * inch ** 3) and p["Sx"] == pytest.approx(163 * inch ** 3)
    assert lookup("w16X36")["Ix"] == pytest.approx(448 * inch ** 4)
    assert len(section_names()) == 289


def test_every_w_shape_is_consistent_with_its_plates():
    """A and Ix of the three plates (flanges bf x tf, web tw over d - 2 tf) against the tabulated
    ones, for every shape: the fillets add 0 to 7% of area and up to 3% of Ix (AISC's k - tf
    fillet), and 3-digit rounding of the dimensions moves a few per cent more; a unit or column
    mix-up would be off by factors."""
    for name in section_names():
        p = lookup(name)
        web = p["d"] - 2 * p["tf"]
        area = 2 * p["bf"] * p["tf"] + web * p["tw"]
        ix = (p["bf"] * p["d"] ** 3 - (p["bf"] - p["tw"]) * web ** 3) / 12
        assert 0.95 < p["A"] / area < 1.12, name
        assert 0.95 < p["Ix"] / ix < 1.06, name
        assert p["Zx"] > p["Sx"] > 0 and p["Ix"] > p["Iy"] > 0, name


def test_unknown_section_names_the_closest():
    with pytest.raises(ConfigError) as err:
        lookup("W12x12O", "frame.members[0].section")
    assert err.value.key == "frame.members[0].section"
    assert "closest: W12X120" in err.value.reason


def test_columns_run_through_joints_and_beams_frame_into_faces():
    out = expand_frame(two_storey())
    bodies = _by_name(out["bodies"])
    dc, db = lookup("W14x90")["d"], lookup("W18x35")["d"]
    # lower column: base to the top of the first-floor panel; upper column: from there up to the roof beam's top
    assert bodies["c10"]["start"] == [4.0, 0.0] and bodies["c10"]["end"] == pytest.approx([4.0, 3.0 + db / 2])
    assert bodies["c11"]["start"] == pytest.approx([4.0, 3.0 + db / 2])
    assert bodies["c11"]["end"] == pytest.approx([4.0, 6.0 + db / 2])
    assert bodies["b01"]["start"] == pytest.approx([dc / 2, 3.0])
    assert bodies["b01"]["end"] == pytest.approx([4.0 - dc / 2, 3.0])
    assert bodies["c00"]["depth"] == dc and bodies["c00"]["area"] == lookup("W14x90")["A"]
    scene = parse_scene(out)  # and the expanded scene is a valid ordinary scene
    assert len(scene.bodies) == 10 and not hasattr(scene, "frame")


def test_supports_cuts_tracks_and_loads():
    out = expand_frame(two_storey())
    bc = _by_name(out["boundary"])
    dc = lookup("W14x90")["d"]
    assert bc["n00"]["type"] == "fixed" and bc["n00"]["lower"] == pytest.approx([-dc / 2 - 2 * H, 0.0])
    assert bc["n10"]["type"] == "fixed" and bc["n10"]["lower"] == bc["n10"]["upper"] == pytest.approx([4.0, 0.0])
    assert bc["n20"]["type"] == "roller_x" and bc["n20"]["lower"] == bc["n20"]["upper"]
    assert all(b["reaction"] and b["moment_about"] == [4.0 * i, 0.0] for i, b in enumerate(out["boundary"]))
    cuts = _by_name(out["output"]["section"])
    assert len(cuts) == 20 and set(cuts) >= {"c00_n00", "c00_n01", "b01_n01", "b01_n11"}
    db = lookup("W18x35")["d"]
    assert cuts["c00_n00"]["position"] == pytest.approx(3 * H)                 # 3 cells above the support
    assert cuts["c00_n01"]["position"] == pytest.approx(3.0 - db / 2 - 3 * H)   # 3 cells below the panel
    assert cuts["c01_n01"]["position"] == pytest.approx(3 * H)                 # 3 cells above the panel
    assert [t["name"] for t in out["output"]["track"]] == [n["name"] for n in two_storey()["frame"]["nodes"]]
    (load,) = out["loads"]["forces"]
    assert load["lower"] == pytest.approx([-dc / 2, 6.0 - db / 2], abs=1e-6)
    assert load["upper"] == pytest.approx([dc / 2, 6.0 + db / 2], abs=1e-6)


def test_load_per_length_and_weak_axis():
    data = two_storey()
    for m in data["frame"]["members"]:
        if m["name"] == "b02":
            m["load_per_length"] = [0.0, -2e4]
        if m["name"] == "c20":
            m["axis"] = "weak"
    out = expand_frame(data)
    line = _by_name(out["loads"]["forces"])["b02_line_load"]
    assert line["force"] == [0.0, -2e4 * 4.0]   # per metre of the node-to-node length
    dc = lookup("W14x90")["d"]
    assert line["lower"][0] > dc / 2 and line["upper"][0] < 4.0 - dc / 2  # the clear span only
    weak = _by_name(out["bodies"])["c20"]
    p = lookup("W14x90")
    assert (weak["depth"], weak["web_thickness"], weak["flange_width"], weak["inertia"]) == (p["bf"], p["d"], 2 * p["tf"], p["Iy"])


def test_mixed_with_ordinary_bodies():
    data = two_storey()
    data["bodies"] = [{"name": "block", "shape": "rectangle", "material": "steel",
                       "lower": [5.0, 4.0], "upper": [6.0, 4.5]}]
    out = expand_frame(data)
    assert [b["name"] for b in out["bodies"]][-1] == "block" and len(out["bodies"]) == 11
    assert data["bodies"][0] == out["bodies"][-1] and "frame" in data  # the input is not changed
    parse_scene(out)


def test_derived_names_that_collide_are_refused():
    """A scene's own cut named like a generated one: refused, naming the frame."""
    data = two_storey()
    data["output"] = {"section": [{"name": "c00_n00", "body": "c00", "position": 1.0}]}
    with pytest.raises(ConfigError) as err:
        expand_frame(data)
    assert err.value.key == "frame" and "two section cuts are named 'c00_n00'" in err.value.reason


def test_toml_writer_round_trips_every_case():
    for path in sorted(glob.glob(os.path.join(ROOT, "cases", "**", "*.toml"), recursive=True)):
        data = read_toml(path)
        assert tomllib.loads(dumps(data)) == data, path
    data = expand_frame(read_toml(os.path.join(ROOT, "cases", "portal_frame.toml")))
    assert tomllib.loads(dumps(data, header="a\nb")) == data


def test_check_report_counts_what_was_generated():
    lines = frame_report(read_toml(os.path.join(ROOT, "cases", "portal_frame.toml")))
    assert lines[0] == "frame: 4 nodes, 3 members"
    assert "3 bodies (i_section strips): left_column, right_column, beam" in lines[1]
    assert "6 section cuts" in lines[4] and "4 tracked points" in lines[5]


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "pmpm.cli", *args], cwd=cwd, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=ROOT))


def test_expand_command_writes_the_ordinary_scene(tmp_path):
    src = os.path.join(ROOT, "cases", "portal_frame.toml")
    proc = _cli("expand", src, "-o", str(tmp_path / "expanded.toml"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    written = read_toml(tmp_path / "expanded.toml")
    assert "frame" not in written and written == expand_frame(read_toml(src))
    a, b = load_scene(str(tmp_path / "expanded.toml")), load_scene(src)
    assert [s.bodies for s in a] == [s.bodies for s in b]
    assert [s.boundaries for s in a] == [s.boundaries for s in b]


def test_expand_command_refuses_bad_input_and_writes_nothing(tmp_path):
    text = open(os.path.join(ROOT, "cases", "portal_frame.toml")).read()
    (tmp_path / "case.toml").write_text(text.replace('section = "W16x36_paper"', 'section = "W16x63x"'))
    proc = _cli("expand", "case.toml", "-o", "out.toml", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert proc.stderr.startswith("pmpm: error: case.toml: frame.members[2].section: unknown section 'W16x63x'")
    assert sorted(os.listdir(tmp_path)) == ["case.toml"]


def test_nodal_masses_add_exactly_their_mass_to_the_joint_panel():
    """[[frame.masses]]: the panel under the node is split off with a denser copy of the
    material; the particles' total mass grows by exactly the masses, and the mass sits in the
    panel (its centroid is the node's height)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    plain = two_storey()
    heavy = two_storey(masses=[{"node": "n01", "mass": 5000.0}, {"node": "n12", "mass": 2500.0}])
    out = expand_frame(heavy)
    names = [b["name"] for b in out["bodies"]]
    assert {"c00_panel_n01", "c11_panel_n12"} <= set(names) and "steel+n01" in out["materials"]
    assert out["materials"]["steel+n01"]["E"] == 2e11
    for data in (plain, heavy):
        data["particles_per_cell"] = 3   # 11 rows across W14X90 at 0.1 m cells (7 cannot carry its I)
    pa = build_solver(parse_scene(plain), MPI.COMM_SELF).particles
    pb = build_solver(parse_scene(heavy), MPI.COMM_SELF).particles
    assert pb["m"].sum() == pytest.approx(pa["m"].sum() + 7500.0, rel=1e-12)
    assert pb["m"][pb["mat"] != 0].sum() > 7500.0 and len(np.unique(pb["mat"])) == 3
    panel = pb["body"] == names.index("c00_panel_n01")
    assert np.average(pb["x"][panel, 1], weights=pb["m"][panel]) == pytest.approx(3.0, abs=0.01)


def _edit(path, value):
    def apply(data):
        node = data["frame"]
        for part in path[:-1]:
            node = node[part]
        node[path[-1]] = value
        return data
    return apply


@pytest.mark.parametrize("edit,key,reason", [
    (_edit(["nodes", 4, "name"], "n00"), "frame.nodes[4].name", "node name 'n00' is already used"),
    (_edit(["supports", 0, "type"], "hinge"), "frame.supports[0].type", "must be one of fixed, pinned, roller"),
    (_edit(["cut_ofset"], 0.1), "frame.cut_ofset", "unknown key"),
    (_edit(["loads", 0, "node"], "n2"), "frame.loads[0].node", "no node named 'n2' (closest: n20, n21, n02)"),
    (_edit(["members", 0, "cut_offsets"], [1.6, 1.6]), "frame.members[0].cut_offsets", "the end cuts of member 'c00' cross"),
    (_edit(["masses"], [{"node": "n00", "mass": 1.0}]), "frame.masses[0].node", "needs a column under node 'n00'"),
    (_edit(["members", 0, "material"], "stee"), "frame.members[0].material", "no material 'stee'"),
])
def test_frame_errors_name_the_entry(edit, key, reason):
    with pytest.raises(ConfigError) as err:
        expand_frame(edit(two_storey()))
    assert err.value.key == key and reason in err.value.reason, str(err.value)
