"""The first fracture of each body and its time: the record a run with ductile fracture keeps.

An effect (pmpm.core.effects) that exists only when a material of the scene names
``[materials.<label>.fracture]`` (pmpm.physics.materials.fracture): after each stress update it
looks for failed points (damage 1) in the bodies that have not failed yet, and notes the end
time of the step in which a body's first point failed. The run summary gets
``first_fracture`` = {body name: time (s)}, the earliest over the ranks, and the log one line
per fractured body. (After a restart the bodies that had failed before it are reported at the
restart's time: the times themselves are not in the checkpoint yet.)
"""
import logging

import numpy as np

from pmpm.core.effects import Effect

__all__ = ["FractureRecord"]
logger = logging.getLogger(__name__)


class FractureRecord(Effect):
    """First failed point per body (module doc)."""

    name = "fracture"

    @classmethod
    def create(cls, scene, setup):
        if not any(getattr(m, "fracture", None) for m in setup.materials):
            return None
        return cls([b.name for b in scene.bodies])

    def __init__(self, body_names):
        self.body_names = list(body_names)
        self.first = {}          # body index -> end time of the step of its first failure (this rank)

    def after_stress_update(self, s):
        damage = s.particles.fields.get("damage")
        if damage is None or len(self.first) == len(self.body_names):
            return
        failed = damage >= 1.0
        if not failed.any():
            return
        t_end = s.t + s._dt_step
        for b in np.unique(s.particles["body"][failed]):
            if b >= 0:
                self.first.setdefault(int(b), t_end)

    def summary(self, s):
        """{"first_fracture": {body name: time}} over every rank (collective)."""
        merged = {}
        for part in s.comm.allgather(self.first):
            for b, t in part.items():
                merged[b] = min(t, merged.get(b, t))
        first = {self.body_names[b]: merged[b] for b in sorted(merged, key=merged.get)}
        if s.comm.Get_rank() == 0:
            for name, t in first.items():
                logger.info("first fracture: body %r at t = %.6g s", name, t)
            if not first:
                logger.info("first fracture: none")
        return {"first_fracture": first}

    def describe(self):
        return ["ductile fracture (damage, release of failed points' tension)"]
