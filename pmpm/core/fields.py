"""The grid's velocity fields as a strategy: how the grid phases of the step map and update them.

``GridFields`` (the default): one field shared by every particle (bodies whose supports overlap
stick together). pmpm.physics.contact's ``BodyFields``, a subclass, gives each contact body its
own field with the contact correction between them (scene ``[contact]``). The solver's grid
phases (reset, particles-to-grid, halo, grid update, grid velocity, grid-to-particles, strain and
move) delegate to the run's grid fields; the scheme orders the phases, the transfer carries the
velocity, the effects' hooks act inside them (pmpm.core.effects).
"""

from pmpm.core import kernels as K

__all__ = ["GridFields"]


class GridFields:
    """One velocity field on the grid window ``s.window.G`` (the solver ``s``'s phases)."""

    #: the implicit integrator's equations are those of one shared field (a subclass with
    #: other fields says False: refused with solver.integrator = "implicit")
    implicit_support = True
    #: the scene key that chose these grid fields (None: the default)
    scene_key = None

    def on_window(self, s):
        """After every new grid window (start, rebalancing): nothing to allocate here."""

    def describe(self):
        return []

    def reset_grid(self, s):
        """Step 1: zero the rank's grid window (owned and ghost nodes) and choose the tiles
        this step's node passes visit: those the particles' stencils reach (plus the halo)."""
        s.window.reset(s.particles["x"])

    def particles_to_grid(self, s, momentum, forces, impulse=False):
        """Steps 4-6 / eq. 2: mass and momentum and/or internal and external forces (``impulse``:
        the force's impulse with the momentum where the transfer can, ``s.impulse_fusable``)."""
        s.transfer.p2g(s._step_context(forces=forces, impulse=impulse), momentum)
        if forces:
            for scatter in s._hooks["scatter_forces"]:   # point loads
                scatter(s)

    def exchange_halo(self, s, fields):
        """HALO: every rank's contributions summed in the owned and the ghost columns alike
        (one round with each neighbour)."""
        s.decomp.sum_halo(s.window.G[..., fields])

    def update_grid(self, s, dt):
        """Steps 7-8 / eq. 3-4: (mv) += f dt (with damping if asked), essential BCs (moving
        with the ground if asked); fields become v and dv."""
        w = s.window
        for prescribe in s._hooks["before_grid_update"]:   # ground motion, pushover
            prescribe(s, s.t + dt)
        damped, reactions = K.grid_update(w.G, dt, s.mass_cutoff, w.bc_mask, w.bc_vel,
                                          0, w.shape[0], 0, w.shape[1], s.damping, s._owned_local,
                                          s.effects.grid_reaction(), w.tiles)
        s.external_work += reactions  # supports are external: their work enters the balance
        for after in s._hooks["after_grid_update"]:   # damping work, held faces
            after(s, damped)

    def grid_velocity(self, s, source, target):
        """v = (mv)/m with BCs, e.g. of the MUSL re-mapped momentum (eq. 6)."""
        w = s.window
        K.momentum_to_velocity(w.G, source, target, w.bc_mask, w.bc_vel,
                               0, w.shape[0], 0, w.shape[1], w.tiles)
        for after in s._hooks["after_grid_velocity"]:
            after(s, target)

    def grid_to_particles(self, s, remap, strain=False, tail=False):
        """Step 9 / eq. 5: particle velocities by the scene's transfer (FLIP/PIC, APIC); MUSL
        also re-maps their momenta. ``strain``: the transfer gathers the strain increment,
        volume and F in the same pass (MLS-MPM: (strain, de, dw, F, vol0, dq) in its context).
        ``tail`` (with ``strain``; only where ``s.tail_fusable``): the move, the strays count and
        the first half of the internal work too (``s.tail_arguments()`` in the context; the
        transfer returns their results after the speed, handed to ``s.take_tail``)."""
        s.new_moves()
        kinematics = None
        if strain:
            kinematics = (s.particles.fields.get("strain"),) + s._kinematics_outputs()
        ctx = s._step_context(kinematics=kinematics, tail=s.tail_arguments() if tail else None)
        out = s.transfer.g2p(ctx, remap)
        vmax, bad = out[:2]
        s.report_speed(vmax, bad)
        if tail:
            s.take_tail(*out[2:])
        for after in s._hooks["after_g2p"]:   # held particles
            after(s)

    def update_strain(self, s, dt, velocity_field, move=True):
        """Step 10 / eq. 6: strain increment, volume (and F) update, and (``move``) positions."""
        p = s.particles
        de, dw, F, vol0, dq = s._kinematics_outputs()
        s.external_work += K.g2p_kinematics(
            p["x"], p["m"], p["vol"], p.fields.get("strain"), de, dw, F, vol0, dq,
            velocity_field, s._dx if move else None, dt,
            s.gravity, None, None, None, *s._geometry())
        if s.interpolation == "cpgimp":
            s._stretch_domains(de)
        if move:
            s._work_of_moves()

    def move_particles(self, s, dt):
        """Position update x += dt sum N v_i (USF: after the stress update)."""
        p = s.particles
        s.external_work += K.g2p_kinematics(
            p["x"], p["m"], p["vol"], None, None, None, None, None, None, 1, s._dx, dt,
            s.gravity, None, None, None, *s._geometry())
        s._work_of_moves()
