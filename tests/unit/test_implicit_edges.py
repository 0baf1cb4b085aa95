"""Slaved edge nodes of the implicit step (``[solver.implicit] edge_mass_ratio``,
pmpm.core.implicit.edges; docs/implicit.md "The points as the quadrature of the strips").

* The operations against their definition: with T the dense extension map written here from
  the rule (u_o = 2 u_(o+e) - u_(o+2e), identity elsewhere), ``expand`` is T u, ``fold`` is
  T^T q, and the folded blocks are T^T K T of the kernel's blocks (NumPy twin:
  pmpm.core.implicit.reference.blocks_to_dense), with no block falling outside the offsets.
* Linear completeness (theory): an expanded linear field is linear on the slaved nodes too,
  so a rigid motion strains no particle.
* The clamped I-section strip (the portal's W12x120 column at 0.05 m cells, 1.5 m high, 100
  kN at its top, elastic, one static step) at two offsets from the grid lines, 0 (its edges
  just past a grid line: the outermost node's weights of order 1e-5) and 0.02 m: a continuum's
  drift does not depend on where the grid lines fall. With the slaved nodes the two drifts
  agree within 0.5 % (the exactly integrated cubic space of these points differs by 0.02 %
  between offsets, and what remains of the points' under-integration across the depth varies
  by up to 0.4 % between offsets: studies.implicit_quadrature on the 3.7 m strip, 0.4-0.5 %
  soft at every offset); without, the offset-0 strip is 7.8 % the softer here (the
  near-zero-energy modes of its outer nodes). The base shear equals the load to Newton's
  tolerance (1e-6: the folded residual is the problem's), and Newton takes no more iterations
  than without slaved nodes (the folded tangent is the exact derivative).

* Accepted with Rayleigh damping and ground motion, whose terms are folded
  (tests/unit/test_implicit_edges_terms.py), and with a load-factor control: under displacement
  control the strip's face point moves by the displacement asked, to round-off, and the base
  shear is the load factor times the pattern, to Newton's tolerance.

Shown to fail on planted bugs (restored): the point's weights left unfolded
(DisplacementControl.weights halo-summing without the fold) -> the point's move off by
7.3e-5 of it; the pattern's forces left unfolded (LoadFactorControl.load_vectors without
``edges``) -> the base shear 5.3e-5 off the load factor's; the
tangent's fold skipped (``fold_tangent`` not called in GridProblem.tangent) -> 21 Newton
iterations instead of 3 in the strip's step; the residual left unfolded (the fold in
GridProblem.internal_force removed) -> the base shear 0.025 % off the load; the grid's fields
left unfolded (ImplicitNewmark._edge_slaves) -> the linear solve diverges; the expansion's
factor 2 written as 1 -> the twin and linear-field tests fail.
"""
import numpy as np
import pytest

from pmpm.core.implicit import reference as RF
from pmpm.core.implicit.edges import DIRECTIONS, EdgeSlaves
from pmpm.runner import Run
from pmpm.scene.config import parse_scene

SECTION = dict(shape="i_section", depth=0.33325, flange_width=0.31293, flange_thickness=0.028067,
               web_thickness=0.018034, area=0.022774, inertia=4.4537e-4)


class _Serial:
    """The decomposition of one rank (fill: nothing to do)."""

    def fill(self, arr):
        pass


def _strip_mass(shape=(14, 10), left=4, right=9, light=1e-5):
    """A nodal mass field: a body over columns left..right (mass 1), its outermost columns
    ``light``, nothing elsewhere; nothing on the top and bottom rows."""
    m = np.zeros(shape)
    m[left:right + 1, 1:-1] = 1.0
    m[left, 1:-1] = light
    m[right, 1:-1] = light
    return m


def _dense_T(code):
    """The extension map (2 nodes, 2 nodes) written from the rule."""
    nx, ny = code.shape
    n = nx * ny
    T = np.eye(2 * n)
    for i, j in zip(*np.nonzero(code)):
        di, dj = DIRECTIONS[code[i, j]]
        o, a, b = i * ny + j, (i + di) * ny + j + dj, (i + 2 * di) * ny + j + 2 * dj
        for c in range(2):
            T[2 * o + c, :] = 0.0
            T[2 * o + c, 2 * a + c] = 2.0
            T[2 * o + c, 2 * b + c] = -1.0
    return T


