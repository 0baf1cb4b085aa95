"""Scene events: bodies removed during the run (a column lost, a member cut out).

``[[events]]`` with ``type = "remove"``, ``body`` (a body's name), ``time`` (s) and ``duration``
(s, may be 0): from ``time`` on, the stress the body's particles pass to the grid (their
internal force, with the viscous stress of Rayleigh damping if any) is scaled by
s = 1 - (t - time) / duration, so the member lets go of its load over ``duration`` (building
guidelines ask for a removal within a tenth of the structure's period: GSA 2016, section 3.2);
at ``time + duration`` the particles leave the run on every rank (they are no longer stored,
moved or written: rows of removed ids in the frames are NaN / -1, as for particles that left
the grid). The body's mass stays until then.

Energy (pmpm.core.solver energies, ``removed_energy``): the grid sees s sigma, while the
internal work integrates the particles' own sigma : de; the difference, (1 - s) sigma : de V
summed over the body's particles each step of the fade (sigma by the internal work's own
trapezoid rule), is work the fading member did not do on the rest, and is taken from
``removed_energy``. When the particles leave, their kinetic
energy and their share of the internal work (strain energy plus plastic work, as the
particles hold them) move from the kinetic energy and the internal work to ``removed_energy``.
So kinetic + internal work + damping works + removed energy stays the initial energy plus the
external work, as before the event (tests/unit/test_events.py checks it).

An event a scene does not name costs nothing: without ``[[events]]`` the solver holds no
events and the force stress is the particles' stress array itself.
"""
import logging

import numpy as np

from pmpm.core import kernels as K
from pmpm.core.effects import Effect, register_energy

__all__ = ["Events", "RemoveBody", "make_events"]
logger = logging.getLogger(__name__)

#: the energy term of events (J)
REMOVED_ENERGY = register_energy(
    "removed_energy", "energy carried out of the run by particles a scene event removed (their kinetic "
                      "energy at removal, less the internal work their fading stress did not transmit)")


class RemoveBody:
    """Remove body ``body`` (index) over [time, time + duration].

    Parameters
    ----------
    config : dict
        One ``Scene.events`` entry (pmpm.scene.analyses): name, body, time, duration.
    body_index : int
    """

    def __init__(self, config, body_index):
        self.name = config["body"]
        self.body = body_index
        self.time = config["time"]
        self.duration = config["duration"]
        self.done = False
        self._released = None   # (rows, (1 - s) sigma_force) of the step's force pass

    def factor(self, t):
        """The share s of the body's stress passed to the grid at time ``t``."""
        if t < self.time:
            return 1.0
        if self.duration <= 0 or t >= self.time + self.duration:
            return 0.0
        return 1.0 - (t - self.time) / self.duration

    def active(self, t):
        """True while the event scales forces (from its time until its particles left)."""
        return not self.done and t >= self.time

    def scale_force_stress(self, particles, stress, t):
        """Scale the body's rows of the force stress ``stress`` (N, 3; a copy the caller owns)
        by the factor at ``t``; remember what was held back for the energy balance: the
        share 1 - s, the rows, the particles' own stress there and the force stress's excess
        over it (the viscous stress of Rayleigh damping, if any)."""
        rows = np.flatnonzero(particles["body"] == self.body)
        s = self.factor(t)
        own = particles["stress"][rows, :3].copy()
        self._released = (1.0 - s, rows, own, stress[rows] - own)
        stress[rows] *= s

    def released_work(self, particles, de):
        """The work the fading stress did not pass on over the step of strain increment ``de``:
        (1 - s) sum V (sigma_mean + sigma_v) : de over the body's particles, sigma_mean the
        mean of their stress before and after the step's update (the trapezoid rule of the
        internal work, pmpm.core.solver.update_stress) and sigma_v the viscous stress that
        acted; call it after the stress update. 0 if nothing faded this step."""
        if self._released is None:
            return 0.0
        share, rows, before, viscous = self._released
        self._released = None
        acting = 0.5 * (before + particles["stress"][rows, :3]) + viscous
        return share * float(np.sum(particles["vol"][rows] * np.einsum("pk,pk->p", acting, de[rows])))

    def due(self, t_next):
        """True when the particles are to leave at the end of a step ending at ``t_next``."""
        return not self.done and t_next >= self.time + self.duration * (1 - 1e-12)

    def leaving(self, particles):
        """Boolean mask of this rank's particles of the body."""
        return particles["body"] == self.body

    def describe(self):
        return (f"event: body {self.name!r} removed from t = {self.time:g} s over {self.duration:g} s "
                f"(stress fading linearly, then its particles leave)")


def make_events(events, bodies):
    """The scene's events as objects (an empty list without ``[[events]]``)."""
    names = [b.name for b in bodies]
    return [RemoveBody(e, names.index(e["body"])) for e in events]


class Events(Effect):
    """The scene's ``[[events]]`` (effect ``events``): a fading body's rows of the force stress
    scaled, the work it held back and the energy its particles carry out as ``removed_energy``
    (module doc), the body's particles removed at the end of its event."""

    name = "events"
    energy_terms = (REMOVED_ENERGY,)

    @classmethod
    def create(cls, scene, setup):
        return cls(make_events(scene.events, scene.bodies)) if scene.events else None

    def __init__(self, events):
        self.events = events
        self.removed_energy = 0.0   # this rank's share, J
        self.removed_by_events = 0  # particles removed (global count)

    def __iter__(self):
        return iter(self.events)

    def __getitem__(self, k):
        return self.events[k]

    def __len__(self):
        return len(self.events)

    def edits_force_stress(self, t):
        return any(e.active(t) for e in self.events)

    def add_force_stress(self, s, out):
        for event in self.events:
            if event.active(s.t):
                event.scale_force_stress(s.particles, out, s.t)

    def after_stress_update(self, s):
        for event in self.events:  # what a fading body's stress did not pass to the grid
            self.removed_energy -= event.released_work(s.particles, s._de)

    def after_step(self, s):
        for event in self.events:
            if event.due(s.t):
                self.remove_body(s, event)

    def remove_body(self, s, event):
        """The particles of an event's body leave the run (collective: every rank at the same
        step). Their kinetic energy, strain energy and plastic work move to ``removed_energy``
        (the latter two out of the internal work, which they had entered)."""
        p = s.particles
        gone = event.leaving(p)
        part = p.take(gone)
        kinetic = K.kinetic_energy(part["m"], part["v"])
        held = s.held_energy(part)
        self.removed_energy += kinetic + held
        s.internal_work -= held
        s.particles = p.take(~gone)
        event.done = True
        count = int(s.decomp.allreduce_sum(int(gone.sum())))
        mass = s.decomp.allreduce_sum(float(part["m"].sum()))
        self.removed_by_events += count
        if s.decomp.rank == 0:
            logger.info("t = %.6g s: body %r removed (%d particles, %.6g kg)", s.t, event.name, count, mass)

    def restore(self, s, attrs):
        for event in self.events:  # a body removed before the checkpoint is not in it
            event.done = s.t >= event.time + event.duration * (1 - 1e-12)

    def describe(self):
        return [e.describe() for e in self.events]
