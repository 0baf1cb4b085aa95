"""Pushover: a displacement-controlled lateral push, slow enough to be quasi-static.

``[pushover]`` names a ``[[boundary]]`` of type ``roller_y`` (its nodes' x velocity is
prescribed, y free) or ``roller_x`` (y prescribed), and the run drives that component of its
nodes with the velocity profile

    v(t) = v0 r(t),  r = sin^2(pi t / (2 t_r)) for t < t_r, 1 up to T - t_r, then back to 0 at T

(t_r = ``ramp``, T = ``duration``), so that the nodes move by ``displacement`` in total,
v0 = displacement / (T - t_r), with no jump in velocity (no impact) and no acceleration between
the ramps. The boundary's other nodes' components stay as the scene sets them.

Why displacement control: past the sway mechanism the frame has (almost) no lateral stiffness
left, so a force that keeps rising cannot be resisted statically and the run turns dynamic; a
prescribed displacement passes through the mechanism and reads the capacity curve's plateau.

How slow: the push is quasi-static when the inertia forces are small beside the restoring
force. With the joint's displacement prescribed, the frame's own sway mode is held, and what
the push rings is the members' higher modes; at constant velocity nothing accelerates. The
check is the one the capacity curve's file reports: kinetic energy over strain energy plus
plastic work, which should stay a few per cent (docs/structural_results.md gives the portal's).
As a rule, ``duration`` of several first periods and ``ramp`` of about one.

Under the implicit integrator (``solver.analysis = "static"`` only) the pushed component is held
at the profile's displacement in each static step (``prescribe_increment``): displacement control
with no inertia, so no rate to choose; the time is then only the push's parameter.

The capacity curve itself (base shear from the reactions against the control point's drift)
is drawn after the run by pmpm.results.capacity.
"""
import math

import numpy as np

from pmpm.core.effects import Effect
from pmpm.errors import ConfigError
from pmpm.physics.boundary import select_nodes

__all__ = ["Pushover", "PUSHED_COMPONENT"]

#: the boundary types a pushover drives, and the component each prescribes
PUSHED_COMPONENT = {"roller_y": 0, "roller_x": 1}


class Pushover(Effect):
    """The pushed boundary's nodes and their velocity over time.

    Parameters
    ----------
    config : dict
        ``Scene.pushover`` (pmpm.scene.analyses).
    boundaries : sequence of BoundaryConfig
    """

    name = "pushover"
    #: statics: the implicit step holds the pushed nodes at their displacement
    #: (``prescribe_increment``); implicit dynamics is refused with the scene
    #: (pmpm.core.implicit.options)
    implicit_support = True

    @classmethod
    def create(cls, scene, setup):
        return cls(scene.pushover, scene.boundaries) if scene.pushover else None

    def __init__(self, config, boundaries):
        self.config = config
        bc = next(b for b in boundaries if b.name == config["boundary"])
        self.boundary = bc
        self.component = PUSHED_COMPONENT[bc.type]
        self.displacement = config["displacement"]
        self.duration = config["duration"]
        self.ramp = config["ramp"]
        self.v0 = self.displacement / (self.duration - self.ramp)
        self.nodes = None

    def velocity(self, t):
        """Prescribed velocity (m/s) at time ``t`` (the module's profile)."""
        T, tr = self.duration, self.ramp
        if t <= 0.0 or t >= T:
            return 0.0
        if tr > 0 and t < tr:
            return self.v0 * math.sin(0.5 * math.pi * t / tr) ** 2
        if tr > 0 and t > T - tr:
            return self.v0 * math.sin(0.5 * math.pi * (T - t) / tr) ** 2
        return self.v0

    def displacement_at(self, t):
        """Prescribed displacement (m) at ``t``: the integral of ``velocity``."""
        T, tr, v0 = self.duration, self.ramp, self.v0
        t = min(max(t, 0.0), T)

        def up(s):  # integral of sin^2(pi s / (2 tr)) from 0 to s <= tr
            return 0.5 * s - tr / (2 * math.pi) * math.sin(math.pi * s / tr) if tr > 0 else 0.0
        if t < tr:
            return v0 * up(t)
        if t <= T - tr:
            return v0 * (up(tr) + t - tr)
        return self.displacement - v0 * up(T - t)

    def bind(self, window):
        """Find the window's pushed nodes (after every window rebuild)."""
        self.nodes = np.nonzero(select_nodes(window, self.boundary))

    def apply(self, window, t):
        """Prescribe the pushed component of the nodes at the velocity of time ``t``."""
        window.bc_vel[self.nodes[0], self.nodes[1], self.component] = self.velocity(t)

    # -- effect hooks
    def on_window(self, s):
        self.bind(s.window)

    def before_grid_update(self, s, t_next):
        self.apply(s.window, t_next)

    def prescribe_increment(self, s, t0, h, U):
        """The implicit step's held increment of the pushed component: the profile's
        displacement from ``t0`` to ``t0 + h`` (a static pushover: displacement control, the
        pushing force the pushed boundary's reaction)."""
        U[self.nodes[0], self.nodes[1], self.component] = self.displacement_at(t0 + h) - self.displacement_at(t0)

    def describe(self):
        return [f"pushover: boundary {self.boundary.name!r} pushed {self.displacement:g} m along "
                f"{'xy'[self.component]} over {self.duration:g} s (ramps {self.ramp:g} s, "
                f"{self.v0:.4g} m/s), drift of {self.config['control']!r}"]
