"""Bodies -> material points.

Each body shape places points on a regular lattice of spacing h / particles_per_cell (or, for
meshes, per element) and gives each point its volume (area x out-of-plane thickness) and mass.
I-section members are plane-stress strips whose points carry the thickness of the section at
their height (flange width in the flanges, web thickness in the web), scaled so the strip's
area and second moment equal the section's.
"""
import logging
import math

import numpy as np

from pmpm.errors import ConfigError
from pmpm.scene.expressions import parse_expression

__all__ = ["generate_body", "body_points", "inside_body", "check_overlaps"]
logger = logging.getLogger(__name__)


def _lattice(lo, hi, spacing):
    """Cell-centred lattice points covering [lo, hi] with spacing close to ``spacing``;
    returns points (N, 2) and the area each represents (exact for the box)."""
    n = [max(1, int(round((hi[d] - lo[d]) / spacing))) for d in range(2)]
    dx = [(hi[d] - lo[d]) / n[d] for d in range(2)]
    xs = lo[0] + (np.arange(n[0]) + 0.5) * dx[0]
    ys = lo[1] + (np.arange(n[1]) + 0.5) * dx[1]
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()]), dx[0] * dx[1]


def _grid_lattice(grid, lo, hi, ppc):
    """Points at the centres of the ppc x ppc sub-cells of the grid inside the box [lo, hi]."""
    d = grid.h / ppc
    i0 = np.floor((np.asarray(lo) - grid.origin) / d).astype(int)
    i1 = np.ceil((np.asarray(hi) - grid.origin) / d).astype(int)
    xs = grid.origin[0] + (np.arange(i0[0], i1[0]) + 0.5) * d
    ys = grid.origin[1] + (np.arange(i0[1], i1[1]) + 0.5) * d
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()]), d * d


def _inside_polygon(pts, verts):
    """Even-odd rule, vectorised over points."""
    verts = np.asarray(verts)
    inside = np.zeros(len(pts), dtype=bool)
    x, y = pts[:, 0], pts[:, 1]
    for (x1, y1), (x2, y2) in zip(verts, np.roll(verts, -1, axis=0)):
        crosses = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < xc)
    return inside


def _i_section(geo, grid, ppc, key):
    """Points of a member strip along start -> end, and their out-of-plane thickness."""
    start, end = np.asarray(geo["start"]), np.asarray(geo["end"])
    length = float(np.linalg.norm(end - start))
    depth = geo["depth"]
    local, area = _lattice((0.0, -depth / 2), (length, depth / 2), grid.h / ppc)
    eta = local[:, 1]
    dy = depth / len(np.unique(eta))
    # fraction of each row's band [eta - dy/2, eta + dy/2] that lies in a flange
    lo, hi = eta - dy / 2, eta + dy / 2
    web_half = depth / 2 - geo["flange_thickness"]
    in_web = np.clip(np.minimum(hi, web_half) - np.maximum(lo, -web_half), 0, None) / dy
    flange = 1.0 - in_web
    bf, tw = geo["flange_width"], geo["web_thickness"]
    A = geo["area"] or (2 * bf * geo["flange_thickness"] + (depth - 2 * geo["flange_thickness"]) * tw)
    I = geo["inertia"] or (bf * depth ** 3 - (bf - tw) * (depth - 2 * geo["flange_thickness"]) ** 3) / 12
    # thickness = a * web_part * tw + b * flange_part * bf, with (a, b) chosen so that the strip's
    # discrete area and second moment per unit length (point quadrature, as the MPM integrates)
    # equal A and I; summing over all points counts each row length/spacing times, hence area/length
    w_web, w_fl = in_web * tw, flange * bf
    M = np.array([[np.sum(w_web), np.sum(w_fl)],
                  [np.sum(w_web * eta ** 2), np.sum(w_fl * eta ** 2)]]) * area / length
    try:
        a, b = np.linalg.solve(M, [A, I])
    except np.linalg.LinAlgError:
        a = b = math.nan
    thickness = a * w_web + b * w_fl
    # too few point rows across the depth: M is singular, or matching I needs negative thickness
    if not (np.all(np.isfinite(thickness)) and np.all(thickness > 0)
            and np.allclose(M @ [a, b], [A, I], rtol=1e-6, atol=0)):
        raise ConfigError(f"{key}.depth", f"{len(np.unique(eta))} particle row(s) across the depth cannot "
                                          f"match area {A:g} and inertia {I:g} with positive thicknesses "
                                          f"(refine the grid or raise particles_per_cell)")
    direction = (end - start) / length
    normal = np.array([-direction[1], direction[0]])
    pts = start + local[:, :1] * direction + local[:, 1:] * normal
    return pts, area, thickness


