"""The frame front end: a ``[frame]`` table of nodes, members and supports, expanded into an
ordinary scene (bodies, boundaries, loads, section cuts, tracked points) before it is parsed.

The solver never sees a member: :func:`expand_frame` turns the TOML data of a scene with a
``[frame]`` table into the TOML data of the same scene written with ``[[bodies]]``,
``[[boundary]]``, ``[[loads.forces]]``, ``[[output.section]]`` and ``[[output.track]]`` only
(``pmpm expand case.toml`` writes it out, pmpm.scene.toml_writer). The schema and the rules are
in docs/scenes.md, "Frames"; in short:

* members are horizontal or vertical; each is an I-section strip (``shape = "i_section"``) of
  its section, bending about its strong axis (or ``axis = "weak"``);
* a column (vertical member) runs through the joints: from its lower node (or the top of the
  joint panel below when a column continues under it) to its upper node, up to the top of the
  deepest beam there when no column continues above; a joint panel belongs to the column under
  it. Beams (horizontal members) end at the faces of the deepest column at each node;
* a support acts on the grid node line through its node (which must lie on one): ``fixed``
  on the nodes across the member's end (its depth plus the B-spline reach of two cells),
  ``pinned`` and ``roller`` on the one grid node nearest the member axis; its reaction (Rx,
  Ry, M about the node) is recorded under the node's name;
* a nodal load acts on the particles of the node's panel (column depth by beam depth),
  shared by mass; a member's ``load_per_length`` (N/m, times the node-to-node length) on the
  particles of its clear length, of that member's body only (``body = "<member>"``);
* two section cuts per member, named ``<member>_<node>``, at ``cut_offset`` from each clear
  end; a tracked point per node, named after it;
* a nodal mass is added to the joint panel of the column under the node, split off as its own
  strip of a denser copy of the column's material (``"<material>+<node>"``).
"""
import copy
import logging
import math
from dataclasses import dataclass

from pmpm.errors import ConfigError
from pmpm.scene.sections import closest, lookup
from pmpm.scene.tables import Table
from pmpm.physics.timefunctions import parse_time_function
from pmpm.scene.names import check_name
from pmpm.scene.grid import parse_grid

__all__ = ["expand_frame", "frame_report", "SUPPORT_TYPES", "I_SECTION_KEYS"]
logger = logging.getLogger(__name__)

SUPPORT_TYPES = ("fixed", "pinned", "roller")
#: the keys of an explicit section ([frame.sections.<name>]), as the i_section body takes them
I_SECTION_KEYS = ("depth", "flange_width", "flange_thickness", "web_thickness", "area", "inertia")
#: support nodes reach this many cells beyond the member's depth (the cubic B-spline's support)
REACH_CELLS = 2.0
#: default distance of the end cuts from the members' clear ends, in cells
CUT_OFFSET_CELLS = 3.0


@dataclass
class Member:
    """One member as read from the table; ``lo``/``hi``: its lower/left and upper/right node."""
    name: str
    key: str
    lo: str
    hi: str
    vertical: bool
    material: str
    strip: dict            # i_section keys: depth, flange_width, ... (area, inertia)
    cut_offsets: dict      # node name -> offset from that clear end (m)
    load: tuple            # load per length (N/m), or None
    load_tf: dict


def _node_table(t, tol):
    """Node name -> (x, y), in the table's order; names unique, no two nodes at one point."""
    nodes = {}
    for k, n in enumerate(t.tables("nodes")):
        name = n.string("name")
        at = n.vector("at")
        n.finish()
        if name in nodes:
            raise ConfigError(n.path("name"), f"node name {name!r} is already used")
        for other, p in nodes.items():
            if math.dist(p, at) <= tol:
                raise ConfigError(n.path("at"), f"coincides with node {other!r} at {p}")
        nodes[name] = at
    if not nodes:
        raise ConfigError(t.path("nodes"), "missing: a frame needs [[frame.nodes]]")
    return nodes


def _node_ref(t, key, nodes):
    """A node name read from ``t[key]``; unknown names list the closest ones."""
    name = t.string(key)
    if name not in nodes:
        near = closest(name, list(nodes))
        raise ConfigError(t.path(key), f"no node named {name!r}"
                                       + (f" (closest: {', '.join(near)})" if near else ""))
    return name


