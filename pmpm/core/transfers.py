"""Particle <-> grid velocity transfers as strategies (``solver.transfer``).

A transfer owns the two phases that move velocity between the particles and the grid: the
momentum part of particles-to-grid, and grid-to-particles (the velocity update, the move and
the MUSL re-map). The scheme (pmpm.core.schemes) orders the phases; the transfer says how each
carries velocity.

* ``flip``: the paper's FLIP with an optional PIC blend (pmpm.core.kernels.transfer).
* ``apic``: affine PIC (pmpm.core.kernels.affine); each particle keeps an affine velocity ``C``
  (4 numbers), a field that exists only in runs that name this transfer.
"""
from pmpm.core import kernels as K
from pmpm.core.kernels.affine import g2p_affine, p2g_affine
from pmpm.registry import lookup

__all__ = ["Transfer", "FLIP", "APIC", "make_transfer"]


class Transfer:
    """Base of the transfers: ``p2g(solver, momentum, forces)`` and ``g2p(solver, remap)``."""

    name = None
    #: per-particle fields the transfer keeps: name -> trailing shape
    fields = {}

    def p2g(self, s, momentum, forces):
        raise NotImplementedError

    def g2p(self, s, remap):
        raise NotImplementedError


class FLIP(Transfer):
    """FLIP with the scene's PIC blend (paper eq. 5)."""

    name = "flip"

    def p2g(self, s, momentum, forces):
        p = s.particles
        K.p2g(p["x"], p["m"], p["v"] if momentum else None, p["vol"], p["stress"] if forces else None,
              s.loads.gravity if forces else None, None, None, None, *s._geometry())

    def g2p(self, s, remap):
        p = s.particles
        return K.g2p_velocity(p["x"], p["m"], p["v"], s.scene.solver.pic_blend, *s._geometry(),
                              remap, s._dx, s._dt_step)


class APIC(Transfer):
    """Affine PIC (Jiang et al. 2015): momentum m (v + C (x_i - x_p)), C = B D^-1."""

    name = "apic"
    fields = {"C": (4,)}

    def p2g(self, s, momentum, forces):
        p = s.particles
        if not momentum:   # USF's force pass: no velocity moves
            return FLIP.p2g(self, s, False, forces)
        p2g_affine(p["x"], p["m"], p["v"], p["C"], p["vol"], p["stress"] if forces else None,
                   s.loads.gravity if forces else None, None, None, None, *s._geometry())

    def g2p(self, s, remap):
        p = s.particles
        return g2p_affine(p["x"], p["m"], p["v"], p["C"], *s._geometry(), remap, s._dx, s._dt_step)


def make_transfer(name):
    """The transfer registered under ``name`` (``flip``, ``apic``)."""
    return lookup(Transfer, name)()
