"""Ground motion: a base-acceleration record imposed on the fixed base nodes.

The record is read from a two-column text file (time, acceleration in m/s^2) or a PEER NGA
``.AT2`` file (acceleration in g at a fixed DT, converted with g = 9.80665 m/s^2), scaled by
``scale``. The ground velocity is the exact integral of the piecewise-linear acceleration; each
step the nodes of the chosen ``fixed`` boundaries move with it along ``direction`` (the other
component stays fixed), so a structure carried rigidly by the ground moves with no strain.

Under the implicit integrator (``GroundMotionImplicit``, docs/implicit.md) the formulation is the
same, absolute: the driven nodes are held components of the step whose displacement increment
is the ground's, the exact integral of the ground velocity over the step (the record's
piecewise-linear acceleration integrated twice), and whose velocity change and end acceleration,
which the particles near the supports receive, are the ground's; no effective load -M a_g is
applied, displacements and velocities are absolute (drifts are differences of points).

With slaved edge nodes (``[solver.implicit] edge_mass_ratio``, pmpm.core.implicit.edges) nothing
is folded for the term: the driven nodes are held, and a held node is never slaved; a slaved
node's targets may be driven nodes, and its extrapolated increment, u_o = 2 u_a - u_b, is read
from the step's whole displacement, held increments included (the residual is evaluated at it,
and the tangent's columns of held components drop out with their zero corrections), so the
prescribed motion reaches it. At the commit the supports' velocity change and acceleration are
written before the expansion (pmpm.core.implicit.scheme), for the same reason.
"""
import logging
import os
import re

import numpy as np

from pmpm.core.effects import Effect
from pmpm.core.implicit.terms import ImplicitTerm
from pmpm.errors import ConfigError
from pmpm.files import read_regular
from pmpm.physics.boundary import select_nodes

__all__ = ["GroundMotion", "read_record"]
logger = logging.getLogger(__name__)

G = 9.80665
#: largest scaled ground acceleration (m/s^2): recorded earthquakes stay below about 5 g; 1000 g
#: is a unit or scale typo, and its velocities would need steps no stable run can take (a record
#: scaled past 1e300 g overflowed to inf and failed with exit 3 after the run had started)
MAX_GROUND_ACCELERATION = 1000 * G


#: largest record file read (a long record at 0.005 s holds a few MB)
MAX_RECORD_BYTES = 64 << 20


def _read_text(path):
    """The file as text; refuses devices, huge and non-UTF-8 files (never quoting them)."""
    raw = read_regular(path, MAX_RECORD_BYTES)  # non-blocking: a FIFO is refused, not waited on
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"not UTF-8 text (byte {exc.start})") from None


def _numbers(text, first_line):
    """Floats of whitespace/comma separated text; the error names the line, not its content."""
    out = []
    for k, line in enumerate(text.splitlines()):
        for word in line.replace(",", " ").split():
            try:
                out.append(float(word))
            except ValueError:
                raise ValueError(f"line {first_line + k} holds something that is not a number") from None
    return np.array(out, dtype=float)


def _read_at2(path):
    lines = _read_text(path).splitlines()
    header = " ".join(lines[:4]).upper()
    npts = re.search(r"NPTS\s*=\s*(\d+)", header)
    dt = re.search(r"DT\s*=\s*([0-9.Ee+-]+)", header)
    if not (npts and dt):
        raise ValueError("no 'NPTS=' and 'DT=' in the first four lines (PEER .AT2 header)")
    try:
        step = float(dt.group(1))
    except ValueError:
        raise ValueError("the header's DT is not a number") from None
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"the header's DT must be a positive number (got {step:g})")
    values = _numbers("\n".join(lines[4:]), 5)
    n = int(npts.group(1))
    if len(values) < n:
        raise ValueError(f"header says NPTS={n} but the file holds {len(values)} values")
    t = np.arange(n) * step
    return t, values[:n] * G


