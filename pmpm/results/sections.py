"""Section cuts: the axial force N, shear V and bending moment M across a member.

Integration rule
----------------
A cut is a straight line through the point ``c`` with unit normal ``n`` (for a member given
by name: its axis, from start to end) and tangent ``e = (-n_y, n_x)``. The line integrals

    N = int sigma_nn t ds,   V = -int e.(sigma n) t ds,   M = int eta sigma_nn t ds

(``t`` the out-of-plane thickness, ``eta = (x - c).e`` the distance along the cut) are the
force and moment that the part on the start side (-n) exerts on the part on the end side
(+n), about ``c``: N positive in tension, M anticlockwise positive. For a column standing on
a support the cut's forces are the support's reaction carried to the cut; for a cantilever
along +x built in at its start under a downward tip load P, V = P and M = P (L - x).

MPM stresses are point values, so the integral over the line is taken as the mean over a band
of width ``b`` (default: two grid cells) centred on the cut::

    int f t ds  ~  (1/b) sum_p phi_p V_p f_p

where ``phi_p`` is the fraction of particle p's domain (its lattice spacing ``l`` along n, in
the reference configuration) inside the band. Particles are chosen by their initial position
(the cut is material: it moves with the member). For the regular lattices of pmpm's bodies
with b a multiple of l the fractions are 0 or 1 and every particle row across the member
counts with its full weight, so the depth integral is the same point quadrature the strip's
thicknesses are fitted to (bodies.py: the strip's discrete A and I equal the section's).
Accuracy: a resultant that varies linearly along the member (M under end loads) is recovered
exactly by the symmetric band mean; a quadratic variation (distributed load) is off by
b^2 M''/24; what remains is the MPM stress error itself (cubic B-splines: a few per cent of the
stress at 2 particles per cell near supports and load points, less in a member's interior;
tests/verification/test_equilibrium.py measures it on a cantilever). Small strains and
rotations are assumed for n, e and b (they are not updated with the deformation).
"""
import logging
from dataclasses import dataclass

import numpy as np

from pmpm.core.effects import Effect
from pmpm.errors import ConfigError
from pmpm.results.hinges import cut_properties

__all__ = ["SectionCut", "SectionCuts", "make_cuts", "particle_spacing", "section_properties"]
logger = logging.getLogger(__name__)

#: default band width in cells: two cells average out the ringing of period 2h that cubic
#: B-spline stresses show within a few cells of a support (docs/structural_results.md)
DEFAULT_WIDTH_CELLS = 2


@dataclass
class SectionCut:
    """Geometry of one cut (see the module docstring for the rule)."""
    name: str
    key: str            # its scene key, for error messages
    center: np.ndarray  # c: the moment point
    normal: np.ndarray  # n
    half_length: float  # particles with |(x0 - c).e| <= half_length
    width: float        # band width b
    spacing: float      # particle domain length l along n
    body: int           # -1: any body (segment cuts)
    properties: dict = None  # A, I, Z and capacities (pmpm.results.hinges)

    @property
    def tangent(self):
        return np.array([-self.normal[1], self.normal[0]])

    def weights(self, x0, body):
        """Band fraction phi (0 outside) of particles at initial positions ``x0``."""
        d = x0 - self.center
        s = d @ self.normal
        eta = d @ self.tangent
        lo = np.maximum(s - self.spacing / 2, -self.width / 2)
        hi = np.minimum(s + self.spacing / 2, self.width / 2)
        phi = np.clip(hi - lo, 0.0, None) / self.spacing
        phi[np.abs(eta) > self.half_length] = 0.0
        if self.body >= 0:
            phi[body != self.body] = 0.0
        return phi

    def resultants(self, x, stress, vol, phi):
        """(N, V, M) of the particles with band fractions ``phi`` (a rank's partial sums)."""
        n, e = self.normal, self.tangent
        w = phi * vol / self.width
        tn_x = stress[:, 0] * n[0] + stress[:, 2] * n[1]
        tn_y = stress[:, 2] * n[0] + stress[:, 1] * n[1]
        s_nn = tn_x * n[0] + tn_y * n[1]
        s_en = tn_x * e[0] + tn_y * e[1]
        eta = (x - self.center) @ e
        return np.array([np.dot(w, s_nn), -np.dot(w, s_en), np.dot(w * eta, s_nn)])


def _lattice_steps(length, spacing):
    """The step bodies.py's lattice takes over ``length`` for a wanted ``spacing``."""
    return length / max(1, int(round(length / spacing)))


def particle_spacing(body, grid, normal):
    """Reference lattice spacing of ``body``'s particles along the unit vector ``normal``
    (exact for cuts along the lattice axes; a projection of the two steps otherwise)."""
    d = grid.h / body.particles_per_cell
    geo = body.geometry
    if body.shape == "i_section":
        start, end = np.asarray(geo["start"]), np.asarray(geo["end"])
        length = float(np.linalg.norm(end - start))
        axis = (end - start) / length
        along, across = _lattice_steps(length, d), _lattice_steps(geo["depth"], d)
        return abs(normal @ axis) * along + abs(normal[0] * axis[1] - normal[1] * axis[0]) * across
    if body.shape == "rectangle":
        dx = _lattice_steps(geo["upper"][0] - geo["lower"][0], d)
        dy = _lattice_steps(geo["upper"][1] - geo["lower"][1], d)
        return abs(normal[0]) * dx + abs(normal[1]) * dy
    return d  # grid-aligned lattices (circle, polygon); meshes: about one element's points


