"""External loads a scene asks for: gravity and total forces on particle sets.

A force set is the particles of the bodies the force names (``body``), narrowed to those whose
initial position lies in its box if it has one; a force that names no body takes every particle
in its box, whatever body it belongs to (``pmpm case.toml --check`` says when such a box
catches several bodies: :func:`box_load_report`). The set's total force (scaled by its time
function) is shared among them by mass. Each particle belongs to at most
one set, recorded in its ``load_id`` / ``load_w`` fields (they exist only when the scene has
forces, and migrate with the particle). With no loads the kernels receive ``None`` and compile
without the code.
"""
import logging

import numpy as np

from pmpm.core import kernels as K
from pmpm.core.effects import Effect
from pmpm.errors import ConfigError
from pmpm.physics.timefunctions import evaluate

__all__ = ["Loads", "select", "box_load_report"]
logger = logging.getLogger(__name__)


def _in_box(x, lower, upper):
    return np.all((x >= np.asarray(lower)) & (x <= np.asarray(upper)), axis=1)


def select(force, x0, body):
    """Mask of the particles ``force`` acts on: of its bodies (``body_ids``), in its box."""
    sel = np.ones(len(x0), dtype=bool) if force.lower is None else _in_box(x0, force.lower, force.upper)
    if force.body_ids:
        sel &= np.isin(body, np.asarray(force.body_ids, dtype=body.dtype))
    return sel


def box_load_report(forces, x0, body, m, body_names):
    """Lines for ``--check``: each force that names no body and whose box catches the particles
    of more than one body (its load is shared among them by mass), with each body's share."""
    lines = []
    for k, f in enumerate(forces):
        if f.body_ids:
            continue
        sel = select(f, x0, body)
        caught = np.unique(body[sel])
        if len(caught) > 1:
            mass = np.bincount(body[sel], weights=m[sel], minlength=len(body_names))
            shares = ", ".join(f"{body_names[b]!r} {mass[b] / mass.sum():.1%}" for b in caught)
            lines.append(f"warning: loads.forces[{k}] ({f.name!r}): its box catches {len(caught)} bodies, "
                         f"the load is shared among them by mass ({shares}); "
                         f"name the body it acts on with body = \"...\"")
    return lines


class Loads(Effect):
    """Gravity vector and force sets of a scene (effect ``loads``: gravity is the kernels'
    body acceleration, the force sets are scattered after the force pass).

    Parameters
    ----------
    config : LoadsConfig
    """

    name = "loads"
    #: the implicit integrator scatters gravity and the force sets itself (pmpm.core.implicit.scheme)
    implicit_support = True

    @classmethod
    def create(cls, scene, setup):
        loads = scene.loads
        return cls(loads) if loads.gravity is not None or loads.forces else None

    def __init__(self, config):
        self.config = config
        self.gravity = None if config.gravity is None else np.asarray(config.gravity, dtype=np.float64)
        self.body_acceleration = self.gravity
        self.forces = config.forces
        self._vec = np.zeros((len(self.forces), 2))
        self._idx, self._idx_of = None, None

    @property
    def has_forces(self):
        return bool(self.forces)

    def describe(self):
        """Effect lines for the start-up log."""
        out = []
        if self.gravity is not None:
            out.append(f"gravity ({self.gravity[0]:g}, {self.gravity[1]:g}) m/s^2")
        for f in self.forces:
            out.append(f"force {f.name!r}: {f.force} N, {f.time_function['type']}")
        return out

    def add_fields(self, particles, setup):
        self.assign(particles.fields, setup.decomp.allreduce_sum)

    def assign(self, fields, allreduce_sum):
        """Add ``load_id``/``load_w`` to the particle ``fields`` (all ranks call it)."""
        if not self.forces:
            return
        x0, m = fields["x0"], fields["m"]
        load_id = np.full(len(m), -1, dtype=np.int32)
        load_w = np.zeros(len(m))
        for k, f in enumerate(self.forces):
            sel = select(f, x0, fields["body"])
            if np.any(sel & (load_id >= 0)):
                other = self.forces[load_id[np.argmax(sel & (load_id >= 0))]].name
                raise ConfigError(f"loads.forces[{k}]", f"overlaps force {other!r}: they select the same "
                                                        f"particles (a particle takes one set)")
            total = allreduce_sum(float(m[sel].sum()))
            if total <= 0:
                raise ConfigError(f"loads.forces[{k}]", "selects no particle of its bodies" if f.body_ids
                                  else "box selects no particle")
            load_id[sel] = k
            load_w[sel] = m[sel] / total
        fields["load_id"], fields["load_w"] = load_id, load_w

    def kernel_args(self, particles, t):
        """(gravity, load_id, load_w, load_vec) for kernels that take every load in their
        particle loop (``None`` where absent). The main solver uses :meth:`point_forces`."""
        if not self.forces:
            return self.gravity, None, None, None
        return self.gravity, particles["load_id"], particles["load_w"], self.vectors(t)

    def vectors(self, t):
        """(n_sets, 2) total force of every set at time ``t``."""
        for k, f in enumerate(self.forces):
            self._vec[k] = np.asarray(f.force) * evaluate(f.time_function, t)
        return self._vec

    def point_forces(self, particles, t):
        """(idx, load_id, load_w, load_vec) of the loaded particles at time ``t``, or None.

        ``idx`` is cached per ``load_id`` array: sorting and migration replace the particle
        arrays, so a new array object means the indices must be found again."""
        if not self.forces:
            return None
        load_id = particles["load_id"]
        if self._idx_of is not load_id:
            self._idx = np.flatnonzero(load_id >= 0).astype(np.int64)
            self._idx_of = load_id
        return self._idx, load_id, particles["load_w"], self.vectors(t)

    # -- effect hooks: the force sets (gravity is in the kernels' particle loops)
    def scatter_forces(self, s):
        """Scatter the force sets' shares onto the grid (after the force pass)."""
        point = self.point_forces(s.particles, s.t)
        if point is not None:
            idx, load_id, load_w, load_vec = point
            K.scatter_point_loads(idx, s.particles["x"], load_id, load_w, load_vec, *s._geometry())

    def after_move(self, s):
        """Work of the set forces over this step's moves (the forces of the step's start)."""
        point = self.point_forces(s.particles, s.t)
        if point is not None:
            idx, load_id, load_w, load_vec = point
            s.external_work += K.point_load_work(idx, s._dx, load_id, load_w, load_vec)