def _slaves(mass, ratio=0.01):
    own = np.ones(mass.shape, dtype=bool)
    return EdgeSlaves(mass, 1e-12, np.zeros(mass.shape + (2,), dtype=bool), own, _Serial(), ratio)


def test_slaves_are_the_light_edge_columns():
    e = _slaves(_strip_mass())
    assert set(zip(*np.nonzero(e.code))) == {(c, j) for c in (4, 9) for j in range(1, 9)}
    assert np.all(e.code[4, 1:-1] == 1) and np.all(e.code[9, 1:-1] == 2)   # +x and -x inward
    # a heavier edge column, or a ratio below its share, is left alone
    assert len(_slaves(_strip_mass(light=0.5))) == 0
    assert len(_slaves(_strip_mass(), ratio=1e-6)) == 0


def test_operations_are_the_extension_map():
    rng = np.random.default_rng(1)
    e = _slaves(_strip_mass())
    T = _dense_T(e.code)
    nx, ny = e.code.shape
    u = rng.normal(size=(nx, ny, 2))
    assert np.allclose(e.expand(u.copy()).reshape(-1), T @ u.reshape(-1), atol=1e-14)
    q = rng.normal(size=(nx, ny, 2))
    folded = q.copy()
    e.fold(folded)
    assert np.allclose(folded.reshape(-1), T.T @ q.reshape(-1), atol=1e-13)
    # the tangent: blocks of a symmetric coupling of every pair of nodes within the offsets
    span = 7
    unknown = (_strip_mass() > 0) & (e.code == 0)
    lid = np.full((nx, ny), -1, np.int64)
    lid[unknown] = np.arange(unknown.sum())
    lid_ext, rows = e.extended_lid(lid)
    K = np.zeros((2 * nx * ny, 2 * nx * ny))
    Kb = np.zeros((rows, span * span, 2, 2))
    for i, j in zip(*np.nonzero(lid_ext >= 0)):
        for off in range(span * span):
            ii, jj = i + off // span - 3, j + off % span - 3
            # couplings only between nodes a particle could share: the slaved nodes' partners
            # lie on their inward side (their outward neighbour holds no material)
            if 0 <= ii < nx and 0 <= jj < ny and lid_ext[ii, jj] >= 0 and _shared(e.code, (i, j), (ii, jj)):
                blk = rng.normal(size=(2, 2))
                Kb[lid_ext[i, j], off] = blk
                K[2 * (i * ny + j):2 * (i * ny + j) + 2, 2 * (ii * ny + jj):2 * (ii * ny + jj) + 2] = blk
    assert e.fold_tangent(Kb, lid_ext, span) == 0
    folded_K = RF.blocks_to_dense(Kb[:unknown.sum()], lid, span)
    assert np.allclose(folded_K, T.T @ K @ T, atol=1e-12)


def _shared(code, p, q):
    """Whether nodes p and q could both be touched by one particle beside a slaved node: every
    slaved one among them sees the other within its inward 4-node reach."""
    for s, t in ((p, q), (q, p)):
        c = code[s]
        if c:
            di, dj = DIRECTIONS[c]
            along = (t[0] - s[0]) * di + (t[1] - s[1]) * dj
            if not 0 <= along <= 3:
                return False
    return True


def test_linear_fields_stay_linear():
    e = _slaves(_strip_mass())
    nx, ny = e.code.shape
    I, J = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    u = np.stack([0.3 + 0.01 * I - 0.02 * J, -0.1 + 0.02 * I + 0.005 * J], axis=-1)
    lin = u.copy()
    u[e.code != 0] = 7.0   # whatever the slaved nodes held
    assert np.allclose(e.expand(u), lin, atol=1e-14)


#: the strip's height and the tracked point's (the top cell row's upper points)
LENGTH = 1.5
TOP = LENGTH - 0.05 / 4