def _explicit_sections(t):
    """``[frame.sections.<name>]``: strips given by their dimensions."""
    out = {}
    sec = t.table("sections", None)
    if sec is None:
        return out
    for name in sec.data:
        s = sec.table(name)
        geo = {}
        for k in I_SECTION_KEYS:  # area and inertia optional: then the plates' own
            geo[k] = s.number(k, None, low=0, low_open=True) if k in ("area", "inertia") \
                else s.number(k, low=0, low_open=True)
        s.finish()
        if 2 * geo["flange_thickness"] >= geo["depth"]:
            raise ConfigError(s.path("flange_thickness"), "two flanges must be thinner than the depth")
        out[name] = geo
    return out


def _strip(t, explicit, axis):
    """The i_section keys of a member's section (explicit, else the AISC table)."""
    name = t.string("section")
    if name in explicit:
        if axis == "weak":
            raise ConfigError(t.path("axis"), f"section {name!r} is given by its strip dimensions: "
                                              f"give the weak-axis strip there instead")
        return {k: v for k, v in explicit[name].items() if v is not None}
    p = lookup(name, t.path("section"))
    if axis == "strong":
        return {"depth": p["d"], "flange_width": p["bf"], "flange_thickness": p["tf"],
                "web_thickness": p["tw"], "area": p["A"], "inertia": p["Ix"]}
    # bending about the weak axis: across the strip (depth bf) the section is two flange
    # tips (thickness 2 tf) either side of the web band (width tw, thickness d)
    return {"depth": p["bf"], "flange_width": 2 * p["tf"], "flange_thickness": (p["bf"] - p["tw"]) / 2,
            "web_thickness": p["d"], "area": p["A"], "inertia": p["Iy"]}


def _member_table(t, nodes, explicit, materials, default_material, cut_offset, tol):
    """The members, each oriented lower/left to upper/right, with its strip and cut offsets."""
    members = []
    for k, m in enumerate(t.tables("members")):
        name = m.string("name")
        a, b = _node_ref(m, "from", nodes), _node_ref(m, "to", nodes)
        if a == b or math.dist(nodes[a], nodes[b]) <= tol:
            raise ConfigError(m.path("to"), f"member {name!r} joins coincident nodes ({a!r} and {b!r})")
        (xa, ya), (xb, yb) = nodes[a], nodes[b]
        if abs(xa - xb) > tol and abs(ya - yb) > tol:
            raise ConfigError(m.path("to"), f"member {name!r} is inclined: only horizontal and vertical "
                                            f"members are expanded (give braces as [[bodies]])")
        vertical = abs(xa - xb) <= tol
        lo, hi = (a, b) if (ya < yb if vertical else xa < xb) else (b, a)
        material = m.string("material", default_material)
        if material is None:
            raise ConfigError(m.path("material"), "missing (or give frame.material)")
        if material not in materials:
            raise ConfigError(m.path("material"), f"no material {material!r} under [materials]")
        axis = m.string("axis", "strong", choices=("strong", "weak"))
        strip = _strip(m, explicit, axis)
        offsets = m.raw("cut_offsets", None)
        if offsets is None:
            offsets = [cut_offset, cut_offset]
        elif (not isinstance(offsets, list) or len(offsets) != 2
              or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                         and v >= 0 for v in offsets)):
            raise ConfigError(m.path("cut_offsets"), "must be two distances >= 0 (m): at from, at to")
        load = m.vector("load_per_length", None)
        tf = m.table("load_time_function", None)
        load_tf = parse_time_function(tf if tf is not None else Table({"type": "step"}, m.path("load_time_function")))
        m.finish()
        if any(x.name == name for x in members):
            raise ConfigError(m.path("name"), f"member name {name!r} is already used")
        members.append(Member(name=name, key=m.key, lo=lo, hi=hi, vertical=vertical, material=material,
                              strip=strip, cut_offsets={a: float(offsets[0]), b: float(offsets[1])},
                              load=load, load_tf=load_tf))
    if not members:
        raise ConfigError(t.path("members"), "missing: a frame needs [[frame.members]]")
    return members


