"""Bad scenes, files and checkpoints through the real command line (issue 10).

Every case runs ``python -m pmpm.cli`` in a subprocess, in its own directory, with a timeout (a
hang fails the case instead of blocking the suite), and asserts pmpm's promise: the exit code,
exactly one line on standard error that starts ``pmpm: error:``, no traceback anywhere, and no
file written (the directory tree is the same before and after). Errors found while the scene is
parsed are checked with ``--check`` (no particles, no kernels: about a second each); the others
(memory per rank, particle placement, restart) with a real start, which stops before any
output is written.
"""
import hashlib
import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXIT_BAD_INPUT, EXIT_WRITE_FAILED = 2, 4
#: a case is a hang if it takes longer than this (a refusal takes one to a few seconds)
TIMEOUT = 60

BASE = """\
[grid]
cell_size = 0.5
cells = [8, 4]

[materials.steel]
type = "linear_elastic"
E = 100.0
nu = 0.3
density = 1.0

[[bodies]]
name = "block"
shape = "rectangle"
material = "steel"
lower = [0.0, 0.0]
upper = [2.0, 1.0]
velocity = [0.1, 0.0]

[solver]
end_time = 0.01
"""

SHELL_ESCAPE = ("[c for c in ().__class__.__base__.__subclasses__() if c.__name__ == '_wrap_close'][0]"
                ".__init__.__globals__['system']('touch pwned') * 0 + 0.1")


def sub(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new, 1)
    return edit


def add(extra):
    return lambda text: text + "\n" + extra + "\n"


def top(extra):
    return lambda text: extra + "\n" + text


def velocity(expr):
    return sub("velocity = [0.1, 0.0]", f"velocity = [{json.dumps(expr)}, 0.0]")


def body(extra):
    return add("[[bodies]]\nmaterial = \"steel\"\n" + extra)


def ground(record_name, fmt=None):
    return add('[[boundary]]\ntype = "fixed"\nlower = [0.0, 0.0]\nupper = [4.0, 0.0]\n'
               f'[loads.ground_motion]\nfile = "{record_name}"' + (f'\nformat = "{fmt}"' if fmt else ""))


def stop(keys, track="tip"):
    """A tracked point ``tip`` and one ``[[stop]]`` table on it with ``keys``."""
    return add(f'[[output.track]]\nname = "tip"\npoint = [2.0, 0.5]\n[[stop]]\ntrack = "{track}"\n{keys}')



def frame(nodes=None, members=None, supports=None, extra=""):
    """A [frame] beside the block: a W12x120 column at x = 3 on the grid's lower edge; each
    argument replaces that part (TOML text)."""
    nodes = nodes if nodes is not None else ('[[frame.nodes]]\nname = "A"\nat = [3.0, 0.0]\n'
                                             '[[frame.nodes]]\nname = "B"\nat = [3.0, 1.5]\n')
    members = members if members is not None else ('[[frame.members]]\nname = "col"\nfrom = "A"\n'
                                                   'to = "B"\nsection = "W12x120"\n')
    supports = supports if supports is not None else '[[frame.supports]]\nnode = "A"\ntype = "fixed"\n'
    return add('[frame]\nmaterial = "steel"\n' + extra + nodes + members + supports)


def node(name, x, y):
    return f'[[frame.nodes]]\nname = "{name}"\nat = [{x}, {y}]\n'


def member(name, a, b, section="W12x120"):
    return f'[[frame.members]]\nname = "{name}"\nfrom = "{a}"\nto = "{b}"\nsection = "{section}"\n'


MESH_HEAD = "# vtk DataFile Version 4.2\nmesh\nASCII\nDATASET UNSTRUCTURED_GRID\n"
MESH_MISSING_NODE = (MESH_HEAD + "POINTS 4 double\n0.5 0.5 0\n1.5 0.5 0\n1.5 1.5 0\n0.5 1.5 0\n"
                     "CELLS 2 8\n3 0 1 2\n3 0 2 9\nCELL_TYPES 2\n5\n5\n")
MESH_COINCIDENT = (MESH_HEAD + "POINTS 4 double\n0.5 0.5 0\n1.5 0.5 0\n1.5 1.5 0\n1.5 1.5 0\n"
                   "CELLS 2 8\n3 0 1 2\n3 0 2 3\nCELL_TYPES 2\n5\n5\n")
MESH_BODY = sub('shape = "rectangle"\nmaterial = "steel"\nlower = [0.0, 0.0]\nupper = [2.0, 1.0]',
                'shape = "mesh"\nmaterial = "steel"\nfile = "part.vtk"')
SECRET = "root:SECRET-HASH-DO-NOT-PRINT:19000:0:99999:7:::"
AT2_HEAD = "PEER NGA STRONG MOTION DATABASE RECORD\nTEST 1999\nACCELERATION TIME SERIES IN UNITS OF G\n"

