"""What a scheme sees of one time step, and the base of the schemes.

A scheme (pmpm.core.schemes) is the order of the step's phases. It receives a ``SchemeContext``
rather than the solver: the phases it may call (in which the effects' hooks run), the step's
``dt`` and start time, and the few parts a scheme with passes of its own reads (particles,
grid window, the transfer kernels' geometry, the halo sum) or hands back (the particles' moves,
their largest speed and troubles). Everything else of the run stays the solver's.
"""
__all__ = ["SchemeContext", "Scheme", "ALL", "MASS_MOMENTUM", "FORCE", "REMAPPED"]

#: grid fields each halo exchange carries
ALL = slice(0, 5)           # mass, momentum, force
MASS_MOMENTUM = slice(0, 3)
FORCE = slice(3, 5)
REMAPPED = slice(5, 7)      # MUSL re-mapped momentum


class SchemeContext:
    """One step as a scheme sees it (built by ``Solver.step`` for each step).

    Phases (each a method of the solver's, pmpm.core.solver; the effects' hooks run inside):
    ``reset_grid()``, ``particles_to_grid(momentum, forces, impulse=False)`` (``impulse``: the
    force's impulse with the momentum, only where ``impulse_fusable``), ``exchange_halo(fields)``,
    ``update_grid(dt)``, ``grid_velocity(source, target)``, ``grid_to_particles(remap,
    strain=False)`` (``strain``: the transfer also gathers the strain increment, volume and F in
    its pass, as MLS-MPM's; ``tail``: also the move, the strays count and the first half of the
    internal work, only where ``tail_fusable``, then no ``move_particles``),
    ``update_strain(dt, velocity_field, move)``,
    ``move_particles(dt)``, ``update_stress()``.

    Attributes
    ----------
    dt, t : float
        The step's time step and its start time.
    particles, window, geometry, sum_halo, gravity, end_time, mass_cutoff, owned :
        What a scheme with passes of its own reads: the rank's particles, the grid window, the
        transfer kernels' grid arguments (G, ox, oy, origin, inv_h, ncx, ncy, shape), the halo
        sum of a window-sized array, the body acceleration (None: none), the run's end time,
        the nodal mass cutoff (kg) and the owned node range of the window (axis, lo, hi).
    """

    __slots__ = ("_solver", "dt")

    def __init__(self, solver, dt):
        self._solver = solver
        self.dt = dt

    # -- the phases ---------------------------------------------------------------------------
    def reset_grid(self):
        self._solver.reset_grid()

    def particles_to_grid(self, momentum, forces, impulse=False):
        self._solver.particles_to_grid(momentum, forces, impulse)

    @property
    def impulse_fusable(self):
        return self._solver.impulse_fusable

    def exchange_halo(self, fields):
        self._solver.exchange_halo(fields)

    def update_grid(self, dt):
        self._solver.update_grid(dt)

    def grid_velocity(self, source, target):
        self._solver.grid_velocity(source, target)

    def grid_to_particles(self, remap, strain=False, tail=False):
        self._solver.grid_to_particles(remap, strain, tail)

    @property
    def tail_fusable(self):
        return self._solver.tail_fusable

    def update_strain(self, dt, velocity_field, move=True):
        self._solver.update_strain(dt, velocity_field, move)

    def move_particles(self, dt):
        self._solver.move_particles(dt)

    def update_stress(self):
        self._solver.update_stress()

    # -- what a scheme with passes of its own reads -------------------------------------------
    @property
    def t(self):
        return self._solver.t

    @property
    def particles(self):
        return self._solver.particles

    @property
    def window(self):
        return self._solver.window

    @property
    def geometry(self):
        return self._solver.geometry

    @property
    def gravity(self):
        return self._solver.gravity

    @property
    def end_time(self):
        return self._solver.options.end_time

    @property
    def mass_cutoff(self):
        return self._solver.mass_cutoff

    @property
    def owned(self):
        return self._solver.owned_local

    def sum_halo(self, array):
        """Every rank's contributions to ``array`` (window-sized) summed (collective)."""
        self._solver.decomp.sum_halo(array)

    def effect(self, name):
        """The run's effect registered as ``name`` (pmpm.core.effects), or None."""
        return self._solver.effect(name)

    # -- what such a scheme hands back -------------------------------------------------------
    def moves(self):
        """The particles' moves of this step (N, 2), to be filled (grid-to-particles does)."""
        return self._solver.new_moves()

    def report_speed(self, vmax, bad):
        """The rank's largest particle speed after the velocity update and its count of
        non-finite particles: the step's end reduces them (next dt, instability stop)."""
        self._solver.report_speed(vmax, bad)

    def scratch(self, name, shape):
        """A float array of ``shape`` kept between steps under ``name`` (reallocated when the
        particle count changes)."""
        return self._solver.scratch(name, shape)


class Scheme:
    """Base of the schemes; ``advance(ctx)`` runs one step's phases on a SchemeContext.

    A scheme owns its options (``from_config(cfg)``, the scene's ``[solver]`` settings; it
    raises ConfigError there for settings it cannot run with), its refusal of parts it cannot
    drive (``check_parts``), the transfer it runs with (``choose_transfer``) and its line of
    the run header (``describe``). It joins the registry by subclassing this class with a
    ``name`` and being imported by pmpm.core.schemes."""

    name = None
    #: chosen by ``solver.scheme`` (the implicit integrator is chosen by ``solver.integrator``)
    selectable = True

    @classmethod
    def from_config(cls, cfg):
        """The scheme with its options from ``cfg`` (the explicit schemes have none)."""
        return cls()

    def check_parts(self, effects, transfer, grid_fields):
        """Refuse (ConfigError) parts of the run this scheme cannot drive; called by
        pmpm.build before the solver is built. The explicit schemes drive every part."""

    def choose_transfer(self, transfer):
        """The transfer this scheme runs with, given the scene's (``solver.transfer``)."""
        return transfer

    def describe(self):
        """Lines for the run header's and ``pmpm --check``'s ``effect on:`` list
        (pmpm.runner.describe_effects); none for the paper's schemes."""
        return []

    def advance(self, ctx):
        raise NotImplementedError