class _Joints:
    """Depths at each node: of the deepest column and beam meeting there, and which continue."""

    def __init__(self, nodes, members):
        self.col = {n: 0.0 for n in nodes}
        self.beam = {n: 0.0 for n in nodes}
        self.below = {n: False for n in nodes}   # a column ends here from below
        self.above = {n: False for n in nodes}   # a column starts here upwards
        for m in members:
            d = m.strip["depth"]
            for n in (m.lo, m.hi):
                target = self.col if m.vertical else self.beam
                target[n] = max(target[n], d)
            if m.vertical:
                self.below[m.hi] = True
                self.above[m.lo] = True

    def panel(self, node, at):
        """Box of the node's joint panel: column depth by beam depth (a member's depth
        both ways where only one kind meets)."""
        dx = self.col[node] or self.beam[node]
        dy = self.beam[node] or self.col[node]
        return (at[0] - dx / 2, at[1] - dy / 2), (at[0] + dx / 2, at[1] + dy / 2)


def _column_extent(m, nodes, joints):
    """(body bottom, body top, clear bottom, clear top) of a column."""
    y_lo, y_hi = nodes[m.lo][1], nodes[m.hi][1]
    half_lo, half_hi = joints.beam[m.lo] / 2, joints.beam[m.hi] / 2
    # a joint panel belongs to the column under it; a column standing on a beam starts below it
    bottom = y_lo + half_lo if joints.below[m.lo] else y_lo - half_lo
    top = y_hi + half_hi
    return bottom, top, y_lo + half_lo, y_hi - half_hi


def _beam_extent(m, nodes, joints):
    x_lo, x_hi = nodes[m.lo][0] + joints.col[m.lo] / 2, nodes[m.hi][0] - joints.col[m.hi] / 2
    return x_lo, x_hi, x_lo, x_hi


def _geometry(members, nodes, joints):
    """Per member: its body (start, end, along-axis extent) and its clear ends."""
    out = []
    for m in members:
        ext = (_column_extent if m.vertical else _beam_extent)(m, nodes, joints)
        start, end, clear_lo, clear_hi = ext
        if not clear_hi > clear_lo:
            raise ConfigError(m.key, f"member {m.name!r} has no clear length between the joint "
                                     f"panels at its ends ({clear_hi - clear_lo:.4g} m)")
        axis = nodes[m.lo][0] if m.vertical else nodes[m.lo][1]
        if m.vertical:
            s, e = (axis, start), (axis, end)
        else:
            s, e = (start, axis), (end, axis)
        half = m.strip["depth"] / 2
        box = ((s[0] - half, s[1]), (e[0] + half, e[1])) if m.vertical else ((s[0], s[1] - half), (e[0], e[1] + half))
        out.append({"start": s, "end": e, "box": box, "clear": (clear_lo, clear_hi), "origin": start})
    return out


def _check_geometry(members, geo, grid, tol):
    """Strips inside the grid; no two overlapping (members joined at a node touch at most)."""
    g_lo = grid.origin
    g_hi = tuple(o + grid.cell_size * n for o, n in zip(grid.origin, grid.cells))
    for m, g in zip(members, geo):
        lo, hi = g["box"]
        if any(lo[d] < g_lo[d] - tol or hi[d] > g_hi[d] + tol for d in range(2)):
            raise ConfigError(m.key, f"member {m.name!r} lies outside the grid (its strip spans "
                                     f"[{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}], the grid "
                                     f"[{g_lo[0]:g}, {g_hi[0]:g}] x [{g_lo[1]:g}, {g_hi[1]:g}])")
    for i in range(len(members)):
        for j in range(i):
            (a0, a1), (b0, b1) = geo[i]["box"], geo[j]["box"]
            if all(min(a1[d], b1[d]) - max(a0[d], b0[d]) > tol for d in range(2)):
                shared = {members[i].lo, members[i].hi} & {members[j].lo, members[j].hi}
                why = (f"and both leave node {sorted(shared)[0]!r} the same way" if shared
                       else "without a node joining them")
                raise ConfigError(members[i].key, f"member {members[i].name!r} overlaps member "
                                                  f"{members[j].name!r} {why}")


