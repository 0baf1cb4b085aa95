"""Particle <-> grid velocity transfers as strategies (``solver.transfer``).

A transfer owns the two phases that move velocity between the particles and the grid: the
momentum part of particles-to-grid, and grid-to-particles (the velocity update, the move and
the MUSL re-map). The scheme (pmpm.core.schemes) orders the phases; the transfer says how each
carries velocity.

* ``flip``: the paper's FLIP with an optional PIC blend (pmpm.core.kernels.transfer).
* ``apic``: affine PIC (pmpm.core.kernels.affine); each particle keeps an affine velocity ``C``
  (4 numbers), a field that exists only in runs that name this transfer.
* ``xpic``: XPIC(m) (pmpm.core.kernels.xpic), order ``solver.xpic_order``; no particle field,
  m - 1 extra particle passes and halo exchanges per step.
"""
from math import comb

import numpy as np

from pmpm.core import kernels as K
from pmpm.core.kernels.affine import g2p_affine, p2g_affine
from pmpm.core.kernels.xpic import grid_particle_grid
from pmpm.registry import lookup

__all__ = ["StepContext", "Transfer", "FLIP", "APIC", "XPIC", "make_transfer", "xpic_coefficients"]


class StepContext:
    """What a transfer reads and writes of the step (built by the solver for each call).

    Attributes
    ----------
    particles : pmpm.core.particles.Particles
    window : pmpm.core.grid.GridWindow
    geometry : tuple
        The transfer kernels' grid arguments (G, ox, oy, origin, inv_h, ncx, ncy, shape).
    sum_halo : callable
        The halo sum of a window-sized array (one round with the neighbours; XPIC's passes).
    stress, gravity : numpy.ndarray or None
        The force pass's stress (the particles', as the effects edit it) and body acceleration;
        None when the pass carries no forces (the kernels compile them out).
    dx : numpy.ndarray or None
        The particles' moves of the step, filled by grid-to-particles.
    dt : float
        The step's time step.
    kinematics : tuple or None
        (strain, de, dw, F, vol0, dq): the strain outputs of pmpm.core.kernels.transfer's
        ``strain_increment`` when the scheme asks grid-to-particles to gather the strain in the
        same pass (MLS-MPM); None otherwise.
    tail : tuple or None
        (m, gravity, stress or None, (axis, c0, c1)) when the scheme asks grid-to-particles to
        fold the step's later particle passes in (the move, the strays count, the first half of
        the internal work: pmpm.core.kernels.mls.g2p_mls); its g2p then returns their results
        after (vmax, bad). None otherwise.

    impulse : bool
        The force pass scatters the force's impulse dt f with the momentum (fields 1, 2) rather
        than the force apart (fields 3, 4), where the transfer can (MLS-MPM's P2G); only when
        the scheme asks (pmpm.core.mls).
    """

    __slots__ = ("particles", "window", "geometry", "sum_halo", "stress", "gravity", "dx", "dt", "kinematics",
                 "tail", "impulse")

    def __init__(self, particles, window, geometry, sum_halo, stress=None, gravity=None, dx=None, dt=0.0,
                 kinematics=None, tail=None, impulse=False):
        self.particles, self.window, self.geometry, self.sum_halo = particles, window, geometry, sum_halo
        self.stress, self.gravity, self.dx, self.dt = stress, gravity, dx, dt
        self.kinematics, self.tail, self.impulse = kinematics, tail, impulse


class Transfer:
    """Base of the transfers: ``p2g(ctx, momentum)`` and ``g2p(ctx, remap)`` on a StepContext;
    ``from_config`` takes the transfer's own options from the scene's ``[solver]`` table and
    ``describe`` gives its line of the run header (none for the paper's FLIP)."""

    name = None
    #: per-particle fields the transfer keeps: name -> trailing shape
    fields = {}
    #: the PIC share of the particle velocity update (FLIP's option; 0 for the others)
    pic_blend = 0.0
    #: whether the implicit integrator's Newmark update of the particles stands for this
    #: transfer (it does for pure FLIP: velocity increments from the grid)
    implicit_support = False

    @classmethod
    def from_config(cls, cfg):
        """The transfer with its options from ``cfg`` (the scene's ``[solver]`` settings)."""
        return cls()

    def describe(self):
        return []

    def p2g(self, ctx, momentum):
        raise NotImplementedError

    def g2p(self, ctx, remap):
        raise NotImplementedError