def _read_two_column(path):
    rows = []
    for k, line in enumerate(_read_text(path).splitlines()):
        line = line.split("#")[0].split("%")[0].strip()
        if not line:
            continue
        row = _numbers(line, k + 1)
        if len(row) != 2:
            raise ValueError(f"line {k + 1}: expected two columns (time, acceleration), found {len(row)}")
        rows.append(row)
    if not rows:
        raise ValueError("no data lines")
    data = np.array(rows)
    t, a = data[:, 0], data[:, 1]
    if not np.all(np.isfinite(t)):
        raise ValueError(f"time on data line {int(np.argmax(~np.isfinite(t))) + 1} is not finite")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must increase")
    return t, a


def read_record(path, fmt="auto"):
    """(t, a) of an acceleration record in SI units; a ConfigError naming the file if unusable
    (the reason never quotes the file's contents)."""
    if fmt == "auto":
        fmt = "at2" if path.lower().endswith(".at2") else "two_column"
    try:
        t, a = _read_at2(path) if fmt == "at2" else _read_two_column(path)
    except OSError as exc:
        raise ConfigError(path, f"cannot read ground motion ({exc.strerror or type(exc).__name__})") from None
    except ValueError as exc:
        raise ConfigError(path, f"not a valid {fmt} acceleration record ({exc})") from None
    if len(t) < 2 or not np.all(np.isfinite(a)):
        raise ConfigError(path, "ground motion needs at least two samples, all finite")
    return t, a