#: largest mesh file read (a 2-D mesh of a million elements is ~100 MB of text)
MAX_MESH_BYTES = 512 << 20


def _mesh(geo, scene_dir, thickness):
    """Points per element of a mesh file read with meshio (triangles and quads)."""
    import contextlib
    import io
    import os
    import meshio
    path = geo["file"] if os.path.isabs(geo["file"]) else os.path.join(scene_dir, geo["file"])
    if not os.path.isfile(path):  # also keeps meshio off devices such as /dev/zero
        raise ConfigError(path, "cannot read mesh (no such regular file)")
    if os.path.getsize(path) > MAX_MESH_BYTES:  # meshio reads it whole
        raise ConfigError(path, f"cannot read mesh (larger than {MAX_MESH_BYTES >> 20} MB)")
    said = io.StringIO()  # meshio prints reader errors and calls sys.exit(1) on unreadable files
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types; all mean "cannot use this file"
        # meshio's messages can quote the file's bytes: the error line names only the kind
        detail = ("not a mesh format meshio reads" if isinstance(exc, SystemExit)
                  else f"meshio: {type(exc).__name__}")
        raise ConfigError(path, f"cannot read mesh ({detail})") from None
    if said.getvalue().strip():
        logger.warning("meshio printed %d line(s) while reading %s", len(said.getvalue().splitlines()), path)
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] < 2 or not np.all(np.isfinite(points[:, :2])):
        raise ConfigError(path, "mesh node coordinates are missing or not finite")
    pts = points[:, :2] * geo["scale"] + np.asarray(geo["offset"])
    n = geo["particles_per_element"]
    out, vols = [], []
    scale = float(np.ptp(pts, axis=0).max()) if len(pts) else 0.0
    for block in mesh.cells:
        conn = np.asarray(block.data)
        if block.type not in ("triangle", "quad"):
            continue
        if conn.size and (conn.min() < 0 or conn.max() >= len(pts)):
            e = int(np.argmax((conn < 0).any(axis=1) | (conn >= len(pts)).any(axis=1)))
            raise ConfigError(path, f"{block.type} element {e} refers to a node that does not exist "
                                    f"(the mesh has {len(pts)} nodes)")
        corners = pts[conn]  # (E, k, 2)
        signed = 0.5 * np.sum(corners[:, :, 0] * np.roll(corners[:, :, 1], -1, axis=1)
                              - corners[:, :, 1] * np.roll(corners[:, :, 0], -1, axis=1), axis=1)
        degenerate = np.abs(signed) <= 1e-12 * scale * scale
        if degenerate.any():
            raise ConfigError(path, f"{block.type} element {int(np.argmax(degenerate))} has zero area "
                                    f"(coincident or collinear nodes)")
        if block.type == "triangle":
            # n points per triangle on a barycentric subdivision: k x k sub-triangles' centroids
            k = max(1, int(round(math.sqrt(n))))
            bary = [((i + 1 / 3) / k, (j + 1 / 3) / k) for i in range(k) for j in range(k - i)]
            bary += [((i + 2 / 3) / k, (j + 2 / 3) / k) for i in range(k) for j in range(k - i - 1)]
            a, b, c = pts[conn[:, 0]], pts[conn[:, 1]], pts[conn[:, 2]]
            area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
            for u, v in bary:
                out.append(a + u * (b - a) + v * (c - a))
                vols.append(area / len(bary) * thickness)
        elif block.type == "quad":
            k = max(1, int(round(math.sqrt(n))))
            q = [pts[conn[:, i]] for i in range(4)]
            for i in range(k):
                for j in range(k):
                    xi, et = (i + 0.5) / k * 2 - 1, (j + 0.5) / k * 2 - 1
                    N = [(1 - xi) * (1 - et) / 4, (1 + xi) * (1 - et) / 4, (1 + xi) * (1 + et) / 4, (1 - xi) * (1 + et) / 4]
                    dxi = [-(1 - et) / 4, (1 - et) / 4, (1 + et) / 4, -(1 + et) / 4]
                    det_ = [-(1 - xi) / 4, -(1 + xi) / 4, (1 + xi) / 4, (1 - xi) / 4]
                    x = sum(Ni * qi for Ni, qi in zip(N, q))
                    jx = sum(d * qi for d, qi in zip(dxi, q))
                    je = sum(d * qi for d, qi in zip(det_, q))
                    detJ = np.abs(jx[:, 0] * je[:, 1] - jx[:, 1] * je[:, 0])
                    out.append(x)
                    vols.append(detJ * 4 / (k * k) * thickness)
    if not out:
        raise ConfigError(path, "mesh has no triangle or quad cells")
    return np.concatenate(out), np.concatenate(vols)


