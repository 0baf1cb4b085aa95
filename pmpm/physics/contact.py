"""Contact between bodies with friction: separate velocity fields per body.

The default grid fields (pmpm.core.fields.GridFields) map every particle to one nodal velocity
field, so bodies whose shape function supports overlap share nodal velocities and stick
together. With a ``[contact]`` section the run's grid fields are :class:`BodyFields` instead
(the solver's grid phases delegate to them), the multi-velocity-field algorithm of
Bardenhagen, Brackbill & Sulsky (2000) and Bardenhagen et al. (2001):

* each contact body (``contact.bodies``, default every body; the bodies not named share one
  more field) maps its mass, momentum, force and mass gradient sum_p m_p grad N_i to its own
  nodal fields, a *slot* of the body window ``B`` (:mod:`pmpm.core.kernels.contact`);
* at nodes where two or more slots have mass, a slot approaching the centre of mass along the
  contact normal loses its normal relative velocity, and its tangential relative velocity by at
  most ``friction`` times that (Coulomb); separating bodies are left alone, components that an
  essential BC constrains are not touched (the rule, the normal and the facing test are in
  :mod:`pmpm.core.kernels.contact`);
* the correction is made twice a step, as Uintah's friction contact does: on the momenta mapped
  from the particles, so that the momentum update starts from a field without interpenetration
  (this one is not passed on to the particles: their velocities change through the stresses the
  held surfaces build up), and on the updated velocities, by the same amount on the velocity
  change FLIP adds to the particles. The velocities from which USF and MUSL take the strain
  increment are corrected the same way;
* each slot's nodal update is the single field's own (``GridFields.update_grid`` and
  ``GridFields.grid_velocity`` run on each slot as if it were the single field: BCs, damping,
  moving supports and their energy accounting included);
* grid to particles, the MUSL re-map, the strain increment and the position update use each
  particle's own slot.

Everything else (materials, loads, migration, output, the schemes' ordering of the phases) is
the solver's (:class:`~pmpm.core.solver.Solver`). The per-body fields, mass gradient included, go through
the same halo accumulate/fill as the single field. Without ``[contact]`` none of this is
imported or run.
"""
import logging

import numpy as np

from pmpm.core.kernels import contact as KC
from pmpm.core.fields import GridFields

__all__ = ["BodyFields", "contact_slots"]
logger = logging.getLogger(__name__)

#: first single-field index (pmpm.core.kernels) that the body layout shifts to make room for the
#: mass gradient, and by how much
_FIRST_SHIFTED = 5
_SHIFT = KC.REMAP - _FIRST_SHIFTED


def contact_slots(scene):
    """(slot of each body, number of slots): the bodies named in ``contact.bodies`` get a slot
    each, in scene order; the others, if any, share the last one."""
    own = set(scene.contact.bodies)
    slot_of = np.empty(len(scene.bodies), dtype=np.int32)
    k = 0
    for b, body in enumerate(scene.bodies):
        if body.name in own:
            slot_of[b] = k
            k += 1
    rest = [b for b, body in enumerate(scene.bodies) if body.name not in own]
    slot_of[rest] = k
    return slot_of, k + (1 if rest else 0)


def _field(f):
    """Body-layout index of single-field index ``f`` (the schemes name fields in that layout)."""
    return f if f < _FIRST_SHIFTED else f + _SHIFT