def _supports(t, nodes, members, joints, grid):
    """[[boundary]] tables of the supports (reactions recorded under the node's name)."""
    out = []
    h = grid.cell_size
    seen = set()
    for s in t.tables("supports"):
        node = _node_ref(s, "node", nodes)
        kind = s.string("type", choices=SUPPORT_TYPES)
        free = s.string("direction", "x", choices=("x", "y")) if kind == "roller" else None
        s.finish()
        if node in seen:
            raise ConfigError(s.path("node"), f"node {node!r} has a support already")
        seen.add(node)
        at = nodes[node]
        ends = [m for m in members if node in (m.lo, m.hi)]
        vertical = any(m.vertical for m in ends)
        depth = joints.col[node] if vertical else joints.beam[node]
        # the support line: the grid node line through the node across the member's end
        across, line = (0, 1) if vertical else (1, 0)
        k_line = (at[line] - grid.origin[line]) / h
        if abs(k_line - round(k_line)) > 1e-6:
            raise ConfigError(s.path("node"), f"support node {node!r} at {'xy'[line]} = {at[line]:g} is not on a "
                                              f"grid node line ({'xy'[line]} = origin + k * cell_size)")
        lower, upper = list(at), list(at)
        if kind == "fixed":
            lower[across] -= depth / 2 + REACH_CELLS * h
            upper[across] += depth / 2 + REACH_CELLS * h
        else:  # one grid node, the nearest to the member axis
            k_node = round((at[across] - grid.origin[across]) / h)
            lower[across] = upper[across] = grid.origin[across] + k_node * h
        bc_type = {"fixed": "fixed", "pinned": "fixed", "roller": f"roller_{free}"}[kind]
        out.append({"name": node, "type": bc_type, "lower": lower, "upper": upper,
                    "moment_about": list(at), "reaction": True})
    return out


def _nodal_loads(t, nodes, joints, tol):
    """A nodal load on the particles of the node's panel (a second load on a node gets its index)."""
    out = []
    for k, f in enumerate(t.tables("loads")):
        node = _node_ref(f, "node", nodes)
        force = f.vector("force")
        tf = f.table("time_function", None)
        time_function = parse_time_function(tf if tf is not None else Table({"type": "step"}, f.path("time_function")))
        f.finish()
        lo, hi = joints.panel(node, nodes[node])
        name = f"{node}_load" if not any(o["name"] == f"{node}_load" for o in out) else f"{node}_load{k}"
        out.append({"name": name,
                    "lower": [lo[0] - tol, lo[1] - tol], "upper": [hi[0] + tol, hi[1] + tol],
                    "force": list(force), "time_function": time_function})
    return out


def _member_loads(members, geo, nodes, tol):
    """A member's load per length times its node-to-node length, on its clear length's particles."""
    out = []
    for m, g in zip(members, geo):
        if m.load is None:
            continue
        length = math.dist(nodes[m.lo], nodes[m.hi])
        (x0, y0), (x1, y1) = g["box"]
        c0, c1 = g["clear"]
        if m.vertical:
            y0, y1 = c0, c1
        # its member's particles only (`body`: never a neighbour the box touches), strictly
        # inside the clear part: the panels' particles belong to the nodal loads
        out.append({"name": f"{m.name}_line_load", "body": m.name,
                    "lower": [x0 + tol, y0 + tol], "upper": [x1 - tol, y1 - tol],
                    "force": [m.load[0] * length, m.load[1] * length], "time_function": m.load_tf})
    return out


