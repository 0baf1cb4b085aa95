"""Geometry a structural user reads, against hand computations (issue 38): the frame front end
on members given from their upper / right node and on weak-axis sections, the section forces
of an I-section cut on a strip whose particle steps along and across differ, and the reaction
and moment of supports attached to a body's face (held faces).

How each test was shown to fail on its bug (planted, watched fail, restored):
* ``mutate.py --only frame_cut_offsets_by_lower_node``: a reversed member's cut offsets taken at
  its lower / left end: ``test_a_reversed_member_expands_like_its_hand_expansion`` fails;
* ``mutate.py --only frame_weak_flange_precedence``: the weak-axis flange zone bf - tw / 2:
  ``test_a_weak_axis_strip_is_the_section_turned`` fails;
* ``mutate.py --only section_spacing_axes_swapped``: the spacing along a cut's normal taken
  from the step across the strip: ``test_i_section_cut_forces_are_the_band_integral`` fails;
* ``mutate.py --only held_particles_momentum_not_counted``: ``test_a_held_face_under_a_moving_body_reacts_with_its_momentum_balance``
  fails;
* ``mutate.py --only held_face_moment_sign``: the constraint impulses' moment with the wrong
  sign of its y x Jx term: ``test_held_faces_react_with_minus_the_loads_and_their_moment`` fails.
"""
import math

import numpy as np
import pytest

import pmpm
from pmpm.scene.config import parse_scene
from pmpm.scene.frame import expand_frame
from pmpm.scene.sections import lookup

H = 0.1


def _by_name(items):
    return {it["name"]: it for it in items}


def _portal(members, **frame):
    """A one-bay portal: A (0, 0), B (0, 3), C (4, 3), D (4, 0); W14x90 columns, W18x35 beam."""
    nodes = [{"name": n, "at": at} for n, at in (("A", [0.0, 0.0]), ("B", [0.0, 3.0]),
                                                  ("C", [4.0, 3.0]), ("D", [4.0, 0.0]))]
    f = {"material": "steel", "nodes": nodes, "members": members,
         "supports": [{"node": "A", "type": "fixed"}, {"node": "D", "type": "pinned"}]}
    f.update(frame)
    return {"grid": {"origin": [-1.0, -0.5], "cell_size": H, "cells": [60, 45]},
            "materials": {"steel": {"type": "linear_elastic", "E": 2e11, "nu": 0.3, "density": 7850.0}},
            "frame": f, "solver": {"end_time": 0.01}}


def test_a_reversed_member_expands_like_its_hand_expansion():
    """Members given from their upper node to their lower node (the left column), from the right
    node to the left (the beam), with unequal cut offsets [at from, at to]: the bodies run lower /
    left to upper / right, and each cut ``<member>_<node>`` sits its own offset from the clear end
    at that node. Hand expansion (docs/scenes.md "Frames"): the left column from y = 0 (no beam at
    A) to the top of the beam at B, clear up to the beam's underside 3 - db/2; the beam between
    the column faces x = dc/2 and 4 - dc/2; positions measured from each body's start."""
    members = [{"name": "left", "from": "B", "to": "A", "section": "W14x90", "cut_offsets": [0.5, 0.3],
                "load_per_length": [1e3, 0.0]},
               {"name": "beam", "from": "C", "to": "B", "section": "W18x35", "cut_offsets": [0.4, 0.7]},
               {"name": "right", "from": "D", "to": "C", "section": "W14x90", "cut_offsets": [0.2, 0.6]}]
    out = expand_frame(_portal(members))
    dc, db = lookup("W14x90")["d"], lookup("W18x35")["d"]
    bodies = _by_name(out["bodies"])
    assert bodies["left"]["start"] == pytest.approx([0.0, 0.0]) and bodies["left"]["end"] == pytest.approx([0.0, 3.0 + db / 2])
    assert bodies["beam"]["start"] == pytest.approx([dc / 2, 3.0]) and bodies["beam"]["end"] == pytest.approx([4.0 - dc / 2, 3.0])
    assert bodies["right"]["start"] == pytest.approx([4.0, 0.0])
    cuts = _by_name(out["output"]["section"])
    want = {"left_B": 3.0 - db / 2 - 0.5, "left_A": 0.3,               # from B: 0.5 below B's panel
            "beam_C": (4.0 - dc / 2 - 0.4) - dc / 2, "beam_B": 0.7,    # from C: 0.4 left of C's face
            "right_D": 0.2, "right_C": 3.0 - db / 2 - 0.6}             # given forwards
    assert {k: cuts[k]["position"] for k in want} == pytest.approx(want)
    assert {k: cuts[k]["body"] for k in want} == {k: k.split("_")[0] for k in want}
    # the line load on the reversed column: over its clear length, per metre of its node-to-node length
    (line,) = [f for f in out["loads"]["forces"] if f["name"] == "left_line_load"]
    assert line["force"] == pytest.approx([3e3, 0.0])
    assert line["lower"][1] == pytest.approx(0.0, abs=1e-6) and line["upper"][1] == pytest.approx(3.0 - db / 2, abs=1e-6)
    parse_scene(out)   # a valid ordinary scene