class FLIP(Transfer):
    """FLIP with the scene's PIC blend (paper eq. 5)."""

    name = "flip"

    def __init__(self, pic_blend=0.0):
        self.pic_blend = pic_blend
        self.implicit_support = pic_blend == 0.0   # Newmark's rule is pure FLIP's increment

    @classmethod
    def from_config(cls, cfg):
        return cls(pic_blend=cfg.pic_blend)

    def p2g(self, ctx, momentum):
        p = ctx.particles
        K.p2g(p["x"], p["m"], p["v"] if momentum else None, p["vol"], ctx.stress,
              ctx.gravity, None, None, None, *ctx.geometry)

    def g2p(self, ctx, remap):
        p = ctx.particles
        return K.g2p_velocity(p["x"], p["m"], p["v"], self.pic_blend, *ctx.geometry,
                              remap, ctx.dx, ctx.dt)


class APIC(Transfer):
    """Affine PIC (Jiang et al. 2015): momentum m (v + C (x_i - x_p)), C = B D^-1."""

    name = "apic"
    fields = {"C": (4,)}

    def describe(self):
        return ["APIC transfer (affine velocity C per particle)"]

    def p2g(self, ctx, momentum):
        p = ctx.particles
        if not momentum:   # USF's force pass: no velocity moves
            return FLIP.p2g(self, ctx, False)
        p2g_affine(p["x"], p["m"], p["v"], p["C"], p["vol"], ctx.stress,
                   ctx.gravity, None, None, None, *ctx.geometry)

    def g2p(self, ctx, remap):
        p = ctx.particles
        return g2p_affine(p["x"], p["m"], p["v"], p["C"], *ctx.geometry, remap, ctx.dx, ctx.dt)


def xpic_coefficients(order):
    """(-1)^(k+1) C(m, k) for k = 1 .. m: v* = sum_k c_k M^(k-1) v^n (they sum to 1)."""
    return [(-1) ** (k + 1) * comb(order, k) for k in range(1, order + 1)]


class XPIC(Transfer):
    """XPIC(m) (Hammerquist & Nairn 2017): v_p = S_p (v^L - v^n + v*), see pmpm.core.kernels.xpic.

    The boundary values hold in v^n and in every M^k v^n, so v* takes them too (its
    coefficients sum to 1) and a particle at a fixed node gets the node's velocity, as with
    PIC; m = 1 is PIC exactly. The particle update goes through the FLIP kernel: with the
    particle velocities zeroed and the velocity-change fields set to v^L - v^n + v*, its
    ``v + sum S dv`` is the XPIC velocity, its move dt sum S v^L and its re-map those of FLIP."""

    name = "xpic"

    def __init__(self, order=2):
        self.order = order
        self.coefficients = xpic_coefficients(order)

    @classmethod
    def from_config(cls, cfg):
        return cls(order=cfg.xpic_order)

    def describe(self):
        return [f"XPIC({self.order}) transfer ({self.order - 1} extra grid-particle-grid passes per step)"]

    def p2g(self, ctx, momentum):
        FLIP.p2g(self, ctx, momentum)

    def _apply_bc(self, w, u):
        mask = w.bc_mask.astype(bool)
        u[mask] = w.bc_vel[mask]
        return u

    def smooth(self, ctx, u):
        """M u = S^+ S u with the boundary values (collective: one halo round)."""
        w, p = ctx.window, ctx.particles
        out = np.zeros_like(u)
        G, ox, oy, origin, inv_h, ncx, ncy, shape = ctx.geometry
        grid_particle_grid(p["x"], p["m"], u, out, ox, oy, origin, inv_h, ncx, ncy, shape)
        ctx.sum_halo(out)
        mass = w.G[..., 0:1]
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(mass > 0.0, out / np.where(mass > 0.0, mass, 1.0), 0.0)
        return self._apply_bc(w, out)

    def g2p(self, ctx, remap):
        w, p = ctx.window, ctx.particles
        G = w.G
        v_new = G[..., 1:3]
        vn = self._apply_bc(w, v_new - G[..., 3:5])   # start-of-step velocity with the BCs
        u = vn
        vstar = self.coefficients[0] * u
        for c in self.coefficients[1:]:
            u = self.smooth(ctx, u)
            vstar += c * u
        G[..., 3:5] = v_new - vn + vstar
        p["v"][...] = 0.0
        return K.g2p_velocity(p["x"], p["m"], p["v"], 0.0, *ctx.geometry, remap, ctx.dx, ctx.dt)


def make_transfer(name, cfg=None, **options):
    """The transfer registered under ``name`` (``flip``, ``apic``, ``xpic``), with its options
    from ``cfg`` (the scene's ``[solver]`` settings: ``Transfer.from_config``) or ``options``
    (e.g. the XPIC ``order``)."""
    cls = lookup(Transfer, name)
    if cfg is not None:
        return cls.from_config(cfg)
    return cls(**options) if options else cls()