def _nodal_masses(t, nodes, members, joints, bodies, materials):
    """``[[frame.masses]]``: a lumped mass at a node becomes density. The joint panel of the
    column under the node (the column over the beam depth) is split off as its own strip, of a
    copy of the column's material whose density adds the mass to the panel's steel; the rest
    of the column stays as it was. Returns the bodies and the derived materials
    (``"<material>+<node>"``)."""
    tables = t.tables("masses")
    derived = {}
    for entry in tables:
        node = _node_ref(entry, "node", nodes)
        mass = entry.number("mass", low=0, low_open=True)
        entry.finish()
        below = [i for i, m in enumerate(members) if m.vertical and m.hi == node]
        if not below:
            raise ConfigError(entry.path("node"), f"a nodal mass needs a column under node {node!r} "
                                                  f"(it is added to that column's joint panel)")
        i = below[0]
        m, body = members[i], bodies[i]
        label = f"{m.material}+{node}"
        if label in derived:
            raise ConfigError(entry.path("node"), f"node {node!r} has a mass already")
        y = nodes[node][1]
        half = (joints.beam[node] or m.strip["depth"]) / 2
        lo_y, hi_y = y - half, body["end"][1]   # the column's body ends at the panel's top
        sp = m.strip
        area = sp.get("area") or (2 * sp["flange_width"] * sp["flange_thickness"]
                                  + (sp["depth"] - 2 * sp["flange_thickness"]) * sp["web_thickness"])
        rho = materials[m.material].get("density") if isinstance(materials[m.material], dict) else None
        if not isinstance(rho, (int, float)) or isinstance(rho, bool) or not rho > 0:
            raise ConfigError(f"materials.{m.material}.density", "a positive number is needed for the "
                                                                  "frame's nodal masses")
        steel = area * (hi_y - lo_y) * rho
        derived[label] = dict(materials[m.material], density=rho * (1 + mass / steel))
        x = body["start"][0]
        bodies[i] = dict(body, end=[x, lo_y])   # the member's body keeps its name and its start
        bodies.append(dict(body, name=f"{m.name}_panel_{node}", material=label, start=[x, lo_y], end=[x, hi_y]))
    return bodies, derived


def _cuts(members, geo, nodes, tol):
    """Two cuts per member, ``<member>_<node>``, at its offsets from the clear ends."""
    out = []
    for m, g in zip(members, geo):
        c0, c1 = g["clear"]
        at_lo, at_hi = c0 + m.cut_offsets[m.lo], c1 - m.cut_offsets[m.hi]
        if not at_lo < at_hi - tol:
            raise ConfigError(f"{m.key}.cut_offsets", f"the end cuts of member {m.name!r} cross "
                                                      f"(clear length {c1 - c0:.4g} m)")
        for node, at in ((m.lo, at_lo), (m.hi, at_hi)):
            out.append({"name": f"{m.name}_{node}", "body": m.name, "position": at - g["origin"]})
    return out


def _check_names(expanded, key):
    """Derived names must be unique where the scene needs them so (files, lookups)."""
    for group, what in (("output.section", "section cut"), ("output.track", "tracked point"),
                        ("boundary", "support")):
        head, _, tail = group.partition(".")
        items = expanded.get(head, {}).get(tail, []) if tail else expanded.get(head, [])
        names = [it["name"] for it in items if "name" in it]
        for n in names:
            try:
                check_name(n, key, what)
            except ConfigError as exc:
                raise ConfigError(key, f"derived {what} name {n!r} is not a valid file name "
                                       f"({exc.reason}): rename the node or member") from None
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(key, f"two {what}s are named {dup[0]!r} (a derived name meets another: "
                                   f"rename a node or member)")


def _read(data):
    """Grid and frame tables of scene ``data`` (the grid as the scene parses it)."""
    if not isinstance(data.get("frame"), dict):
        raise ConfigError("frame", "must be a table")
    grid = parse_grid(Table(data.get("grid", {}), "grid"))
    materials = data.get("materials", {})
    return grid, Table(data["frame"], "frame"), materials if isinstance(materials, dict) else {}