def test_a_weak_axis_strip_is_the_section_turned():
    """A W14x90 column bending about its weak axis, by hand: across the strip (depth bf) two
    flange tips of total thickness 2 tf reach from the web band (width tw, thickness d) to the
    edges, so each flange zone is (bf - tw) / 2 wide; the plates' area is the section's plates'
    area turned, 2 bf tf + (d - 2 tf) tw, and their second moment 2 tf bf^3 / 12 + (d - 2 tf)
    tw^3 / 12 (the rolled shape's Iy with its fillets is given as the inertia)."""
    members = [{"name": "left", "from": "A", "to": "B", "section": "W14x90", "axis": "weak"},
               {"name": "beam", "from": "B", "to": "C", "section": "W18x35"},
               {"name": "right", "from": "C", "to": "D", "section": "W14x90"}]
    out = expand_frame(_portal(members))
    p = lookup("W14x90")
    d, bf, tf, tw = p["d"], p["bf"], p["tf"], p["tw"]
    weak = _by_name(out["bodies"])["left"]
    assert weak["depth"] == pytest.approx(bf)
    assert weak["flange_thickness"] == pytest.approx((bf - tw) / 2)
    assert weak["flange_width"] == pytest.approx(2 * tf) and weak["web_thickness"] == pytest.approx(d)
    # the strip's plates, as the i_section body integrates them (bodies.py: A and I of its plates)
    t_f, w_f, w_w, depth = weak["flange_thickness"], weak["flange_width"], weak["web_thickness"], weak["depth"]
    area = 2 * w_f * t_f + (depth - 2 * t_f) * w_w
    inertia = (w_f * depth ** 3 - (w_f - w_w) * (depth - 2 * t_f) ** 3) / 12
    assert area == pytest.approx(2 * bf * tf + (d - 2 * tf) * tw, rel=1e-12)
    assert inertia == pytest.approx(2 * tf * bf ** 3 / 12 + (d - 2 * tf) * tw ** 3 / 12, rel=1e-12)
    assert weak["inertia"] == p["Iy"] and weak["area"] == p["A"]
    # the weak strip is narrower than the strong one: the beam frames into its face at bf / 2
    assert _by_name(out["bodies"])["beam"]["start"] == pytest.approx([bf / 2, 3.0])


# -- section forces of an I-section cut -------------------------------------------------------
# a strip along +x whose lattice steps differ along (1.3 / 26 = 0.05 m) and across (0.37 / 7 =
# 0.0529 m: 7.4 rows of 0.05 rounded to 7)
SEC = dict(depth=0.37, flange_width=0.3, flange_thickness=0.03, web_thickness=0.02)
X0, Y0, LEN = 0.3, 0.45, 1.3
CUT_AT = 0.56   # m from the strip's start: the band's edges cut through particle domains (the
                # fractions are not all 0 or 1)


@pytest.fixture(scope="module")
def strip():
    return pmpm.run({
        "particles_per_cell": 2,
        "grid": {"origin": [0.0, 0.0], "cell_size": H, "cells": [20, 9]},
        "materials": {"steel": {"type": "linear_elastic", "E": 2e8, "nu": 0.3, "density": 7850.0}},
        "bodies": [{"name": "member", "shape": "i_section", "material": "steel", "start": [X0, Y0],
                    "end": [X0 + LEN, Y0], **SEC}],
        "boundary": [{"name": "clamp", "type": "fixed", "lower": [0.0, 0.0], "upper": [X0, 0.9]}],
        "loads": {"gravity": [2.0, -9.81],
                  "forces": [{"name": "tip", "lower": [X0 + LEN - 0.1, Y0 - 0.2], "upper": [X0 + LEN, Y0 + 0.2],
                              "force": [4e3, -6e3]}]},
        "solver": {"end_time": 0.012, "cfl": 0.5},
        "output": {"interval": 0.004, "history_interval": 0.001, "fields": ["x", "x0", "stress", "vol"],
                   "section": [{"name": "cut", "body": "member", "position": CUT_AT}]},
    }, dataframes=False)


