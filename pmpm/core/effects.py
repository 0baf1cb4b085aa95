"""Effects: the optional physics a scene names, plugged into the solver's fixed phases.

An effect (gravity and loads, ground motion, pushover, events, damping, supports, reactions,
...) is an object of a subclass of :class:`Effect`, registered under ``name`` (the registry of
pmpm.registry) and built by its ``create(scene, setup)`` from the scene, or not at all when the
scene does not name it (``create`` returns None). The solver holds the effects a scene names,
in registry order, and calls each *hook* an effect overrides at its place in the step; the
hooks of the base class do nothing, and the solver never calls a hook that no effect of the
run overrides (``EffectList.hooks``), so an effect that is off costs nothing, not even a call.

What an effect gives the step, in the order of a step (docs/architecture.md draws it):

* ``body_acceleration`` (gravity), ``nodal_damping`` (the coefficient of -c m v in the grid
  update): arguments of the numba kernels, None unless an effect sets them (the kernels are
  compiled without the code then: docs/effects.md);
* ``on_window(s)``: after every new grid window (start, rebalancing): find its nodes;
* ``scatter_forces(s)``: after the force pass of particles-to-grid (point loads);
* ``edits_force_stress(t)`` / ``add_force_stress(s, out)``: the stress whose divergence is the
  internal force (viscous stress, a fading body); the particles' stress itself when no
  effect edits it;
* ``before_grid_update(s, t_next)``: prescribed nodal velocities (ground motion, pushover);
* ``grid_reaction()``: the reaction accumulator of the grid-update kernel;
* ``after_grid_update(s, damped_work)`` and ``after_grid_velocity(s, field)``: constraints on
  the nodal velocities (supports held by particles);
* ``after_g2p(s)``: the particles' new velocities (held particles);
* ``after_move(s)``: work of forces over the step's moves (point loads);
* ``after_stress_update(s)``: viscous stress update, the work a fading body held back;
* ``after_step(s)``: at the step's end (a body leaves the run);
* ``limit_dt(dt, speed, s)``: a shorter stable step;
* ``energy_terms`` and the attributes of those names: rank-local energies (J) that the solver
  adds to its energies, the run to its energy columns and the checkpoints to their state;
  ``restore(s, attrs)`` after a restart;
* ``add_fields(particles, setup)``: per-particle fields the effect keeps (they migrate and are
  checkpointed like any field);
* ``describe()``: lines of the run header's ``effect on:`` list;
* ``summary(s)``: entries of the run summary at the end (the first fracture of each body).
* ``implicit_support``: True if the implicit integrator carries the effect (default False:
  refused there, so that a new effect is never silently left out of an implicit step).
  The implicit step calls none of the hooks above; it has its own:
  ``prescribe_increment(s, t0, h, U)`` (the displacement increments of held components over
  the step from ``t0`` to ``t0 + h``, written into the window array ``U``: a pushover's nodes),
  ``after_implicit_step(s, step)`` (a converged step's nodal support forces,
  :class:`ConvergedStep`: reactions), and ``implicit_term(s)``: what it adds to the implicit
  step's equations, if anything (a pmpm.core.implicit.terms.ImplicitTerm: forces and tangent
  blocks, prescribed support motion, its work), None by default.

A material can contribute energy terms too (:data:`ENERGY_TERMS`, ``register_energy``): a
damage model's dissipated energy is one more column without a change here.
"""
import logging

from pmpm.registry import all_subclasses

__all__ = ["Effect", "EffectList", "ConvergedStep", "EnergyTerm", "ENERGY_TERMS", "register_energy", "energy_terms"]
logger = logging.getLogger(__name__)


class EnergyTerm:
    """An energy (J) the run reports beside the kinetic, strain and internal ones.

    Parameters
    ----------
    name : str
        Column of ``/energies`` and key of ``Solver.energies``.
    meaning : str
        What it is (the results file's description, pmpm.io.schema).
    outside : bool
        True: work done outside the internal work (damping, energy taken out of the run):
        added to the total. False: a part of the internal work held as a dissipation (plastic
        work, damage): only subtracted in the numerical loss.
    """

    def __init__(self, name, meaning, outside=True):
        self.name, self.meaning, self.outside = name, meaning, outside

    def __repr__(self):
        return f"EnergyTerm({self.name!r})"


#: every energy term registered, in registration order (the order of the results' columns)
ENERGY_TERMS = {}


def register_energy(name, meaning, outside=True):
    """Register an energy term (once per name; the first registration's meaning is kept) and
    return its name: effects and materials name their terms with it at import."""
    ENERGY_TERMS.setdefault(name, EnergyTerm(name, meaning, outside))
    return name


def energy_terms():
    """The registered energy terms, in registration order."""
    return list(ENERGY_TERMS.values())