def expand_frame(data):
    """The ordinary scene data of scene ``data`` with a ``[frame]`` table (a deep copy;
    ``data`` itself is not changed; data without ``[frame]`` is returned as is).

    Parameters
    ----------
    data : dict
        TOML data of a scene.

    Returns
    -------
    dict
        The same scene with the frame's bodies first in ``bodies``, its supports first in
        ``boundary``, its loads first in ``loads.forces``, its cuts and tracked points first in
        ``output.section`` and ``output.track``, and no ``frame`` key.

    Raises
    ------
    ConfigError
        Bad frame input, naming the ``frame.*`` entry and the reason.
    """
    if "frame" not in data:
        return data
    _check_lists_of_tables(data)  # before any of them is iterated or merged with the frame's
    grid, t, materials = _read(data)
    tol = 1e-6 * grid.cell_size
    default_material = t.string("material", None)
    cut_offset = t.number("cut_offset", CUT_OFFSET_CELLS * grid.cell_size, low=0)
    nodes = _node_table(t, tol)
    explicit = _explicit_sections(t)
    members = _member_table(t, nodes, explicit, materials, default_material, cut_offset, tol)
    reached = {n for m in members for n in (m.lo, m.hi)}
    for k, name in enumerate(nodes):
        if name not in reached:
            raise ConfigError(f"frame.nodes[{k}]", f"no member reaches node {name!r}")
    joints = _Joints(nodes, members)
    geo = _geometry(members, nodes, joints)
    _check_geometry(members, geo, grid, tol)
    supports = _supports(t, nodes, members, joints, grid)
    forces = _nodal_loads(t, nodes, joints, tol) + _member_loads(members, geo, nodes, tol)
    bodies = [{"name": m.name, "shape": "i_section", "material": m.material,
               "start": list(g["start"]), "end": list(g["end"]), **m.strip} for m, g in zip(members, geo)]
    bodies, derived = _nodal_masses(t, nodes, members, joints, bodies, materials)
    t.finish()
    tracks = [{"name": n, "point": list(p)} for n, p in nodes.items()]
    out = copy.deepcopy(data)
    del out["frame"]
    if derived:
        out["materials"] = dict(out["materials"], **derived)
    out["bodies"] = bodies + list(out.get("bodies", []))
    out["boundary"] = supports + list(out.get("boundary", []))
    if forces:
        loads = out.setdefault("loads", {})
        if not isinstance(loads, dict):
            raise ConfigError("loads", "must be a table")
        loads["forces"] = forces + list(loads.get("forces", []))
    output = out.setdefault("output", {})
    if not isinstance(output, dict):
        raise ConfigError("output", "must be a table")
    output["section"] = _cuts(members, geo, nodes, tol) + list(output.get("section", []))
    output["track"] = tracks + list(output.get("track", []))
    _check_names(out, "frame")
    return out


#: the scene's own lists the frame's generated entries are put in front of
MERGED_LISTS = ("bodies", "boundary", "loads.forces", "output.section", "output.track")


def _check_lists_of_tables(data):
    """Each of :data:`MERGED_LISTS` the scene gives must be a list of tables (``[[bodies]]``):
    a number, a boolean, a string or a list holding one is refused naming the entry."""
    for key in MERGED_LISTS:
        node = data
        for part in key.split(".")[:-1]:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or key.split(".")[-1] not in node:
            continue
        value = node[key.split(".")[-1]]
        if not isinstance(value, list):
            raise ConfigError(key, f"must be a list of tables ([[{key}]]), not {type(value).__name__}")
        for k, item in enumerate(value):
            if not isinstance(item, dict):
                raise ConfigError(f"{key}[{k}]", f"must be a table ([[{key}]]), not {type(item).__name__}")


def frame_report(data):
    """Lines saying what the ``[frame]`` of scene ``data`` generates (``pmpm case.toml --check``)."""
    if "frame" not in data:
        return []
    out = expand_frame(data)
    nb, ns = len(out["bodies"]) - len(data.get("bodies", [])), len(out["boundary"]) - len(data.get("boundary", []))
    nf = len(out.get("loads", {}).get("forces", [])) - len(data.get("loads", {}).get("forces", []))
    old = data.get("output", {})
    nc = len(out["output"]["section"]) - len(old.get("section", []))
    nt = len(out["output"]["track"]) - len(old.get("track", []))
    names = lambda items, n: ", ".join(i["name"] for i in items[:n]) or "none"  # noqa: E731
    return [f"frame: {len(data['frame'].get('nodes', []))} nodes, {len(data['frame'].get('members', []))} members",
            f"  {nb} bodies (i_section strips): {names(out['bodies'], nb)}",
            f"  {ns} supports with reactions: {names(out['boundary'], ns)}",
            f"  {nf} loads: {names(out.get('loads', {}).get('forces', []), nf)}",
            f"  {nc} section cuts: {names(out['output']['section'], nc)}",
            f"  {nt} tracked points: {names(out['output']['track'], nt)}"] + (
        [f"  {len(data['frame']['masses'])} nodal masses: on the joint panels of "
         + ", ".join(m["node"] for m in data["frame"]["masses"])] if data["frame"].get("masses") else [])