def _exact_share(area, n):
    """Equal volumes that add up to the shape's exact area (a lattice clipped by a curved or
    slanted edge covers a slightly different area; mass and energy should not inherit that)."""
    return np.full(n, area / max(n, 1))


def body_points(body, grid, scene_dir, key="body"):
    """Positions (N, 2) and volumes (N,) of a body's material points (``key`` names it in errors)."""
    geo, ppc, t = body.geometry, body.particles_per_cell, body.thickness
    if body.shape == "rectangle":
        pts, area = _lattice(geo["lower"], geo["upper"], grid.h / ppc)
        return pts, np.full(len(pts), area * t)
    if body.shape == "circle":
        c, r = np.asarray(geo["center"]), geo["radius"]
        pts, area = _grid_lattice(grid, c - r, c + r, ppc)
        pts = pts[np.sum((pts - c) ** 2, axis=1) < r * r]
        return pts, _exact_share(math.pi * r * r, len(pts)) * t
    if body.shape == "polygon":
        verts = np.asarray(geo["vertices"])
        pts, area = _grid_lattice(grid, verts.min(axis=0), verts.max(axis=0), ppc)
        pts = pts[_inside_polygon(pts, verts)]
        x, y = verts[:, 0], verts[:, 1]
        shoelace = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        return pts, _exact_share(shoelace, len(pts)) * t
    if body.shape == "i_section":
        pts, area, thickness = _i_section(geo, grid, ppc, key)
        return pts, area * thickness
    return _mesh(geo, scene_dir, t)


def inside_body(body, pts, tol):
    """Mask of ``pts`` that lie inside ``body``'s shape by more than ``tol`` (None for a mesh,
    whose region is not tested)."""
    geo = body.geometry
    if body.shape == "rectangle":
        lo, hi = np.asarray(geo["lower"]) + tol, np.asarray(geo["upper"]) - tol
        return np.all((pts > lo) & (pts < hi), axis=1)
    if body.shape == "circle":
        r = geo["radius"] - tol
        return np.sum((pts - np.asarray(geo["center"])) ** 2, axis=1) < r * r
    if body.shape == "polygon":
        return _inside_polygon(pts, geo["vertices"])
    if body.shape == "i_section":
        start, end = np.asarray(geo["start"]), np.asarray(geo["end"])
        length = float(np.linalg.norm(end - start))
        direction = (end - start) / length
        rel = pts - start
        along = rel @ direction
        across = rel @ np.array([-direction[1], direction[0]])
        return (along > tol) & (along < length - tol) & (np.abs(across) < geo["depth"] / 2 - tol)
    return None


def check_overlaps(bodies, points_of, h):
    """Refuse two bodies whose regions overlap (their masses would add up there): a point of
    one lying inside another by more than 1e-6 of a cell. Touching is fine; meshes are not
    tested. ``points_of[k]`` are the points of body ``k``."""
    tol = 1e-6 * h
    for i, a in enumerate(bodies):
        for j, b in enumerate(bodies):
            if i == j or len(points_of[j]) == 0:
                continue
            inside = inside_body(a, points_of[j], tol)
            if inside is not None and inside.any():
                p = points_of[j][int(np.argmax(inside))]
                raise ConfigError(f"bodies[{max(i, j)}]", f"overlaps bodies[{min(i, j)}] (a point at "
                                                         f"({p[0]:g}, {p[1]:g}) lies in both); "
                                                         f"bodies may touch but not overlap")


def _initial_velocity(body, pts, key):
    """The body's velocity entries (numbers, or expressions in x, y parsed by
    :mod:`pmpm.scene.expressions`, never run as code) at its points; non-finite refused."""
    v = np.zeros((len(pts), 2))
    for d, entry in enumerate(body.velocity):
        if isinstance(entry, str):
            v[:, d] = parse_expression(entry, f"{key}.velocity").evaluate(pts[:, 0], pts[:, 1], f"{key}.velocity")
        else:
            v[:, d] = entry
    return v


def generate_body(k, body, grid, density, scene_dir):
    """Material points of body ``k``: dict with x, v, vol, m (all ranks build the same set)."""
    key = f"bodies[{k}]"
    pts, vol = body_points(body, grid, scene_dir, key)
    if len(pts) == 0:
        raise ConfigError(key, "holds no particle (smaller than the particle spacing?)")
    outside = ~grid.inside(pts)
    if outside.any():
        p = pts[np.argmax(outside)]
        raise ConfigError(key, f"lies outside the grid (a point at ({p[0]:g}, {p[1]:g}) is not inside "
                               f"[{grid.origin[0]:g}, {grid.upper[0]:g}] x [{grid.origin[1]:g}, {grid.upper[1]:g}])")
    return {"x": pts, "v": _initial_velocity(body, pts, key), "vol": vol, "m": density * vol}