class GroundMotion(Effect):
    """The record, its velocity, and the base nodes it drives.

    Parameters
    ----------
    config : dict
        ``LoadsConfig.ground_motion``.
    boundaries : sequence of BoundaryConfig
    scene_dir : str
        Relative record paths are relative to the scene file.
    """

    name = "ground_motion"

    @classmethod
    def create(cls, scene, setup):
        ground = scene.loads.ground_motion
        return cls(ground, scene.boundaries, setup.scene_dir) if ground else None

    def __init__(self, config, boundaries, scene_dir):
        path = config["file"]
        path = path if os.path.isabs(path) else os.path.join(scene_dir, path)
        self.t, a = read_record(path, config["format"])
        with np.errstate(over="ignore", invalid="ignore"):
            self.a = a * config["scale"]
            peak = float(np.max(np.abs(self.a))) if len(self.a) else 0.0
        if not peak <= MAX_GROUND_ACCELERATION:  # before any step: a typo, not a record
            raise ConfigError("loads.ground_motion.scale", f"gives a peak ground acceleration of "
                                                           f"{peak / G:.3g} g, more than "
                                                           f"{MAX_GROUND_ACCELERATION / G:g} g")
        dt = np.diff(self.t)
        self.v = np.concatenate([[0.0], np.cumsum(0.5 * (self.a[1:] + self.a[:-1]) * dt)])
        # ground displacement at the samples: the integral of the velocity (exact for
        # piecewise-linear acceleration: v_k h + a_k h^2 / 2 + (a_k+1 - a_k) h^2 / 6 a sample)
        self.d = np.concatenate([[0.0], np.cumsum(self.v[:-1] * dt + self.a[:-1] * dt ** 2 / 2
                                                  + (self.a[1:] - self.a[:-1]) * dt ** 2 / 6)])
        self.direction = 0 if config["direction"] == "x" else 1
        # the box supports (a boundary attached to a body holds particles, not nodes)
        names = config["boundaries"] or [b.name for b in boundaries if b.type == "fixed" and b.body is None]
        chosen = []
        for name in names:
            match = [b for b in boundaries if b.name == name]
            if not match:
                raise ConfigError("loads.ground_motion.boundaries", f"no [[boundary]] named {name!r}")
            if match[0].body is not None:
                raise ConfigError("loads.ground_motion.boundaries",
                                  f"boundary {name!r} is attached to a body: ground motion moves box supports")
            if match[0].type != "fixed":
                raise ConfigError("loads.ground_motion.boundaries", f"boundary {name!r} is not 'fixed'")
            chosen.append(match[0])
        if not chosen:
            raise ConfigError("loads.ground_motion", "needs a 'fixed' [[boundary]] to move")
        self.boundaries = chosen
        self.nodes = None

    def describe(self):
        return [f"ground motion along {'xy'[self.direction]}: {len(self.t)} samples over "
                f"{self.t[-1]:g} s, peak {np.abs(self.a).max():.3g} m/s^2"]

    def velocity(self, time):
        """Ground velocity at ``time`` (exact for piecewise-linear acceleration)."""
        if time <= self.t[0]:
            return 0.0
        if time >= self.t[-1]:
            return float(self.v[-1] + self.a[-1] * 0.0)
        k = int(np.searchsorted(self.t, time) - 1)
        tau = time - self.t[k]
        h = self.t[k + 1] - self.t[k]
        return float(self.v[k] + self.a[k] * tau + (self.a[k + 1] - self.a[k]) * tau * tau / (2 * h))

    def acceleration(self, time):
        """Ground acceleration at ``time`` (the record's linear interpolation; 0 outside it:
        the velocity stays at its last value, as ``velocity`` says)."""
        if time <= self.t[0] or time >= self.t[-1]:
            return 0.0
        return float(np.interp(time, self.t, self.a))

    def displacement(self, time):
        """Ground displacement at ``time`` (exact for piecewise-linear acceleration; after the
        record, the last velocity carries on)."""
        if time <= self.t[0]:
            return 0.0
        if time >= self.t[-1]:
            return float(self.d[-1] + self.v[-1] * (time - self.t[-1]))
        k = int(np.searchsorted(self.t, time) - 1)
        tau = time - self.t[k]
        h = self.t[k + 1] - self.t[k]
        return float(self.d[k] + self.v[k] * tau + self.a[k] * tau ** 2 / 2
                     + (self.a[k + 1] - self.a[k]) * tau ** 3 / (6 * h))

    def bind(self, window):
        """Find the window's nodes of the driven boundaries (after every window rebuild)."""
        sel = np.zeros(window.shape, dtype=bool)
        for bc in self.boundaries:
            sel |= select_nodes(window, bc)
        self.nodes = np.nonzero(sel)

    def apply(self, window, time):
        """Set the driven nodes' prescribed velocity to the ground velocity at ``time``."""
        window.bc_vel[self.nodes[0], self.nodes[1], self.direction] = self.velocity(time)

    # -- effect hooks
    implicit_support = True

    def implicit_term(self, s):
        """The driven supports' motion in the implicit step (module doc)."""
        return GroundMotionImplicit(self)

    #: with slaved edge nodes (edge_mass_ratio): the driven nodes are held, so never slaved; a
    #: slaved node's targets may be driven nodes, whose prescribed increments the expansion
    #: reads from the step's displacement (module doc). The term adds no force of its own.
    implicit_term_folded = True

    def on_window(self, s):
        self.bind(s.window)

    def before_grid_update(self, s, t_next):
        self.apply(s.window, t_next)


class GroundMotionImplicit(ImplicitTerm):
    """The driven nodes' motion over an implicit step (module doc): held components whose
    displacement increment, velocity change and end acceleration are the ground's."""

    def __init__(self, effect):
        self.effect = effect

    def prescribe_start(self, s, t0, v, a):
        g = self.effect
        v[g.nodes[0], g.nodes[1], g.direction] = g.velocity(t0)
        a[g.nodes[0], g.nodes[1], g.direction] = g.acceleration(t0)

    def prescribe(self, s, t0, h, u, dv, a):
        g = self.effect
        i, j, k = g.nodes[0], g.nodes[1], g.direction
        if u is not None:
            u[i, j, k] = g.displacement(t0 + h) - g.displacement(t0)
        if dv is not None:
            dv[i, j, k] = g.velocity(t0 + h) - g.velocity(t0)
        if a is not None:
            a[i, j, k] = g.acceleration(t0 + h)