def test_i_section_cut_forces_are_the_band_integral(strip):
    """N, V, M of the cut at every frame against the band mean written here: particles chosen by
    their initial position, each with the fraction of its domain along the member (its lattice
    step, measured from the initial positions themselves) inside the band of two cells centred
    on the cut, N = sum phi V sxx / b, V = sum phi V sxy / b (the member's +y side pushing up on
    the end side: V = -e.(sigma n) with n = +x, e = +y), M = sum phi V sxx eta / b with eta the
    current distance from the cut's line along +y; docs: pmpm/results/sections.py. The strip's
    steps along (0.05) and across (0.0529) differ, so a spacing from the wrong lattice direction
    gives other weights and a different sum. Tolerance: round-off (1e-9 of the scale)."""
    res = strip
    x0 = res.frames["x0"][0]
    along = np.diff(np.unique(np.round(x0[:, 0], 12)))
    across = np.diff(np.unique(np.round(x0[:, 1], 12)))
    step = along.mean()
    assert np.ptp(along) < 1e-9 and abs(step - across.mean()) > 0.002   # not square
    b = 2 * H
    c = np.array([X0 + CUT_AT, Y0])
    s = x0[:, 0] - c[0]
    phi = np.clip(np.minimum(s + step / 2, b / 2) - np.maximum(s - step / 2, -b / 2), 0, None) / step
    assert np.any((phi > 0) & (phi < 1))   # partial weights at the band's edges
    cut = res.sections["cut"]
    ct = np.asarray(cut["time"])
    checked = 0
    for k, t in enumerate(res.frame_times):
        row = np.flatnonzero(np.isclose(ct, t, rtol=0, atol=1e-9))
        if not len(row):
            continue
        sig, vol, x = res.frames["stress"][k], res.frames["vol"][k], res.frames["x"][k]
        w = phi * vol / b
        eta = x[:, 1] - c[1]
        want = np.array([np.dot(w, sig[:, 0]), -np.dot(w, sig[:, 2]), np.dot(w * eta, sig[:, 0])])
        got = np.array([cut["N"][row[0]], cut["V"][row[0]], cut["M"][row[0]]])
        scale = np.abs(want).max() + 1.0
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale)
        checked += 1
    assert checked >= 3
    # the cut carries what the loads put on it: a real moment and shear to compare
    assert abs(cut["M"][-1]) > 100.0 and abs(cut["V"][-1]) > 100.0


# -- supports attached to a body's face ---------------------------------------------------------
def _cross(d, f):
    return d[..., 0] * f[..., 1] - d[..., 1] * f[..., 0]


