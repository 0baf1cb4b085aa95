"""Update schemes as strategies: where the stress update sits in the step.

USF (update stress first), USL (update stress last) and MUSL (modified USL, the paper's choice,
eq. 6: particle momenta re-mapped to the grid before the strain increment) differ only in the
order of the solver's phases; each scheme is that order, read top to bottom. ``newmark`` is the
implicit integrator (pmpm.core.implicit.scheme: its own Newton loop after the solver's first
phases); it refuses, in ``check_parts``, the parts that do not say ``implicit_support``.
"""
from pmpm.registry import lookup, names
from pmpm.core.kernels import MOM, REMAP
from pmpm.core.implicit.scheme import ImplicitNewmark

#: grid fields each halo exchange carries
ALL = slice(0, 5)           # mass, momentum, force
MASS_MOMENTUM = slice(0, 3)
FORCE = slice(3, 5)
REMAPPED = slice(5, 7)      # MUSL re-mapped momentum

__all__ = ["Scheme", "USF", "USL", "MUSL", "Newmark", "make_scheme"]


class Scheme:
    """Base of the schemes; ``advance(solver, dt)`` runs one step's grid and particle phases.

    The solver holds no scene: a scheme with options takes them at construction
    (``from_config(cfg)``, the scene's ``[solver]`` settings); in ``advance`` it reads the
    solver's parts (particles, window, materials, ``options``, ``gravity``, ``effect(name)``) and
    calls its phases, in which the effects' hooks run (docs/architecture.md)."""

    name = None

    @classmethod
    def from_config(cls, cfg):
        """The scheme with its options from ``cfg`` (the explicit schemes have none)."""
        return cls()

    def check_parts(self, effects, transfer, grid_fields):
        """Refuse (ConfigError) parts of the run this scheme cannot drive; called by
        pmpm.build before the solver is built. The explicit schemes drive every part."""

    def advance(self, s, dt):
        raise NotImplementedError


class USF(Scheme):
    """Strain and stress from the start-of-step grid velocity, then the momentum update."""

    name = "usf"

    def advance(self, s, dt):
        s.reset_grid()
        s.particles_to_grid(momentum=True, forces=False)
        s.exchange_halo(MASS_MOMENTUM)
        s.grid_velocity(source=MOM, target=REMAP)
        s.update_strain(dt, velocity_field=REMAP, move=False)
        s.update_stress()
        s.particles_to_grid(momentum=False, forces=True)
        s.exchange_halo(FORCE)
        s.update_grid(dt)
        s.grid_to_particles(remap=False)
        s.move_particles(dt)


class USL(Scheme):
    """Momentum update, then strain and stress from the updated grid velocity."""

    name = "usl"

    def advance(self, s, dt):
        s.reset_grid()
        s.particles_to_grid(momentum=True, forces=True)
        s.exchange_halo(ALL)
        s.update_grid(dt)
        s.grid_to_particles(remap=False)
        s.update_strain(dt, velocity_field=MOM, move=True)
        s.update_stress()


class MUSL(Scheme):
    """USL whose strain comes from the re-mapped particle momenta (paper eq. 6)."""

    name = "musl"

    def advance(self, s, dt):
        s.reset_grid()
        s.particles_to_grid(momentum=True, forces=True)
        s.exchange_halo(ALL)
        s.update_grid(dt)
        s.grid_to_particles(remap=True)
        s.exchange_halo(REMAPPED)
        s.grid_velocity(source=REMAP, target=REMAP)
        s.update_strain(dt, velocity_field=REMAP, move=True)
        s.update_stress()


class Newmark(ImplicitNewmark, Scheme):
    """The implicit integrator (pmpm.core.implicit.scheme), ``solver.integrator = "implicit"``."""


def make_scheme(name, cfg=None):
    """The scheme registered under ``name`` (``usf``, ``usl``, ``musl``), with its options from
    ``cfg`` (the scene's ``[solver]`` settings) when given."""
    cls = lookup(Scheme, name)
    return cls.from_config(cfg) if cfg is not None else cls()


def scheme_names():
    return names(Scheme)