def _strip_scene(offset, ratio, length=LENGTH, h=0.05, axis="auto", dynamic=False):
    col = dict(SECTION, name="column", material="steel", start=[offset, 0.0], end=[offset, length])
    data = {"title": "I-section strip", "formulation": "plane_stress", "particles_per_cell": 2,
            "grid": {"origin": [-0.5, 0.0], "cell_size": h,
                     "cells": [int(round(1.0 / h)), int(round((length + 0.3) / h))]},
            "materials": {"steel": {"type": "linear_elastic", "E": 207e9, "nu": 0.3, "density": 7850.0}},
            "bodies": [col],
            "boundary": [{"name": "base", "type": "fixed", "lower": [-0.5, 0.0], "upper": [0.5, 0.0],
                          "reaction": True}],
            "loads": {"forces": [{"name": "push", "body": "column", "lower": [-0.5, length - h],
                                  "upper": [0.5, length + h], "force": [1e5, 0.0]}]},
            "solver": {"integrator": "implicit", "analysis": "dynamic" if dynamic else "static",
                       "time_step": 2e-4 if dynamic else 1.0, "end_time": 1e-3 if dynamic else 1.0},
            "output": {"interval": 1.0, "history_interval": 2e-4 if dynamic else 1.0, "fields": ["x", "x0"],
                       "track": [{"name": "top", "point": [offset, length - h / 4]}]},
            "parallel": {"axis": axis}}
    if ratio:
        data["solver"]["implicit"] = {"edge_mass_ratio": ratio}
    return data


def _static(offset, ratio):
    """(drift, base shear, Newton iterations, slaved nodes) of the strip's static step."""
    run = Run(parse_scene(_strip_scene(offset, ratio), "strip.toml"), write=False)
    run.execute()
    st = run.solver.scheme.stats
    p = run.solver.particles
    top = int(np.argmin(np.sum((p["x0"] - [offset, TOP]) ** 2, axis=1)))
    drift = float(p["x"][top, 0] - p["x0"][top, 0])
    names = run.structural.reaction_names
    shear = -float(run.structural.rows[-1][2][names.index("base"), 0])
    return drift, shear, st["newton_iterations"], st.get("slaved_nodes", 0)


def test_strip_drift_does_not_depend_on_the_grid_offset():
    (a, shear, its, slaved), (b, _, _, _) = _static(0.0, 0.01), _static(0.02, 0.01)
    assert slaved > 0
    assert abs(a / b - 1) < 5e-3, (a, b)
    plain_a, plain_b = _static(0.0, 0.0)[0], _static(0.02, 0.0)[0]
    assert plain_a / plain_b - 1 > 1e-2, (plain_a, plain_b)   # what the option removes
    # the folded residual and tangent are the problem's: equilibrium with the supports to
    # Newton's tolerance, and Newton as fast as without slaved nodes (an exact tangent)
    assert abs(shear / 1e5 - 1) < 1e-6, shear
    assert its <= _static(0.0, 0.0)[2], its


def test_damped_strip_is_accepted():
    damped = _strip_scene(0.0, 0.01, dynamic=True)
    damped["loads"]["damping"] = {"ratio": 0.02, "periods": [0.01, 0.002]}
    Run(parse_scene(damped, "strip.toml"), write=False)   # (Rayleigh's term is folded)


#: the face particle of the strip's top row (its stencil reaches the slaved node column x = -0.25)
FACE = (-0.154, TOP)


def test_displacement_control_with_slaved_nodes():
    """A load-factor control ([solver.static] control = "displacement") on the strip with slaved
    edge nodes: the pattern's forces and the controlled point's weights are folded. The point
    (a particle on the face, whose stencil reaches the slaved column) moves by exactly the
    displacement asked (the constraint c . u is linear and each correction meets it: round-off,
    1e-9 relative, with the particle moved by the expanded increment), and the base shear is the
    load factor times the pattern's 100 kN to Newton's tolerance (1e-6, as the load-controlled
    strip's)."""
    data = _strip_scene(0.0, 0.01)
    data["solver"]["static"] = {"control": "displacement", "point": list(FACE), "component": "x",
                                "displacement": 0.001}
    run = Run(parse_scene(data, "strip.toml"), write=False)
    run.execute()
    s = run.solver
    control = s.scheme.control
    assert s.scheme.stats.get("slaved_nodes", 0) > 0
    p = s.particles
    k = int(np.flatnonzero(p["id"] == control.particle)[0])
    assert abs(p["x0"][k, 0] - FACE[0]) < 0.01 and abs(p["x0"][k, 1] - FACE[1]) < 0.02   # the face particle
    moved = float(p["x"][k, 0] - p["x0"][k, 0])
    assert abs(moved / 0.001 - 1) < 1e-9, moved
    names = run.structural.reaction_names
    shear = -float(run.structural.rows[-1][2][names.index("base"), 0])
    assert abs(shear / (control.load_factor * 1e5) - 1) < 1e-6, (shear, control.load_factor)
