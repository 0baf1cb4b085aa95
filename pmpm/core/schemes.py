"""Update schemes as strategies: where the stress update sits in the step (the registry).

USF (update stress first), USL (update stress last) and MUSL (modified USL, the paper's choice,
eq. 6: particle momenta re-mapped to the grid before the strain increment) differ only in the
order of the solver's phases; each scheme is that order, read top to bottom, on the step's
SchemeContext (pmpm.core.step). ``mls`` (pmpm.core.mls) is MLS-MPM: one particle-to-grid and
one grid-to-particle pass. ``newmark`` is the implicit integrator (pmpm.core.implicit.scheme:
its own Newton loop after the solver's first phases); it refuses, in ``check_parts``, the parts
that do not say ``implicit_support``.

A new scheme: its own module (a ``Scheme`` subclass with ``name``) and one import line below.
"""
from pmpm.registry import lookup, names
from pmpm.core.kernels import MOM, REMAP
from pmpm.core.step import ALL, FORCE, MASS_MOMENTUM, REMAPPED, Scheme
from pmpm.core.implicit.scheme import ImplicitNewmark
from pmpm.core.mls import MLS   # noqa: F401  (registers "mls")

__all__ = ["Scheme", "USF", "USL", "MUSL", "Newmark", "make_scheme", "scheme_names", "selectable_scheme_names",
           "ALL", "MASS_MOMENTUM", "FORCE", "REMAPPED"]


class USF(Scheme):
    """Strain and stress from the start-of-step grid velocity, then the momentum update."""

    name = "usf"

    def advance(self, ctx):
        dt = ctx.dt
        ctx.reset_grid()
        ctx.particles_to_grid(momentum=True, forces=False)
        ctx.exchange_halo(MASS_MOMENTUM)
        ctx.grid_velocity(source=MOM, target=REMAP)
        ctx.update_strain(dt, velocity_field=REMAP, move=False)
        ctx.update_stress()
        ctx.particles_to_grid(momentum=False, forces=True)
        ctx.exchange_halo(FORCE)
        ctx.update_grid(dt)
        ctx.grid_to_particles(remap=False)
        ctx.move_particles(dt)


class USL(Scheme):
    """Momentum update, then strain and stress from the updated grid velocity."""

    name = "usl"

    def advance(self, ctx):
        dt = ctx.dt
        ctx.reset_grid()
        ctx.particles_to_grid(momentum=True, forces=True)
        ctx.exchange_halo(ALL)
        ctx.update_grid(dt)
        ctx.grid_to_particles(remap=False)
        ctx.update_strain(dt, velocity_field=MOM, move=True)
        ctx.update_stress()


class MUSL(Scheme):
    """USL whose strain comes from the re-mapped particle momenta (paper eq. 6)."""

    name = "musl"

    def advance(self, ctx):
        dt = ctx.dt
        ctx.reset_grid()
        ctx.particles_to_grid(momentum=True, forces=True)
        ctx.exchange_halo(ALL)
        ctx.update_grid(dt)
        ctx.grid_to_particles(remap=True)
        ctx.exchange_halo(REMAPPED)
        ctx.grid_velocity(source=REMAP, target=REMAP)
        ctx.update_strain(dt, velocity_field=REMAP, move=True)
        ctx.update_stress()


class Newmark(ImplicitNewmark, Scheme):
    """The implicit integrator (pmpm.core.implicit.scheme), ``solver.integrator = "implicit"``.

    It still reads the solver itself (its moves, speed report, strain increment, scratch
    arrays, mass cutoff and owned range: what SchemeContext offers as ``moves``,
    ``report_speed``, ``scratch``, ``mass_cutoff``, ``owned``); until it takes the context,
    this adapter hands it the solver behind the context."""

    selectable = False

    def advance(self, ctx):
        return ImplicitNewmark.advance(self, ctx._solver, ctx.dt)


def make_scheme(name, cfg=None):
    """The scheme registered under ``name`` (``usf``, ``usl``, ``musl``, ``mls``, ``newmark``),
    with its options from ``cfg`` (the scene's ``[solver]`` settings) when given."""
    cls = lookup(Scheme, name)
    return cls.from_config(cfg) if cfg is not None else cls()


def scheme_names():
    return names(Scheme)


def selectable_scheme_names():
    """The names ``solver.scheme`` accepts (the implicit integrator has its own key)."""
    return tuple(n for n in names(Scheme) if lookup(Scheme, n).selectable)
