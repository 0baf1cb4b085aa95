"""MLS-MPM as a scheme (``solver.scheme = "mls"``; Hu et al. 2018, pmpm.core.kernels.mls).

One step is one particle-to-grid pass (mass, affine momentum and the stress's force together),
the halo exchange, the grid update, one grid-to-particle pass (velocity, affine matrix C_p and
the strain increment, volume and F from it), the move and the stress update:

    reset_grid -> particles_to_grid (mass, momentum, forces) -> exchange_halo (all)
    -> update_grid -> grid_to_particles (v, C, d_eps, V, F, dx) -> move -> update_stress

where the P2G scatters the force's impulse dt f with the momentum (three fields a node, not
five) unless the grid update needs the force apart (nodal damping, a hook after the grid update:
``impulse_fusable``), and the move, the step-end count of particles that left the grid or the slab and the first
half of the internal work run inside the G2P's pass unless something acts between them (held
particles: ``tail_fusable``); a stream over the particle arrays each, a fifth of the quadratic
step before (docs/performance.md). With the tail folded in, the G2P also applies the stress
update where the materials' update is one linear map (one linear elastic law, no objective
rate: Solver._point_stress_map, Material.increment_matrix), as Hu et al.'s G2P does, and leaves
out the moves and increments arrays where no effect reads them after the pass.

USL's order with APIC's transfer, and 2 K^2 node visits per particle-step where MUSL makes
4 K^2. The scheme brings its transfer (``MLSTransfer``: the affine matrix C per particle);
``solver.transfer`` stays the default. Point particles only (the MLS gradient is built from
the B-spline weights of a point), with one grid field (no ``[contact]``).
"""
from pmpm.core.kernels.mls import g2p_mls, p2g_mls
from pmpm.core.step import ALL, Scheme
from pmpm.core.transfers import Transfer
from pmpm.errors import ConfigError

__all__ = ["MLS", "MLSTransfer"]


class MLSTransfer(Transfer):
    """MLS-MPM's transfer: APIC's momentum with the MLS force in p2g; in g2p the velocity,
    C_p and (the scheme asks it: ``ctx.kinematics``) the strain in the same pass."""

    name = None   # not a choice of solver.transfer: the mls scheme brings it
    fields = {"C": (4,)}

    def describe(self):
        return ["MLS-MPM transfer (affine velocity C per particle, one P2G and one G2P)"]

    def p2g(self, ctx, momentum):
        p = ctx.particles
        args = (p["x"], p["m"], p["v"], p["C"], p["vol"], ctx.stress, ctx.gravity, None, None, None, *ctx.geometry)
        if ctx.impulse:   # m v + dt f scattered together (Hu et al.'s P2G)
            p2g_mls(*args, ctx.dt)
        else:
            p2g_mls(*args)

    def g2p(self, ctx, remap):
        p = ctx.particles
        strain, de, dw, F, vol0, dq = ctx.kinematics
        dx = ctx.dx
        if ctx.tail is not None:   # (vmax, bad, work, power, outside, leaving, inverted, power after)
            *tail, moves_read, increments_read = ctx.tail
            dx = dx if moves_read else None     # the arrays nothing reads after the pass: not written
            de = de if increments_read else None
            return g2p_mls(p["x"], p["v"], p["C"], *ctx.geometry, dx, ctx.dt, strain, de, dw, F, p["vol"], vol0, dq,
                           *tail)
        return g2p_mls(p["x"], p["v"], p["C"], *ctx.geometry, dx, ctx.dt, strain, de, dw, F, p["vol"], vol0, dq)[:2]


class MLS(Scheme):
    """MLS-MPM: one P2G and one G2P per step (USL order, APIC transfer, MLS force)."""

    name = "mls"

    @classmethod
    def from_config(cls, cfg):
        if cfg.interpolation != "point":
            raise ConfigError("solver.scheme", f"mls is defined for point particles, not "
                                               f"interpolation = {cfg.interpolation!r}")
        if cfg.transfer != "flip" or cfg.pic_blend:
            raise ConfigError("solver.transfer" if cfg.transfer != "flip" else "solver.pic_blend",
                              "the mls scheme brings its own (affine) transfer: leave it out")
        return cls()

    def check_parts(self, effects, transfer, grid_fields):
        if grid_fields.scene_key is not None:
            raise ConfigError(grid_fields.scene_key, "the mls scheme runs one grid field (not with contact)")

    def choose_transfer(self, transfer):
        return MLSTransfer()

    def advance(self, ctx):
        dt = ctx.dt
        ctx.reset_grid()
        if ctx.impulse_fusable:   # the force's impulse scattered with the momentum
            ctx.particles_to_grid(momentum=True, forces=True, impulse=True)
        else:
            ctx.particles_to_grid(momentum=True, forces=True)
        ctx.exchange_halo(ALL)
        ctx.update_grid(dt)
        if ctx.tail_fusable:   # the move, strays count and first work half in the G2P's pass
            ctx.grid_to_particles(remap=False, strain=True, tail=True)
        else:
            ctx.grid_to_particles(remap=False, strain=True)
            ctx.move_particles(dt)
        ctx.update_stress()