def section_properties(body):
    """(A, I, S, Z, depth) of an i_section body's W shape (A, I as given or from the
    plates; Z of the plates: 2 bf tf (d - tf)/2 + tw (d - 2 tf)^2 / 4)."""
    g = body.geometry
    d, bf, tf, tw = g["depth"], g["flange_width"], g["flange_thickness"], g["web_thickness"]
    hw = d - 2 * tf
    A = g["area"] or (2 * bf * tf + hw * tw)
    I = g["inertia"] or (bf * d ** 3 - (bf - tw) * hw ** 3) / 12
    Z = bf * tf * (d - tf) + tw * hw ** 2 / 4
    return A, I, I / (d / 2), Z, d


def _cut(k, cfg, scene, grid):
    key = f"output.section[{k}]"
    if cfg.body is not None:
        b = [x.name for x in scene.bodies].index(cfg.body)
        body = scene.bodies[b]
        start, end = np.asarray(body.geometry["start"]), np.asarray(body.geometry["end"])
        axis = (end - start) / np.linalg.norm(end - start)
        center, normal = start + cfg.position * axis, axis
        spacing = particle_spacing(body, grid, normal)
        half = body.geometry["depth"] / 2 + spacing  # the whole depth, the body only
    else:
        p1, p2 = np.asarray(cfg.segment[0]), np.asarray(cfg.segment[1])
        tangent = (p2 - p1) / np.linalg.norm(p2 - p1)
        center, normal = 0.5 * (p1 + p2), np.array([tangent[1], -tangent[0]])
        half, b, spacing = 0.5 * float(np.linalg.norm(p2 - p1)), -1, None
    return SectionCut(cfg.name, key, center, normal, half, cfg.width or DEFAULT_WIDTH_CELLS * grid.h,
                      spacing, b)


def make_cuts(scene, grid, points):
    """The scene's cuts, checked against the scene's particles ``points`` (every rank holds
    all of them at set-up): a cut must meet exactly one member, across its whole band."""
    cuts = []
    for k, cfg in enumerate(scene.output.sections):
        cut = _cut(k, cfg, scene, grid)
        if cut.spacing is None:  # segment: the spacing of the body it crosses
            cut.spacing = grid.h / scene.bodies[0].particles_per_cell
            hit = _touched_bodies(cut, points)
            if len(hit) == 0:
                raise ConfigError(f"{cut.key}.segment", "misses every member (no particle on the cut)")
            if len(hit) > 1:
                names = ", ".join(repr(scene.bodies[i].name) for i in hit)
                raise ConfigError(f"{cut.key}.segment", f"crosses more than one member ({names})")
            cut.spacing = particle_spacing(scene.bodies[hit[0]], grid, cut.normal)
        phi = cut.weights(points["x"], points["body"])
        if not phi.any():
            raise ConfigError(cut.key, "misses every member (no particle on the cut)")
        _check_band_inside(cut, points, phi)
        cut.properties = cut_properties(cut, cfg, scene, points)
        cuts.append(cut)
    return cuts


def _touched_bodies(cut, points):
    phi = cut.weights(points["x"], points["body"])
    return sorted(set(points["body"][phi > 0].tolist()))


def _check_band_inside(cut, points, phi):
    """The band must lie inside the member along n: a band hanging over a member's end would
    integrate a part of the section and report it as the whole. Thin probes at the band's
    centre and just inside both of its edges must each meet as many particles."""
    probe = SectionCut(cut.name, cut.key, cut.center, cut.normal, cut.half_length,
                       1e-6 * cut.spacing, cut.spacing, cut.body)
    counts = []
    for offset in (0.0, -0.5, 0.5):
        probe.center = cut.center + offset * (cut.width - 2e-6 * cut.spacing) * cut.normal
        counts.append(np.count_nonzero(probe.weights(points["x"], points["body"])))
    if min(counts[1:]) < 0.5 * counts[0]:
        raise ConfigError(cut.key, f"its band (width {cut.width:g} m) leaves the member: move the "
                                   "cut at least half a band away from the member's end")



class SectionCuts(Effect):
    """The scene's section cuts (effect ``sections``, ``[[output.section]]``): found and checked
    at construction on the scene's particles; the run's recorder samples them (no step hook)."""

    name = "sections"
    #: read from the particles' stresses at the samples: a converged implicit step's as well
    implicit_support = True

    @classmethod
    def create(cls, scene, setup):
        return cls(make_cuts(scene, setup.grid, setup.points)) if scene.output.sections else None

    def __init__(self, cuts):
        self.cuts = cuts

    def __iter__(self):
        return iter(self.cuts)

    def __len__(self):
        return len(self.cuts)