class BodyFields(GridFields):
    implicit_support = False   # (no contact correction in the implicit equations yet)
    scene_key = "contact"
    """One velocity field per contact body (scene ``[contact]``): the grid phases of the solver
    ``s`` on the body window ``B``.

    Parameters
    ----------
    friction : float
        Coulomb friction coefficient (``contact.friction``).
    slot_of, n_slots : the velocity field of each body and their number (``contact_slots``)
    """

    def __init__(self, friction, slot_of, n_slots):
        self.friction = float(friction)
        self.slot_of, self.n_slots = slot_of, n_slots
        self.corrections = 0  # (node, slot) corrections on this rank, ghosts included
        self.B = None

    def describe(self):
        """The run header's line of the physics these fields add."""
        return [f"contact with friction {self.friction:g} ({self.n_slots} velocity fields)"]

    def _load_args(self, s):
        """(gravity, load_id, load_w, load_vec) of the loads effect for the body kernels, which
        take every load in their particle loop (None where absent)."""
        loads = s.effect("loads")
        return loads.kernel_args(s.particles, s.t) if loads is not None else (None,) * 4

    # -- the body window ---------------------------------------------------------------------
    def on_window(self, s):
        self.B = np.zeros((*s.window.shape, self.n_slots, KC.N_BODY_FIELDS))

    def _body_geometry(self, s):
        w, g = s.window, s.grid
        return (self.B, w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape)

    def _halo_views(self, fields):
        """Views of ``B`` for the single-field slice ``fields``: those fields of every slot; the
        mass gradient travels with the mass."""
        a, b = fields.start, fields.stop
        a2, b2 = _field(a), (b if b <= _FIRST_SHIFTED else b + _SHIFT)
        if a == 0 and b2 == KC.GRAD:  # mass .. force: one contiguous block with the gradient
            return [self.B[..., a2:KC.GRAD + 2]]
        views = [self.B[..., a2:b2]]
        if a == 0:
            views.append(self.B[..., KC.GRAD:KC.GRAD + 2])
        return views

    def _per_slot(self, phase, s, *args):
        """Run a single-field grid phase on each slot as if it were the single field."""
        w = s.window
        G = w.G
        try:
            for k in range(self.n_slots):
                w.G = self.B[:, :, k]
                phase(s, *args)
        finally:
            w.G = G

    def _contact(self, s, vf, dvf, momentum=False):
        w = s.window
        if self.n_slots > 1:
            self.corrections += KC.contact_update(self.B, vf, dvf, momentum, s.mass_cutoff,
                                                  self.friction, w.bc_mask, 0, w.shape[0], 0, w.shape[1])

    # -- the phases that differ -----------------------------------------------------------------
    def reset_grid(self, s):
        self.B.fill(0.0)

    def particles_to_grid(self, s, momentum, forces):
        p = s.particles
        gravity, load_id, load_w, load_vec = self._load_args(s) if forces else (None,) * 4
        KC.p2g_bodies(p["x"], p["m"], p["v"] if momentum else None, p["vol"],
                      s.force_stress() if forces else None, p["body"], self.slot_of,
                      gravity, load_id, load_w, load_vec, *self._body_geometry(s))

    def exchange_halo(self, s, fields):
        for view in self._halo_views(fields):
            s.decomp.sum_halo(view)

    def update_grid(self, s, dt):
        """Contact correction of the mapped momenta, each slot's momentum update with its BCs,
        then the contact correction of the new velocities and of the velocity changes."""
        self._contact(s, KC.MOM, -1, momentum=True)
        self._per_slot(super().update_grid, s, dt)
        self._contact(s, KC.MOM, KC.FORCE)

    def grid_velocity(self, s, source, target):
        """Each slot's v = (mv)/m with its BCs, then the contact correction (the velocity from
        which USF and MUSL take the strain increment)."""
        self._per_slot(super().grid_velocity, s, _field(source), _field(target))
        self._contact(s, _field(target), -1)

    def grid_to_particles(self, s, remap):
        p = s.particles
        s._dx = s._scratch("_dx_buf", (p.n, 2))
        vmax, bad = KC.g2p_velocity_bodies(p["x"], p["m"], p["v"], p["body"], self.slot_of,
                                           s.transfer.pic_blend, *self._body_geometry(s),
                                           remap, s._dx, s._dt_step)
        s._vmax_local, s._bad_local = vmax, bad

    def update_strain(self, s, dt, velocity_field, move=True):
        p = s.particles
        de, dw, F, vol0, dq = s._kinematics_outputs()
        gravity, load_id, load_w, load_vec = self._load_args(s)
        s.external_work += KC.g2p_kinematics_bodies(
            p["x"], p["m"], p["vol"], p.fields.get("strain"), de, dw, F, vol0, dq, p["body"], self.slot_of,
            _field(velocity_field), s._dx if move else None, dt,
            gravity, load_id, load_w, load_vec, *self._body_geometry(s))

    def move_particles(self, s, dt):
        p = s.particles
        gravity, load_id, load_w, load_vec = self._load_args(s)
        s.external_work += KC.g2p_kinematics_bodies(
            p["x"], p["m"], p["vol"], None, None, None, None, None, None, p["body"], self.slot_of,
            KC.MOM, s._dx, dt, gravity, load_id, load_w, load_vec, *self._body_geometry(s))