class Effect:
    """Base of the effects: every hook does nothing (module doc)."""

    #: registry name: the scene key that switches the effect on
    name = None
    #: energies this effect accounts: names registered with ``register_energy``, each an
    #: attribute of the object holding this rank's share (J)
    energy_terms = ()
    #: acceleration (2,) every particle's mass feels (gravity); None: none
    body_acceleration = None
    #: coefficient c (1/s) of the nodal force -c m v of the grid update; None: none
    nodal_damping = None
    #: whether the implicit integrator (pmpm.core.implicit) carries this effect: it calls none
    #: of the explicit step's hooks, so an effect says so only when the integrator does what
    #: the effect does (False: a scene naming it is refused with solver.integrator = "implicit")
    implicit_support = False

    @classmethod
    def create(cls, scene, setup):
        """The effect of ``scene``, or None if the scene does not name it. ``setup`` holds
        what construction knows (grid, materials, the global points, the scene folder)."""
        return None

    # -- construction ---------------------------------------------------------------------
    def add_fields(self, particles, setup):
        pass

    def on_window(self, s):
        pass

    # -- the step's hooks, in step order ----------------------------------------------------
    def scatter_forces(self, s):
        pass

    def edits_force_stress(self, t):
        return False

    def add_force_stress(self, s, out):
        pass

    def before_grid_update(self, s, t_next):
        pass

    def grid_reaction(self):
        return None

    def after_grid_update(self, s, damped_work):
        pass

    def after_grid_velocity(self, s, field):
        pass

    def after_g2p(self, s):
        pass

    def after_move(self, s):
        pass

    def after_stress_update(self, s):
        pass

    def after_step(self, s):
        pass

    def limit_dt(self, dt, speed, s):
        return dt

    # -- the implicit step's hooks (pmpm.core.implicit.scheme) ------------------------------
    def prescribe_increment(self, s, t0, h, U):
        pass

    def after_implicit_step(self, s, step):
        pass

    def implicit_term(self, s):
        """The effect's part of the implicit step (pmpm.core.implicit.terms), or None."""
        return None

    #: whether the effect's implicit term folds its forces and tangent onto the slaved edge
    #: nodes (``[solver.implicit] edge_mass_ratio``, pmpm.core.implicit.edges); an effect with
    #: a term that does not is refused with that option (pmpm.core.implicit.scheme)
    implicit_term_folded = False

    # -- state and reporting ---------------------------------------------------------------
    def restore(self, s, attrs):
        """After a restart from a checkpoint with ``attrs`` at time ``s.t`` (the energy terms
        are restored by the run)."""

    def describe(self):
        return []

    def summary(self, s):
        """Entries of the run summary (collective: every rank calls it once, at the end)."""
        return {}


#: the hooks the solver calls through ``EffectList.hooks`` (only on effects overriding them)
HOOKS = ("on_window", "scatter_forces", "before_grid_update", "after_grid_update", "after_grid_velocity",
         "after_g2p", "after_move", "after_stress_update", "after_step", "limit_dt",
         "prescribe_increment", "after_implicit_step")


class ConvergedStep:
    """What a converged implicit step gives ``after_implicit_step``.

    Parameters
    ----------
    t0, h : float
        The step's start time and length (s).
    static : bool
        ``solver.analysis = "static"``: ``support_force`` is an equilibrium state's.
    support_force : ndarray (nx, ny, 2)
        The force the supports exert on each held component of the window's active nodes at
        the step's end (N; zero elsewhere; ghost nodes hold their owners' values).
    support_force_start : ndarray (nx, ny, 2) or None
        The same at the step's start, on this step's grid (dynamics: the trapezoid of the two
        is the supports' impulse over the step under the trapezoidal rule).
    """

    def __init__(self, t0, h, static, support_force, support_force_start=None):
        self.t0, self.h, self.static = t0, h, static
        self.support_force, self.support_force_start = support_force, support_force_start


class EffectList:
    """The effects of one run, in registry order, with each hook's overriding methods.

    Parameters
    ----------
    effects : iterable of Effect
    """

    def __init__(self, effects):
        self.effects = [e for e in effects if e is not None]
        self.by_name = {e.name: e for e in self.effects}
        #: hook name -> bound methods of the effects that override it
        self.hooks = {h: [getattr(e, h) for e in self.effects
                          if getattr(type(e), h) is not getattr(Effect, h)] for h in HOOKS}
        self.stress_editors = [e for e in self.effects
                               if type(e).add_force_stress is not Effect.add_force_stress]
        self.body_acceleration = _single(self.effects, "body_acceleration")
        self.nodal_damping = _single(self.effects, "nodal_damping")

    def __iter__(self):
        return iter(self.effects)

    def __len__(self):
        return len(self.effects)

    def get(self, name):
        """The effect registered as ``name`` if this run has it, else None."""
        return self.by_name.get(name)

    def grid_reaction(self):
        """The grid-update kernel's reaction argument (None: no effect records reactions)."""
        for e in self.effects:
            arg = e.grid_reaction()
            if arg is not None:
                return arg
        return None

    def energy(self, name):
        """This rank's share of energy ``name`` over the effects holding it (J)."""
        return sum(getattr(e, name) for e in self.effects if name in e.energy_terms)

    def set_energy(self, name, value):
        """Give energy ``name`` the value ``value``: to the first effect holding it, zero to
        the others (a restart's rank 0 holds the sum)."""
        first = True
        for e in self.effects:
            if name in e.energy_terms:
                setattr(e, name, value if first else 0.0)
                first = False

    def describe(self):
        return [line for e in self.effects for line in e.describe()]


def _single(effects, attr):
    """The one value of ``attr`` the effects set (None: none sets it)."""
    values = [getattr(e, attr) for e in effects if getattr(e, attr) is not None]
    if len(values) > 1:
        raise ValueError(f"two effects set {attr}: {[e.name for e in effects if getattr(e, attr) is not None]}")
    return values[0] if values else None


def registered_effects():
    """Every registered effect class, in registration (import) order."""
    return [c for c in all_subclasses(Effect) if c.name]