#: id -> (edit of BASE, extra files {name: str | bytes}, extra args, exit code, the error line
#: must contain); args "--check" for parse-time errors, [] for those found at the start of a run
CASES = {
    # 1. code in expressions (the escape runs 'touch pwned' if anything evaluates it)
    "escape-shell": (velocity(SHELL_ESCAPE), {}, ["--check"], 2, "bodies[0].velocity: expression refused"),
    "escape-shell-run": (velocity(SHELL_ESCAPE), {}, [], 2, "bodies[0].velocity: expression refused"),
    "escape-in-variant": (add(f'[variants.v]\n"bodies.0.velocity" = [{json.dumps(SHELL_ESCAPE)}, 0.0]'),
                          {}, ["--check"], 2, "bodies[0].velocity: expression refused"),
    "escape-import": (velocity("__import__('os').system('touch pwned')"), {}, ["--check"], 2, "expression refused"),
    "escape-dunder": (velocity("().__class__.__bases__"), {}, ["--check"], 2, "expression refused"),
    "escape-open": (velocity("open('pwned', 'w')"), {}, ["--check"], 2, "cannot call 'open'"),
    "escape-lambda": (velocity("(lambda: 0)()"), {}, ["--check"], 2, "expression refused"),
    "escape-attribute": (velocity("x.real"), {}, ["--check"], 2, "expression refused"),
    "escape-string": (velocity("'a' * 10"), {}, ["--check"], 2, "expression refused"),
    "hang-power-tower": (velocity("10**10**10"), {}, ["--check"], 2, "exponent of ** must be a number"),
    "hang-power-tower-run": (velocity("9**9**9**9"), {}, [], 2, "exponent of ** must be a number"),
    "power-too-large": (velocity("x**1000"), {}, ["--check"], 2, "too large"),
    "power-variable": (velocity("2**x"), {}, ["--check"], 2, "must be a number"),
    "constant-overflow": (velocity("1e400"), {}, ["--check"], 2, "not finite"),
    "expr-division-by-zero": (velocity("x/0"), {}, ["--check"], 2, "bodies[0].velocity: expression 'x/0' is not finite"),
    "expr-nan": (velocity("sqrt(-1-x)"), {}, ["--check"], 2, "is not finite"),
    "expr-overflow": (velocity("exp(1000*x)"), {}, ["--check"], 2, "is not finite"),
    "expr-unknown-name": (velocity("0.1*sin(z)"), {}, ["--check"], 2, "unknown name 'z'"),
    "expr-syntax": (velocity("0.1 *"), {}, ["--check"], 2, "not valid arithmetic syntax"),
    "expr-too-long": (velocity("x+" * 300 + "x"), {}, ["--check"], 2, "longer than 500"),
    "expr-keyword": (velocity("sin(x=1)"), {}, ["--check"], 2, "no keyword"),
    "velocity-not-list": (sub("velocity = [0.1, 0.0]", "velocity = 0.1"), {}, ["--check"], 2, "bodies[0].velocity"),
    # supports (issue 20): a box that selects no grid node, and a face held twice
    "support-box-outside": (add('[[boundary]]\nname = "floor"\ntype = "fixed"\nlower = [0.0, -1.0]\nupper = [4.0, -0.5]'),
                            {}, [], 2, "boundary[0]: box selects no grid node"),
    "support-holds-nothing": (add('[[boundary]]\nname = "post"\ntype = "fixed"\nlower = [3.5, 1.5]\nupper = [3.5, 1.5]'),
                              {}, [], 2, "boundary[0]: box holds nothing"),
    "support-overridden": (add('[[boundary]]\nname = "roller"\ntype = "roller_x"\nbody = "block"\nface = "left"\n'
                               '[[boundary]]\nname = "clamp"\ntype = "fixed"\nbody = "block"\nface = "left"'),
                           {}, [], 2, "boundary[0]: holds nothing"),
    # 2. names that become file names
    "variant-traversal": (add('[variants."/../../../escaped"]\n"solver.cfl" = 0.4'), {}, [], 2,
                          "case.toml: variants: variant name '/../../../escaped'"),
    "variant-parent": (add('[variants."../victim"]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "variant name"),
    "variant-empty": (add('[variants.""]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "must not be empty"),
    "variant-reserved": (add('[variants.CON]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "reserved name"),
    "variant-space": (add('[variants."a b"]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "may hold only"),
    "variant-dots": (add('[variants."a..b"]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "'..'"),
    "variant-hidden": (add('[variants.".h5"]\n"solver.cfl" = 0.4'), {}, ["--check"], 2, "may hold only"),
    "track-separator": (add('[[output.track]]\nname = "a/b"\npoint = [1.0, 0.5]'), {}, ["--check"], 2,
                        "output.track[0].name: track name 'a/b'"),
    "track-time": (add('[[output.track]]\nname = "time"\npoint = [1.0, 0.5]'), {}, ["--check"], 2, "reserved"),
    "track-empty": (add('[[output.track]]\nname = ""\npoint = [1.0, 0.5]'), {}, ["--check"], 2, "must not be empty"),
    "track-dotdot": (add('[[output.track]]\nname = ".."\npoint = [1.0, 0.5]'), {}, ["--check"], 2, "track name"),
    "track-case-clash": (add('[[output.track]]\nname = "tip"\npoint = [1.0, 0.5]\n'
                             '[[output.track]]\nname = "TIP"\npoint = [1.5, 0.5]'), {}, ["--check"], 2,
                         "gives the file"),
    "track-variant-clash": (add('[[output.track]]\nname = "b"\npoint = [1.0, 0.5]\n'
                                '[[output.track]]\nname = "a_history_b"\npoint = [1.5, 0.5]\n'
                                '[variants.x_history_a]\n"solver.cfl" = 0.4\n[variants.x]\n"solver.cfl" = 0.3'),
                            {}, ["--check"], 2, "gives the file 'case_x_history_a_history_b.csv'"),
    "output-directory-empty": (add('[output]\ndirectory = ""'), {}, ["--check"], 2, "output.directory: must be"),
    "output-directory-is-file": (add('[output]\ndirectory = "afile"'), {"afile": "x"}, ["--check"], 2,
                                 "is not a directory"),
    "output-directory-below-file": (add('[output]\ndirectory = "afile/sub"'), {"afile": "x"}, ["--check"], 2,
                                    "lies below a file"),
    "output-directory-nul": (add('[output]\ndirectory = "a\\u0000b"'), {}, ["--check"], 2, "output.directory"),
    # 3. resources: memory per rank, integer range, grid extent
    "cells-1e9": (sub("cells = [8, 4]", "cells = [1000000000, 1000000000]"), {}, ["--check"], 2,
                  "grid.cells: a rank would need about"),
    "cells-20000": (sub("cells = [8, 4]", "cells = [20000, 20000]"), {}, [], 2, "grid.cells: a rank would need"),
    "cells-100000": (sub("cells = [8, 4]", "cells = [100000, 100000]"), {}, [], 2, "grid.cells: a rank would need"),
    "cells-int64-max": (sub("cells = [8, 4]", "cells = [9223372036854775807, 20]"), {}, ["--check"], 2,
                        "grid.cells: at most"),
    "cell-size-overflow": (sub("cell_size = 0.5", "cell_size = 1e308"), {}, ["--check"], 2,
                           "grid.cells: the grid's extent"),
    "cell-size-underflow": (sub("cell_size = 0.5", "cell_size = 1e-12\norigin = [1e6, 0.0]"), {}, ["--check"], 2,
                            "grid.cell_size: too small"),
    # 4. time steps
    "density-denormal": (sub("density = 1.0", "density = 1e-320"), {}, ["--check"], 2,
                         "materials.steel: wave speed"),
    "density-denormal-run": (sub("density = 1.0", "density = 1e-320"), {}, [], 2, "materials.steel: wave speed"),
    "E-huge": (sub("E = 100.0", "E = 1e300"), {}, ["--check"], 2, "solver.max_estimated_steps"),
    "end-time-huge": (sub("end_time = 0.01", "end_time = 1e12"), {}, ["--check"], 2, "steps to end_time"),
    "max-estimated-steps": (sub("end_time = 0.01", "end_time = 10.0\nmax_estimated_steps = 10"), {}, ["--check"], 2,
                            "more than solver.max_estimated_steps = 10"),
    "time-step-100x": (sub("end_time = 0.01", "end_time = 0.01\ntime_step = 2.0"), {}, ["--check"], 2,
                       "solver.time_step: 2 s is above the stable step"),
    "time-step-above-run": (sub("end_time = 0.01", "end_time = 0.01\ntime_step = 0.0475"), {}, [], 2,
                            "solver.time_step:"),
    "time-step-zero": (sub("end_time = 0.01", "end_time = 0.01\ntime_step = 0.0"), {}, ["--check"], 2,
                       "solver.time_step: must be > 0"),
    "allow-unstable-not-bool": (sub("end_time = 0.01", "end_time = 0.01\nallow_unstable_time_step = 1"), {},
                                ["--check"], 2, "solver.allow_unstable_time_step: must be true or false"),
    # 4b. Rayleigh damping by ratio (issue 23)
    "damping-ratio-negative": (add('[loads]\ndamping = {ratio = -0.1, periods = [0.1, 0.05]}'), {}, ["--check"], 2,
                               "loads.damping.ratio: must be >= 0"),
    "damping-ratio-above-one": (add('[loads]\ndamping = {ratio = 1.5, periods = [0.1, 0.05]}'), {}, ["--check"], 2,
                                "loads.damping.ratio: must be <= 1"),
    "damping-period-zero": (add('[loads]\ndamping = {ratio = 0.05, periods = [0.1, 0.0]}'), {}, ["--check"], 2,
                            "loads.damping.periods: must be two periods > 0"),
    "damping-period-negative-run": (add('[loads]\ndamping = {ratio = 0.05, periods = [-0.1, 0.05]}'), {}, [], 2,
                                    "loads.damping.periods: must be two periods > 0"),
    # 4c. pushover and events (issue 23)
    "pushover-no-boundary": (add('[pushover]\ndisplacement = 0.1'), {}, ["--check"], 2,
                             "pushover.boundary: missing (required)"),
    "pushover-no-control": (add('[[boundary]]\nname = "push"\ntype = "roller_y"\nlower = [0.0, 0.0]\n'
                                'upper = [0.0, 1.0]\n[pushover]\nboundary = "push"\ndisplacement = 0.1'),
                            {}, ["--check"], 2, "pushover.control: missing (required)"),
    "pushover-fixed-boundary": (add('[[boundary]]\nname = "base"\ntype = "fixed"\nlower = [0.0, 0.0]\n'
                                    'upper = [4.0, 0.0]\n[pushover]\nboundary = "base"\ndisplacement = 0.1'),
                                {}, ["--check"], 2, "pushover.boundary: boundary 'base' is 'fixed'"),
    "event-unknown-body": (add('[[events]]\nbody = "column"\ntime = 0.001'), {}, ["--check"], 2,
                           "events[0].body: no body named 'column'"),
    "event-beyond-end": (add('[[events]]\nbody = "block"\ntime = 0.02'), {}, ["--check"], 2,
                         "events[0].time: the removal ends at 0.02 s, not before solver.end_time"),
    "event-beyond-end-run": (add('[[events]]\nbody = "block"\ntime = 0.005\nduration = 0.01'), {}, [], 2,
                             "events[0].time: the removal ends at 0.015 s"),
    # 5. geometry
    "polygon-bow-tie": (body('shape = "polygon"\nvertices = [[2.5, 0.5], [3.5, 1.5], [3.5, 0.5], [2.5, 1.5]]'),
                        {}, ["--check"], 2, "bodies[1].vertices:"),
    "polygon-collinear": (body('shape = "polygon"\nvertices = [[2.5, 0.5], [3.0, 0.5], [3.5, 0.5]]'),
                          {}, ["--check"], 2, "zero area"),
    "polygon-repeated-vertex": (body('shape = "polygon"\nvertices = [[2.5, 0.5], [3.5, 0.5], [3.5, 0.5], [3.0, 1.5]]'),
                                {}, ["--check"], 2, "coincide"),
    "duplicate-body-names": (body('name = "block"\nshape = "rectangle"\nlower = [2.5, 0.0]\nupper = [3.5, 1.0]'),
                             {}, ["--check"], 2, "bodies[1].name: body name 'block' is already used"),
    "overlapping-bodies": (body('name = "b2"\nshape = "circle"\ncenter = [1.5, 1.0]\nradius = 0.6'), {}, [], 2,
                           "bodies[1]: overlaps bodies[0]"),
    "mesh-missing-node": (MESH_BODY, {"part.vtk": MESH_MISSING_NODE}, [], 2,
                          "part.vtk: triangle element 1 refers to a node that does not exist"),
    "mesh-coincident-nodes": (MESH_BODY, {"part.vtk": MESH_COINCIDENT}, [], 2,
                              "part.vtk: triangle element 1 has zero area"),
    "mesh-dev-zero": (sub('shape = "rectangle"\nmaterial = "steel"\nlower = [0.0, 0.0]\nupper = [2.0, 1.0]',
                          'shape = "mesh"\nmaterial = "steel"\nfile = "/dev/zero"'), {}, [], 2,
                      "/dev/zero: cannot read mesh"),
    # 6. ground-motion records
    "record-nan-time": (ground("rec.txt"), {"rec.txt": "0.0 0.1\nnan 0.2\n0.02 0.0\n"}, [], 2,
                        "rec.txt: not a valid two_column acceleration record (time on data line 2 is not finite)"),
    "record-at2-dt-zero": (ground("rec.at2"), {"rec.at2": AT2_HEAD + "NPTS=   4, DT=   0.0000 SEC\n0.1 0.2 0.1 0.0\n"},
                           [], 2, "the header's DT must be a positive number"),
    "record-secret-file": (ground("shadow"), {"shadow": SECRET + "\n"}, [], 2, "shadow: not a valid"),
    "record-missing": (ground("nope.txt"), {}, [], 2, "nope.txt: cannot read ground motion"),
    "record-dev-zero": (ground("/dev/zero"), {}, [], 2, "/dev/zero: not a valid two_column acceleration record"),
    "record-not-utf8": (ground("rec.txt"), {"rec.txt": b"0.0 0.1\n\xff\xfe 0.2\n"}, [], 2, "not UTF-8"),
    "record-one-column": (ground("rec.txt"), {"rec.txt": "0.0\n0.01\n"}, [], 2, "expected two columns"),
    # 6b. stop conditions ([[stop]]): keys, the track they name, the thresholds
    "stop-unknown-key": (stop('quantity = "ux"\nabove = 0.1\nabov = 1.0'), {}, ["--check"], 2,
                         "stop[0].abov: unknown key"),
    "stop-no-such-track": (stop('quantity = "ux"\nabove = 0.1', track="nope"), {}, ["--check"], 2,
                           "stop[0].track: no [[output.track]] named 'nope'"),
    "stop-bad-quantity": (stop('quantity = "drift"\nabove = 0.1'), {}, ["--check"], 2,
                          "stop[0].quantity: must be one of"),
    "stop-no-threshold": (stop('quantity = "ux"'), {}, ["--check"], 2, "stop[0]: give above or below"),
    "stop-below-over-above": (stop('quantity = "ux"\nabove = 0.1\nbelow = 0.2'), {}, ["--check"], 2,
                              "stop[0].below: must be below above"),
    "stop-threshold-string": (stop('quantity = "|u|"\nabove = "0.1"'), {}, ["--check"], 2,
                              "stop[0].above: must be a finite number"),
    # 7. the scene file itself
    "scene-stray-ff": (lambda t: t.encode() + b"\n# \xff\n", {}, ["--check"], 2, "case.toml: not UTF-8 text"),
    "scene-utf16-bom": (lambda t: t.encode("utf-16"), {}, ["--check"], 2, "case.toml: not UTF-8 text"),
    "scene-utf8-bom": (lambda t: b"\xef\xbb\xbf" + t.encode(), {}, ["--check"], 2, "byte-order mark"),
    "scene-binary": (lambda t: bytes(range(256)) * 4, {}, ["--check"], 2, "case.toml: not UTF-8 text"),
    "scene-nul-bytes": (lambda t: b"\0" * 64, {}, ["--check"], 2, "case.toml: not valid TOML"),
    "scene-huge": (lambda t: t + "#" * (2 << 20), {}, ["--check"], 2, "not a scene file"),
    "scene-name-space": ("rename:my case.toml", {}, ["--check"], 2, "may hold only"),
    # 7b. numbers that would overflow the set-up or the first step, strings that would break the
    # one line (issue 19): refused when the scene is read
    "circle-radius-1e308": (body('shape = "circle"\ncenter = [3.0, 1.0]\nradius = 1e308'), {}, ["--check"], 2,
                            "bodies[1].radius: must be at most 1e+100 in magnitude"),
    "velocity-1e308": (sub("velocity = [0.1, 0.0]", "velocity = [1e308, 0.0]"), {}, ["--check"], 2,
                       "bodies[0].velocity: must be at most 1e+100"),
    "gravity-1e308": (add("[loads]\ngravity = [0.0, -1e308]"), {}, ["--check"], 2,
                      "loads.gravity: every entry must be at most 1e+100"),
    "ground-scale-1e308": (lambda t: ground("rec.txt")(t) + "scale = 1e308\n", {"rec.txt": "0.0 0.1\n0.02 0.0\n"},
                           ["--check"], 2, "loads.ground_motion.scale: must be at most 1e+100"),
    "title-nul": (top('title = "a\\u0000b"'), {}, [], 2, "case.toml: title: holds the control character '\\x00'"),
    "title-newline": (top('title = "a\\nb"'), {}, ["--check"], 2, "title: holds the control character '\\n'"),
    "key-ansi-escape": (sub("[solver]\n", '[solver]\n"\\u001b[31mred" = 1\n'), {}, ["--check"], 2,
                        "case.toml: solver.\\x1b[31mred: unknown key"),
    "output-directory-proc": (add('[output]\ndirectory = "/proc/pmpm_out"'), {}, [], 2,
                              "output.directory: '/proc/pmpm_out' lies in /proc"),
    # 8. combinations pmpm does not support: CPDI's corners in the contact solver's kernels
    "cpdi-with-contact": (lambda t: sub("end_time = 0.01", 'end_time = 0.01\ninterpolation = "cpdi"')(t)
                          + "\n[contact]\nfriction = 0.0\n", {}, ["--check"], 2,
                          "solver.interpolation: the contact solver's kernels use point B-splines only"),
    # 9. the frame front end (issue 22): each refusal names the frame entry
    "frame-coincident-nodes": (frame(nodes=node("A", 3.0, 0.0) + node("B", 3.0, 1.5),
                                     members=member("col", "A", "B") + member("stub", "B", "B")),
                               {}, ["--check"], 2, "frame.members[1].to: member 'stub' joins coincident nodes"),
    "frame-node-unreached": (frame(nodes=node("A", 3.0, 0.0) + node("B", 3.0, 1.5) + node("C", 3.5, 1.5)),
                             {}, ["--check"], 2, "frame.nodes[2]: no member reaches node 'C'"),
    "frame-unknown-section": (frame(members=member("col", "A", "B", "W12x12O")), {}, ["--check"], 2,
                              "frame.members[0].section: unknown section 'W12x12O' (closest: W12X120"),
    "frame-support-no-node": (frame(supports='[[frame.supports]]\nnode = "Q"\ntype = "fixed"\n'),
                              {}, ["--check"], 2, "frame.supports[0].node: no node named 'Q'"),
    "frame-overlap-unjoined": (frame(nodes=node("A", 3.0, 0.0) + node("B", 3.0, 1.5) + node("C", 3.1, 0.5)
                                     + node("D", 3.1, 1.0),
                                     members=member("col", "A", "B") + member("col2", "C", "D")),
                               {}, ["--check"], 2, "frame.members[1]: member 'col2' overlaps member 'col' "
                                                   "without a node joining them"),
    "frame-outside-grid": (frame(nodes=node("A", 3.9, 0.0) + node("B", 3.9, 1.5)), {}, ["--check"], 2,
                           "frame.members[0]: member 'col' lies outside the grid"),
    "frame-inclined": (frame(nodes=node("A", 3.0, 0.0) + node("B", 3.5, 1.5)), {}, ["--check"], 2,
                       "frame.members[0].to: member 'col' is inclined"),
    "frame-support-off-line": (frame(nodes=node("A", 3.0, 0.1) + node("B", 3.0, 1.5)), {}, ["--check"], 2,
                               "frame.supports[0].node: support node 'A' at y = 0.1 is not on a grid node line"),
}


def _tree(root):
    """Every path below ``root`` with a digest of its content (what 'nothing written' means)."""
    out = {}
    for base, dirs, files in os.walk(root):
        for d in dirs:
            out[os.path.relpath(os.path.join(base, d), root)] = "dir"
        for f in files:
            p = os.path.join(base, f)
            with open(p, "rb") as fh:
                out[os.path.relpath(p, root)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def run_cli(cwd, *args, timeout=TIMEOUT, ranks=0):
    """``python -m pmpm.cli args`` (``ranks`` > 0: under ``mpirun -n ranks``)."""
    cmd = [sys.executable, "-m", "pmpm.cli", *args]
    env = None
    if ranks:
        cmd = ["mpirun", "-n", str(ranks), "--oversubscribe", "--bind-to", "none"] + cmd
        env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return subprocess.run(cmd, cwd=cwd, capture_output=True, timeout=timeout, env=env)


def run_in_process(cwd, *args):
    """``pmpm args`` in this process, as :func:`run_cli` reports it (no interpreter start: the
    cases that need no hang protection or second rank; studies/bad_input.py
    puts back the process-wide state the command line changes)."""
    import types
    from studies.bad_input import cli_in_process
    code, out, err, exc = cli_in_process(args, cwd)
    if exc is not None:
        raise exc
    return types.SimpleNamespace(returncode=code, stdout=out.encode(), stderr=err.encode())


def _without_mpirun_report(err):
    """Standard error without mpirun's own boxed report of a non-zero exit (lines of dashes
    around it), which is mpirun's, not pmpm's."""
    keep, boxed = [], False
    for line in err.splitlines():
        if set(line.strip()) == {"-"}:
            boxed = not boxed
            continue
        if not boxed:
            keep.append(line)
    return keep


def assert_promise(proc, code, expected):
    """Exit code, exactly one error line containing ``expected``, no traceback; returns it."""
    err = proc.stderr.decode("utf-8", "replace")
    out = proc.stdout.decode("utf-8", "replace")
    assert proc.returncode == code, (proc.returncode, out, err)
    assert "Traceback" not in err + out, err + out
    lines = _without_mpirun_report(err)
    assert len(lines) == 1, err
    assert lines[0].startswith("pmpm: error: ") and expected in lines[0], lines[0]
    return lines[0]


#: cases found on every rank at the start of a run: under MPI still one line (rank 0 prints)
MPI_CASES = ["escape-shell-run", "cells-20000", "overlapping-bodies", "mesh-missing-node",
             "time-step-above-run"]


@pytest.mark.parametrize("name,ranks", [(n, 0) for n in CASES] + [(n, 2) for n in MPI_CASES])
def test_bad_input_keeps_the_promise(tmp_path, name, ranks):
    edit, files, args, code, expected = CASES[name]
    # three folders deep, so a traversal of up to three levels lands in the watched tree
    work = tmp_path / "a" / "b" / "c"
    work.mkdir(parents=True)
    case = "case.toml"
    if isinstance(edit, str) and edit.startswith("rename:"):
        case, data = edit.split(":", 1)[1], BASE
    else:
        data = edit(BASE)
    (work / case).write_bytes(data if isinstance(data, bytes) else data.encode())
    for fname, content in files.items():
        (work / fname).write_bytes(content if isinstance(content, bytes) else content.encode())
    before = _tree(tmp_path)
    line = assert_promise(run_cli(work, case, *args, ranks=ranks), code, expected)
    assert _tree(tmp_path) == before, "a file was written"
    assert "SECRET" not in line  # an error line never quotes a file's contents


def test_scene_from_dev_zero_and_a_directory(tmp_path):
    for target, expected in (("/dev/zero", "/dev/zero: is not a regular file"),
                             (str(tmp_path), "is not a regular file (a folder)")):
        before = _tree(tmp_path)
        assert_promise(run_cli(tmp_path, target, "--check"), 2, expected)
        assert _tree(tmp_path) == before


def test_unwritable_output_directory(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root may write anywhere: permissions cannot make a directory unwritable")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        (tmp_path / "case.toml").write_text(BASE + '\n[output]\ndirectory = "ro/out"\n')
        assert_promise(run_cli(tmp_path, "case.toml", "--check"), 2, "is not writable")
    finally:
        ro.chmod(0o700)


# -- restart: foreign and crafted checkpoints ------------------------------------------------

CKPT_SCENE = BASE.replace("end_time = 0.01", "end_time = 0.1") + "\n[output]\ncheckpoint_interval = 0.05\n"


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A real run with checkpoints (one start of the kernels for the whole module)."""
    work = tmp_path_factory.mktemp("ckpt")
    (work / "case.toml").write_text(CKPT_SCENE)
    proc = run_cli(work, "case.toml", "--no-plots", "-q", timeout=600)
    assert proc.returncode == 0, proc.stderr.decode()
    return work


def _copy_run(src, dst):
    import shutil
    shutil.copytree(src, dst, dirs_exist_ok=True)
    return dst


def _craft(path, edit_attrs=None, edit_fields=None):
    """Rewrite a checkpoint in place: its attrs JSON and/or particle arrays."""
    with h5py.File(path, "r+") as f:
        attrs = json.loads(f.attrs["attrs"])
        if edit_attrs:
            edit_attrs(attrs)
            f.attrs["attrs"] = json.dumps(attrs)
            f.attrs["time"] = attrs.get("time", 0.0)
        if edit_fields:
            fields = {k: f["particles"][k][:] for k in f["particles"]}
            edit_fields(fields)
            for k, a in fields.items():
                f["particles"][k][...] = a


def _dup_ids(fields):
    fields["id"][1] = fields["id"][0]


def _nan_x(fields):
    fields["x"][3, 0] = np.nan


def _drop_record(attrs):
    del attrs["scene_record"]


def _positions_3_columns(f):
    x = f["particles/x"][()]
    del f["particles/x"]
    f["particles/x"] = np.concatenate([x, np.zeros((len(x), 1))], axis=1)


def _count_lowered(f):
    """The root particle count lowered by 5 (the arrays and the JSON record keep theirs)."""
    f.attrs["n_total"] = int(f.attrs["n_total"]) - 5


def _soft_link(f):
    del f["particles/v"]
    f["particles/v"] = h5py.SoftLink("/particles/v")  # a loop


RESTARTS = {
    # scene edit, checkpoint edit, --restart target, expected
    "other-material": (sub("E = 100.0", "E = 200.0"), None, "case_results/case.h5",
                       "case.toml: materials.steel.E: differs from the scene of the checkpoint"),
    "other-geometry": (sub("upper = [2.0, 1.0]", "upper = [2.0, 1.5]"), None, "case_results/case.h5",
                       "bodies[0].geometry.upper: differs"),
    "other-scene-file": ("other.toml", None, "case_results/case.h5", "differs from the scene of the checkpoint"),
    "duplicate-ids": (None, ("ids", _dup_ids), "case_results/case.h5", "ids are duplicated"),
    "time-1e308": (None, ("attrs", lambda a: a.update(time=1e308)), "case_results/case.h5",
                   "beyond solver.end_time"),
    "time-nan": (None, ("attrs", lambda a: a.update(time=float("nan"))), "case_results/case.h5",
                 "not a finite time"),
    "nan-position": (None, ("ids", _nan_x), "case_results/case.h5", "non-finite particle values"),
    "no-scene-record": (None, ("attrs", _drop_record), "case_results/case.h5", "records no scene"),
    "particle-count": (None, ("attrs", lambda a: a.update(n_total=a["n_total"] + 5)), "case_results/case.h5",
                       "particle ids"),
    "missing-checkpoint": (None, None, "nowhere/case.h5", "cannot restart"),
    # the write gate's checks of the folder come before a restart reads it (issue 35): the
    # garbage at a checkpoint name is named as a file that is not pmpm's
    "garbage-checkpoint": (None, ("garbage", None), "case_results/case.h5",
                           "case_results/case.ckpt0.h5: exists and carries no 'pmpm_owner' record"),
    # issue 19: a checkpoint's layout checked before it is used
    "positions-3-columns": (None, ("h5", _positions_3_columns), "case_results/case.h5",
                            "/particles/x has shape (32, 3), expected (32, 2)"),
    "particle-count-lowered": (None, ("h5", _count_lowered), "case_results/case.h5",
                               "counts of particle ids disagree"),
    "soft-link-loop": (None, ("h5", _soft_link), "case_results/case.h5", "/particles/v is a soft link"),
}


@pytest.mark.parametrize("name", list(RESTARTS))
def test_restart_refuses_foreign_and_crafted_checkpoints(tmp_path, finished_run, name):
    scene_edit, ckpt_edit, target, expected = RESTARTS[name]
    work = _copy_run(finished_run, tmp_path / "w")
    case = "case.toml"
    if isinstance(scene_edit, str):  # another scene file restarted from this one's checkpoint
        case = scene_edit
        (work / case).write_text(CKPT_SCENE.replace('name = "block"', 'name = "other"'))
    elif scene_edit is not None:
        (work / case).write_text(scene_edit(CKPT_SCENE))
    if ckpt_edit is not None:
        kind, fn = ckpt_edit
        for k in (0, 1):
            path = work / "case_results" / f"case.ckpt{k}.h5"
            if kind == "garbage":
                path.write_bytes(b"not an HDF5 file")
            elif kind == "h5":
                with h5py.File(path, "r+") as f:
                    fn(f)
            elif kind == "attrs":
                _craft(path, edit_attrs=fn)
            else:
                _craft(path, edit_fields=fn)
    before = _tree(tmp_path)
    assert_promise(run_cli(work, case, "--restart", target, "--no-plots"), 2, expected)
    assert _tree(tmp_path) == before, "a file was written (another run's checkpoint touched?)"


def test_a_fresh_run_never_writes_over_another_scene_files(tmp_path, finished_run):
    """other.toml sends its output into case.toml's folder and file names: refused."""
    work = _copy_run(finished_run, tmp_path / "w")
    os.rename(work / "case.toml", work / "orig.toml")
    (work / "sub").mkdir()
    (work / "sub" / "case.toml").write_text(CKPT_SCENE.replace("[output]", '[output]\ndirectory = "../case_results"'))
    before = _tree(tmp_path)
    assert_promise(run_cli(work / "sub", "case.toml", "--no-plots"), 2,
                   "output.directory: ")
    assert _tree(tmp_path) == before


# -- a full disk -------------------------------------------------------------------------------

@pytest.mark.parametrize("ranks", [0, 2])
def test_full_disk_stops_with_one_line_naming_the_file(tmp_path, ranks):
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)],
                             capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        # 800 particles; a frame of x, v, stress is 58 KB in float64 (less as written:
        # float32, compressed), a checkpoint 100 KB: two checkpoints and a few dozen frames fit in
        # 1 MB, the run's 100 frames do not
        scene = (BASE.replace("cell_size = 0.5", "cell_size = 0.1").replace("cells = [8, 4]", "cells = [40, 20]")
                 .replace("end_time = 0.01", "end_time = 0.5")
                 + '\n[output]\ndirectory = "disk/out"\ninterval = 0.005\ncheckpoint_interval = 0.02\n')
        (tmp_path / "case.toml").write_text(scene)
        proc = run_cli(tmp_path, "case.toml", "--no-plots", timeout=300, ranks=ranks)
        line = assert_promise(proc, EXIT_WRITE_FAILED, "disk/out/case")  # every rank stopped
        assert "No space left on device" in line, line
        complete = []
        for k in (0, 1):  # the checkpoints written before the disk filled are whole
            with h5py.File(disk / "out" / f"case.ckpt{k}.h5", "r") as f:
                assert f.attrs["complete"] and np.isfinite(f["particles/x"][:]).all()
                complete.append(float(f.attrs["time"]))
        # and usable: the same scene continues from them once there is room
        import shutil
        room = tmp_path / "room"
        shutil.copytree(disk, room / "disk")
        shutil.copy(tmp_path / "case.toml", room / "case.toml")
        # a little beyond the newest checkpoint (where the disk filled depends on the frames' size)
        (room / "case.toml").write_text(scene.replace("end_time = 0.5", f"end_time = {max(complete) + 0.02:.6g}"))
        proc = run_cli(room, "case.toml", "--restart", "disk/out/case.h5", "--no-plots", timeout=300)
        assert proc.returncode == 0, proc.stderr.decode()
        assert f"t = {max(complete):.6g} s" in proc.stdout.decode()
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


def test_disk_full_at_start_is_one_line_and_leaves_no_results_file(tmp_path):
    """A disk with less than the write margin free before the run starts: refused before HDF5
    creates a results file it could not finish (it once left an unreadable one, and a traceback)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        (disk / "fill").write_bytes(b"\0" * (240 << 10))  # 16 KB left: below the 64 KB margin
        (tmp_path / "case.toml").write_text(BASE + '\n[output]\ndirectory = "disk/out"\n')
        line = assert_promise(run_cli(tmp_path, "case.toml", "--no-plots"), EXIT_WRITE_FAILED, "disk/out/case.h5")
        assert "No space left on device" in line
        assert not (disk / "out" / "case.h5").exists()
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


# -- the same table through the Python API (issue 19: the API once skipped the CLI's checks) --
#: CLI-only cases: a scene file name the API gets as given ("rename:"), flags the API has not
API_SKIP = {n for n, (edit, _f, args, _c, _e) in CASES.items()
            if isinstance(edit, str) or any(a.startswith("--") and a != "--check" for a in args)}


@pytest.mark.parametrize("name", [n for n in CASES if CASES[n][3] == 2 and n not in API_SKIP])
def test_bad_input_through_the_api_keeps_the_promise(tmp_path, monkeypatch, name):
    """``pmpm.run(..., write=True)`` refuses every scene the CLI refuses, with the same
    reason, and writes nothing anywhere (checked three folders up)."""
    import pmpm
    from pmpm.errors import ConfigError
    edit, files, _args, _code, expected = CASES[name]
    work = tmp_path / "a" / "b" / "c"
    work.mkdir(parents=True)
    data = edit(BASE)
    (work / "case.toml").write_bytes(data if isinstance(data, bytes) else data.encode())
    for fname, content in files.items():
        (work / fname).write_bytes(content if isinstance(content, bytes) else content.encode())
    monkeypatch.chdir(work)
    before = _tree(tmp_path)
    with pytest.raises(ConfigError) as err:
        pmpm.run("case.toml", write=True)
    reason = expected.split("case.toml: ", 1)[-1]
    assert reason in str(err.value), (str(err.value), reason)
    assert _tree(tmp_path) == before, "a file was written"


@pytest.mark.parametrize("variant", ["x/../../../../name", "../victim", "/abs", "a\nb", "", 7])
def test_api_variant_argument_cannot_leave_the_folder(tmp_path, monkeypatch, variant):
    """The attack of issue 19: a variant name given to pmpm.run (or set on a Scene by hand)
    that would put the results, checkpoints or last good state outside output.directory."""
    import dataclasses
    import pmpm
    from pmpm.errors import ConfigError
    work = tmp_path / "a" / "b" / "c"
    work.mkdir(parents=True)
    (work / "case.toml").write_text(BASE + '\n[variants.x]\n"solver.cfl" = 0.4\n')
    monkeypatch.chdir(work)
    before = _tree(tmp_path)
    if variant != "":  # "" means "every variant" to pmpm.run: valid there
        with pytest.raises(ConfigError, match="variant"):
            pmpm.run("case.toml", write=True, variant=variant)
    scene = pmpm.load_scene("case.toml", "x")[0]
    with pytest.raises(ConfigError, match="variant"):
        pmpm.run(dataclasses.replace(scene, variant=variant) if variant != "" else
                 dataclasses.replace(scene, variant="../../x"), write=True)
    from pmpm.runner import Run
    with pytest.raises(ConfigError, match="variant"):
        Run(dataclasses.replace(scene, variant="../../../../name"), write=True)
    assert _tree(tmp_path) == before, "a file was written"


def test_api_dict_scene_writes_only_with_a_file_name(tmp_path, monkeypatch):
    """A scene given as TOML data has no stem to name files: write=True is refused in one
    ConfigError (it once wrote '<scene>.h5'); write=False runs."""
    import tomllib
    import pmpm
    from pmpm.errors import ConfigError
    monkeypatch.chdir(tmp_path)
    data = tomllib.loads(BASE)
    with pytest.raises(ConfigError, match="no file name"):
        pmpm.run(data, write=True)
    assert os.listdir(tmp_path) == []


# -- ownership: pmpm writes over and deletes only its own files (issue 19, docs/output.md) ----
TRACKED = CKPT_SCENE + '\n[[output.track]]\nname = "tip"\npoint = [2.0, 0.5]\n'


@pytest.fixture(scope="module")
def tracked_run(tmp_path_factory):
    """A finished run with checkpoints, a tracked point, its CSV and plots and a VTU export."""
    work = tmp_path_factory.mktemp("owned")
    (work / "case.toml").write_text(TRACKED)
    proc = run_in_process(work, "case.toml", "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    proc = run_in_process(work, "export", "case_results/case.h5")
    assert proc.returncode == 0, proc.stderr.decode()
    return work


#: file in case_results (replaced by a user's own), content, the command that meets it
FOREIGN = {
    "results-text": ("case.h5", b"my notes\n", ["case.toml", "--no-plots"]),
    "results-hdf5": ("case.h5", "hdf5", ["case.toml", "--no-plots"]),
    "stale-checkpoint": ("case.ckpt0.h5", "hdf5", ["case.toml", "--no-plots"]),
    "lastgood": ("case.lastgood.h5", b"x", ["case.toml", "--no-plots"]),
    "sidecar": ("case.xdmf", b"<Xdmf/>\n", ["case.toml", "--no-plots"]),
    "track-csv": ("case_history_tip.csv", b"t,ux\n0,0\n", ["case.toml"]),
    "history-png": ("case_history_tip.png", b"\x89PNG mine", ["case.toml"]),
    "edited-csv": ("case_history_tip.csv", "append", ["case.toml"]),
    "manifest": ("pmpm-files.json", b"{\"mine\": 1}\n", ["case.toml"]),
    "plot-png": ("case_energies.png", b"mine", ["plot", "case_results/case.h5"]),
    "export-vtu": ("case_vtu/case_00001.vtu", b"mine", ["export", "case_results/case.h5"]),
    "export-xdmf": ("case.xdmf", b"<Xdmf/>\n", ["export", "case_results/case.h5", "--format", "xdmf"]),
}


@pytest.mark.parametrize("name", list(FOREIGN))
def test_foreign_files_are_never_overwritten_or_deleted(tmp_path, tracked_run, name):
    target, content, args = FOREIGN[name]
    work = _copy_run(tracked_run, tmp_path / "w")
    path = work / "case_results" / target
    if content == "hdf5":  # a user's own HDF5 file: no pmpm record
        path.unlink()
        with h5py.File(path, "w") as f:
            f["mine"] = np.arange(3)
    elif content == "append":  # pmpm's file, edited by the user afterwards
        with open(path, "ab") as fh:
            fh.write(b"1,2\n")
    else:
        path.write_bytes(content)
    before = _tree(tmp_path)
    line = assert_promise(run_in_process(work, *args), 2, f"case_results/{target}: exists and ")
    assert "overwrites or deletes only the files it wrote" in line
    assert _tree(tmp_path) == before, "a file was written or deleted"


def test_own_files_are_rewritten_and_two_scenes_share_a_folder(tmp_path, tracked_run):
    """The same scene runs again over its own files; a second scene in the same folder writes
    its own names beside them and changes none of the first scene's."""
    work = _copy_run(tracked_run, tmp_path / "w")
    first = {k: v for k, v in _tree(work / "case_results").items() if not k.startswith("pmpm-files")}
    (work / "other.toml").write_text(TRACKED.replace("[output]", '[output]\ndirectory = "case_results"'))
    proc = run_in_process(work, "other.toml", "-q")
    assert proc.returncode == 0, proc.stderr.decode()
    after = _tree(work / "case_results")
    assert {k: after[k] for k in first} == first, "the second scene changed the first one's files"
    assert {"other.h5", "other_history_tip.csv", "other_history_tip.png"} <= set(after)
    proc = run_in_process(work, "case.toml", "-q")  # its own files, recorded: no refusal
    assert proc.returncode == 0, proc.stderr.decode()
    with open(work / "case_results" / "pmpm-files.json") as fh:
        owners = {n: e["owner"] for n, e in json.load(fh)["files"].items()}
    assert owners["case_history_tip.csv"] == "case" and owners["other_history_tip.csv"] == "other"


# -- files read: FIFOs, broken results files, the API's arguments (issue 19) ---------------------
@pytest.mark.parametrize("which", ["scene", "record"])
def test_a_fifo_is_refused_not_waited_on(tmp_path, which):
    """A FIFO as the scene file or as the ground-motion record: opened non-blocking and refused
    (it once blocked forever: the timeout fails the case)."""
    os.mkfifo(tmp_path / "pipe")
    if which == "scene":
        args, expected = ["pipe", "--check"], "pipe: is not a regular file (a FIFO)"
    else:
        (tmp_path / "case.toml").write_text(ground("pipe")(BASE))
        args, expected = ["case.toml"], "pipe: not a valid"
    before = _tree_names(tmp_path)
    line = assert_promise(run_cli(tmp_path, *args, timeout=TIMEOUT), 2, expected)
    assert "FIFO" in line
    assert _tree_names(tmp_path) == before, "a file was written"


def _tree_names(root):
    """The names below ``root`` (a FIFO cannot be hashed by reading it)."""
    return sorted(os.path.relpath(os.path.join(b, n), root) for b, ds, fs in os.walk(root) for n in ds + fs)


def test_a_10000_vertex_polygon_is_checked_in_bounded_memory():
    """The crossing check of a 10,000-vertex polygon (the largest allowed) once took 763 MB at
    --check; in blocks of pairs it stays under 100 MB (tracemalloc sees numpy's allocations)."""
    import math
    import tracemalloc
    from pmpm.scene.config import _polygon_vertices
    from pmpm.scene.tables import Table
    n = 10000
    verts = [[math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n)] for k in range(n)]
    tracemalloc.start()
    try:
        _polygon_vertices(Table({"vertices": verts}, "bodies[0]"))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6, peak
    bad = verts[:]
    bad[10], bad[5000] = bad[5000], bad[10]  # two far vertices swapped: edges cross
    from pmpm.errors import ConfigError
    with pytest.raises(ConfigError, match="cross"):
        _polygon_vertices(Table({"vertices": bad}, "bodies[0]"))


def _h5_edit(edit):
    def apply(path):
        with h5py.File(path, "r+") as f:
            edit(f)
    return apply


def _replace(name, data):
    def edit(f):
        del f[name]
        f[name] = data
    return edit


def _link(name, link):
    def edit(f):
        del f[name]
        f[name] = link
    return edit


#: results-file mutation, the line must contain
BROKEN_RESULTS = {
    "external-link": (_link("frames/v", h5py.ExternalLink("/etc/passwd", "/x")), "/frames/v is an external link"),
    "soft-link-loop": (_link("frames/v", h5py.SoftLink("/frames/v")), "/frames/v is a soft link"),
    "positions-as-strings": (lambda f: _replace("frames/x", np.full(f["frames/x"].shape[:2], b"x"))(f),
                             "/frames/x holds |S1 values"),
    "history-1d": (lambda f: _replace("history/tip", f["history/tip"][:, 0])(f), "/history/tip has shape"),
    "no-n-total": (lambda f: f.attrs.__delitem__("n_total"), "'n_total' is missing"),
    "step-count": (lambda f: _replace("frames/step", np.arange(1))(f), "/frames/step has shape (1,)"),
}


@pytest.fixture(scope="module")
def tracked_results(tracked_run):
    return tracked_run


#: each mutation through one of the three commands (the generated suite crosses them all)
_COMMANDS = ["plot", "export", "xdmf"]


@pytest.mark.parametrize("name,command", [(n, _COMMANDS[k % 3]) for k, n in enumerate(BROKEN_RESULTS)])
def test_broken_results_files_are_refused_by_plot_and_export(tmp_path, tracked_results, name, command):
    work = _copy_run(tracked_results, tmp_path / "w")
    import shutil
    shutil.rmtree(work / "case_results" / "case_vtu")
    edit, expected = BROKEN_RESULTS[name]
    _h5_edit(edit)(work / "case_results" / "case.h5")
    args = {"plot": ["plot", "case_results/case.h5", "-o", "plots"], "export": ["export", "case_results/case.h5"],
            "xdmf": ["export", "case_results/case.h5", "--format", "xdmf", "-o", "xd"]}[command]
    before = _tree(tmp_path)
    line = assert_promise(run_in_process(work, *args), 2, "case_results/case.h5: ")
    assert expected in line, line
    assert _tree(tmp_path) == before, "a file was written (a partial export or plot?)"


def test_api_arguments_of_the_wrong_kind_are_one_line(tmp_path, monkeypatch):
    import pmpm
    from pmpm.errors import ConfigError
    (tmp_path / "case.toml").write_text(BASE)
    monkeypatch.chdir(tmp_path)
    for kwargs, expected in (({"comm": "world"}, "comm: must be an mpi4py communicator"),
                             ({"write": "yes"}, "write: must be True or False"),
                             ({"dataframes": "x"}, "dataframes: must be None"),
                             ({"progress": 3}, "progress: must be True")):
        with pytest.raises(ConfigError, match=expected):
            pmpm.run("case.toml", **kwargs)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(ConfigError, match="'afile' exists and is not a directory"):
        pmpm.run("case.toml", write=True, overrides={"output.directory": "afile"})
    with h5py.File(tmp_path / "part.h5", "w") as f:  # only part of the layout
        f.attrs["layout"] = "pmpm-results-2"
        for g in ("frames", "history", "energies"):
            f.create_group(g)
    with pytest.raises(ValueError, match="part.h5: not a usable pmpm results file: the root attribute 'n_total'"):
        pmpm.load_results(tmp_path / "part.h5")
    assert sorted(os.listdir(tmp_path)) == ["afile", "case.toml", "part.h5"]


@pytest.mark.parametrize("args,expected", [
    (["bench", "throughput", "--particles", "1000000000000000"], "bench throughput: argument --particles: must be at most"),
    (["bench", "fixedcost", "--work", "inf"], "bench fixedcost: argument --work: must be a finite number"),
    (["bench", "fixedcost", "--work", "nan"], "argument --work: must be a finite number"),
    (["case.toml", "--bogus"], "run: unrecognized arguments: --bogus"),
    (["plot", "x.h5", "--nope"], "plot: unrecognized arguments: --nope"),
    (["case\nname.toml", "--check"], "case\\nname.toml: cannot read"),
])
def test_command_line_errors_are_one_line_naming_the_subcommand(tmp_path, args, expected):
    before = _tree(tmp_path)
    assert_promise(run_in_process(tmp_path, *args), 2, expected)
    assert _tree(tmp_path) == before