def test_held_faces_react_with_minus_the_loads_and_their_moment():
    """A strip one particle thick, its left face held by a support attached to the body (so every
    particle is held and nothing moves), under gravity with a horizontal part and a sideways
    force: each interval the constraint impulses carry exactly the loads, R = -(W + F), and their
    moment about a point off the origin and off the strip is M = -[(x_G - p) x W + (x_F - p) x F]
    (x_G the mass centroid, x_F the mass centroid of the force's particles: a set force is shared
    by mass), summed here by hand from the particle fields. The projection makes the nodal
    velocities zero exactly (the loads' nodal accelerations are in the range of N^T: lambda_p =
    m_p a_p dt), so the impulse moment is the loads' moment by the B-splines' linear
    reproduction. Tolerance: round-off of the projection's solve (1e-9 of the scale)."""
    g = np.array([2.7, -9.81])
    F = np.array([-35.0, 12.0])
    p_m = np.array([3.05, -1.7])
    lo, hi = np.array([2.0, -1.9]), np.array([2.05, -1.2])        # one particle column (h / 2 wide)
    box = ([1.9, -1.45], [2.1, -1.2])
    res = pmpm.run({
        "particles_per_cell": 2,
        "grid": {"origin": [1.4, -2.2], "cell_size": H, "cells": [14, 14]},
        "materials": {"m": {"type": "linear_elastic", "E": 1e5, "nu": 0.3, "density": 500.0}},
        "bodies": [{"name": "strip", "shape": "rectangle", "material": "m", "lower": list(lo), "upper": list(hi)}],
        "boundary": [{"name": "held", "type": "fixed", "body": "strip", "face": "left", "reaction": True,
                      "moment_about": list(p_m)}],
        "loads": {"gravity": list(g), "forces": [{"name": "push", "lower": box[0], "upper": box[1], "force": list(F)}]},
        "solver": {"end_time": 0.02, "cfl": 0.5},
        "output": {"interval": 0.02, "history_interval": 0.005, "fields": ["x", "x0", "v", "m"]},
    }, dataframes=False)
    m, x = res.frames["m"][-1], res.frames["x"][-1]
    np.testing.assert_allclose(x, res.frames["x0"][-1], rtol=0, atol=1e-12)   # held: nothing moved
    in_box = (x[:, 0] >= box[0][0]) & (x[:, 0] <= box[1][0]) & (x[:, 1] >= box[0][1]) & (x[:, 1] <= box[1][1])
    W = m.sum() * g
    x_G = (m[:, None] * x).sum(axis=0) / m.sum()
    x_F = (m[in_box, None] * x[in_box]).sum(axis=0) / m[in_box].sum()
    want = np.concatenate([-(W + F), [-(_cross(x_G - p_m, W) + _cross(x_F - p_m, F))]])
    R = res.reactions["held"]
    got = np.column_stack([R["Rx"], R["Ry"], R["M"]])[1:]   # every interval after the start
    assert len(got) >= 3
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=0, atol=1e-9 * scale)
    assert abs(want[0]) > 10.0 and abs(want[2]) > 10.0


def test_a_held_face_under_a_moving_body_reacts_with_its_momentum_balance():
    """A cantilever held by a support on its left face (the rest free to swing), under gravity
    with a horizontal part and a sideways tip force: FLIP moves momentum between particles and
    grid exactly and internal forces sum to zero, so over each history interval the body's
    momentum changes by the loads' impulse plus the support's, R dt = P(t_k) - P(t_k-1) - (W + F)
    dt, with P = sum m v summed here from the frames (one per interval). The support's impulse is
    both the constraint's on the nodes and the momentum the held particles' velocities lose
    (pmpm/physics/supports.py); each is large here. Tolerance: round-off (1e-9 of the scale)."""
    g = np.array([1.5, -9.81])
    F = np.array([-40.0, -25.0])
    dt_h = 0.004
    res = pmpm.run({
        "particles_per_cell": 2,
        "grid": {"origin": [1.4, -2.2], "cell_size": H, "cells": [16, 10]},
        "materials": {"m": {"type": "linear_elastic", "E": 2e5, "nu": 0.3, "density": 500.0}},
        "bodies": [{"name": "beam", "shape": "rectangle", "material": "m", "lower": [1.85, -1.9], "upper": [2.85, -1.7]}],
        "boundary": [{"name": "held", "type": "fixed", "body": "beam", "face": "left", "reaction": True,
                      "moment_about": [2.0, -1.3]}],
        "loads": {"gravity": list(g), "forces": [{"name": "tip", "lower": [2.75, -1.9], "upper": [2.85, -1.7],
                                                  "force": list(F)}]},
        "solver": {"end_time": 0.04, "cfl": 0.5},
        "output": {"interval": dt_h, "history_interval": dt_h, "fields": ["x", "v", "m"]},
    }, dataframes=False)
    m, v = res.frames["m"], res.frames["v"]
    P = np.einsum("fp,fpd->fd", m, v)
    W = m[0].sum() * g
    R = res.reactions["held"]
    rt = np.asarray(R["time"])
    np.testing.assert_allclose(rt, res.frame_times, rtol=0, atol=1e-12)
    dt = np.diff(res.frame_times)
    want = np.diff(P, axis=0) / dt[:, None] - (W + F)
    got = np.column_stack([R["Rx"], R["Ry"]])[1:]
    scale = np.abs(W + F).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * scale)
    assert np.abs(np.diff(P, axis=0) / dt[:, None]).max() > 0.1 * scale   # the body accelerates
