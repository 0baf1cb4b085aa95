"""The implicit integrator as a scheme: one call of ``advance(solver, dt)`` is one step of the
scene's ``solver.time_step``, read top to bottom as the solver's phases and this package's:

    reset_grid -> particles_to_grid (mass, momentum) -> inertia and loads to the grid
    -> exchange_halo -> [Newton: residual -> tangent -> PETSc solve -> line search]
    -> particles from the converged step (Newmark) -> stresses, volumes pushed forward

A step whose Newton iterations fail is halved and retried from the same start state (the
particles are only written once a step has converged); after ``GROW_AFTER`` converged steps
the step doubles again, up to the scene's. A step that fails at the smallest length allowed
(``max_halvings``) stops the run (UnstableRunError: exit 3, the last converged state kept).
Statics (``solver.analysis = "static"``) is the same loop without the inertia: each step
brings the loads of its end time (load control) to equilibrium and the velocities stay zero.

The class here is registered in pmpm.core.schemes as ``newmark``; the scene selects it with
``solver.integrator = "implicit"`` (pmpm.core.implicit.options).
"""
import logging

import numpy as np

from pmpm.core import kernels as K
from pmpm.core.effects import ConvergedStep, Effect
from pmpm.core.implicit import kernels as IK
from pmpm.core.implicit.arclength import make_control
from pmpm.core.implicit.control import linear_predictor
from pmpm.core.implicit.edges import EdgeSlaves, owned_mask
from pmpm.core.implicit.linear_solver import LinearSolver
from pmpm.core.implicit.newmark import Newmark
from pmpm.core.implicit.newton import NewtonFailed, newton
from pmpm.core.implicit.options import IMPLICIT_DEFAULTS
from pmpm.core.implicit.problem import GridProblem
from pmpm.errors import ConfigError, UnstableRunError

__all__ = ["ImplicitNewmark", "GROW_AFTER", "ACCELERATION"]
logger = logging.getLogger(__name__)

#: converged steps after a halving before the step doubles again
GROW_AFTER = 4
#: the particle field holding Newmark's acceleration (migrates with the particle)
ACCELERATION = "acc"
#: grid fields the step reads after the halo sum: mass, momentum, external force, m a
MASS, MOMENTUM, FORCE, INERTIA = 0, slice(1, 3), slice(3, 5), slice(5, 7)


class ImplicitNewmark:
    """Newmark's average acceleration rule with Newton iterations on the grid (docs/implicit.md)."""

    name = "newmark"

    def __init__(self, options=None, analysis="dynamic", petsc=None, static=None, time_step=None, end_time=None):
        self.options = dict(IMPLICIT_DEFAULTS if options is None else options)
        # a load factor as an unknown of the static steps ([solver.static], pmpm.core.implicit.arclength)
        self.control = make_control(static, time_step, end_time)
        self.dynamic = analysis == "dynamic"
        self.petsc = dict(petsc or {})
        self.alpha = self.options["hht_alpha"]
        self.linear = None
        self.fraction = 1.0        # current step length / the scene's step
        self.converged_in_row = 0
        self.stats = {"steps": 0, "newton_iterations": 0, "factorisations": 0, "tangents": 0, "residual_evaluations": 0,
                      "linear_iterations": 0, "halvings": 0}
        self.history = []          # (|R|, energy) of the last step's iterations
        self.edges = None          # the step's slaved edge nodes (edge_mass_ratio; pmpm.core.implicit.edges)
        self.held_force = np.zeros(2)   # sum of the nodal forces on held components (last step)
        self.options_checked = False

    @classmethod
    def from_config(cls, cfg):
        """The integrator with the scene's ``[solver.implicit]`` tolerances, ``solver.analysis``
        and ``[solver.petsc]`` options (``cfg``: the scene's ``[solver]`` settings; the solver
        holds no scene)."""
        return cls(cfg.implicit, cfg.analysis, cfg.petsc, cfg.static, cfg.time_step, cfg.end_time)

    def check_parts(self, effects, transfer, grid_fields):
        """Refuse every part of the run that does not say ``implicit_support`` (the effects,
        the transfer, the grid fields: pmpm.core.effects): this step calls none of the
        explicit step's hooks, so a part it does not carry would be silently left out.
        What is not a part of the solver (checkpoints, output fields, the materials'
        tangents, the time step) is refused with the scene (pmpm.core.implicit.options)."""
        for effect in effects:
            if not effect.implicit_support:
                what = "; ".join(effect.describe()) or effect.name
                raise ConfigError(effect.name, f"is explicit-only for now ({what}; solver.integrator = "
                                               f"\"implicit\", docs/implicit.md)")
        if not transfer.implicit_support:
            raise ConfigError("solver.transfer", f"{transfer.name}" + (f" with pic_blend = {transfer.pic_blend:g}"
                              if transfer.pic_blend else "") + ": the implicit step updates velocities by "
                              "Newmark's rule (solver.integrator = \"implicit\")")
        if not grid_fields.implicit_support:
            raise ConfigError(grid_fields.scene_key, "is explicit-only for now (solver.integrator = \"implicit\", "
                                         "docs/implicit.md)")
        if self.options.get("edge_mass_ratio"):
            for effect in effects:   # a term whose forces and tangent are not folded onto the slaved nodes
                if type(effect).implicit_term is not Effect.implicit_term and not effect.implicit_term_folded:
                    raise ConfigError("solver.implicit.edge_mass_ratio", f"not with {effect.name} yet (its implicit "
                                                                         f"term is not folded onto the slaved nodes)")

    # -- one scene step, in as many sub-steps as Newton needs ------------------------------
    def advance(self, s, dt):
        self._start(s)
        done, halvings = 0.0, 0
        while done < dt * (1.0 - 1e-12):
            h = min(dt * self.fraction, dt - done)
            try:
                self.substep(s, h, s.t + done)
            except NewtonFailed as exc:
                halvings += 1
                self.stats["halvings"] += 1
                if self.fraction * 0.5 < 0.5 ** self.options["max_halvings"]:
                    raise UnstableRunError(
                        f"Newton's method did not converge at t = {s.t + done:.6g} s with the smallest step "
                        f"allowed, {h:.3g} s ({exc}); solver.implicit.max_halvings = "
                        f"{self.options['max_halvings']}") from None
                self.fraction *= 0.5
                self.converged_in_row = 0
                if s.decomp.rank == 0:
                    logger.info("t = %.6g s: Newton failed (%s); step halved to %.3g s", s.t + done, exc,
                                dt * self.fraction)
                continue
            done += h
            if done < dt * (1.0 - 1e-12):
                self.migrate_between_substeps(s)
            self.converged_in_row += 1
            if self.fraction < 1.0 and self.converged_in_row >= GROW_AFTER:
                self.fraction = min(1.0, 2.0 * self.fraction)
                self.converged_in_row = 0
        if s.t + dt >= s.options.end_time * (1.0 - 1e-12) and s.decomp.rank == 0:
            st = self.stats
            logger.info("implicit: %d steps, %d Newton iterations (%.2f a step), %d tangents, %d factorisations, "
                        "%d residual evaluations, %d linear iterations, %d halvings", st["steps"],
                        st["newton_iterations"], st["newton_iterations"] / max(st["steps"], 1),
                        st["tangents"], st["factorisations"], st["residual_evaluations"],
                        st["linear_iterations"], st["halvings"])

    def summary(self, s):
        """Entries of the run's summary: a load-factor control's path (``load_factor_path``:
        rows of time, load factor, iterations and the control's own column, one a converged
        step; pmpm.core.implicit.arclength) and its last load factor."""
        if self.control is None:
            return {}
        return {"load_factor": self.control.load_factor, "load_factor_path": [tuple(r) for r in self.control.path]}

    @staticmethod
    def migrate_between_substeps(s):
        """Particles that crossed their slab's boundary in a sub-step go to their new owner
        before the next sub-step of the same scene step (the solver migrates only at the step's
        end): the step's kernels index the rank's window from the particles' start positions,
        and a stencil has no spare node column above its slab (a cubic B-spline reaches two
        nodes above its cell, the ghost width is two), so a particle that crossed the upper
        boundary would make them read and write one column past the window (collective)."""
        if s.decomp.size == 1:
            return
        p, g, d = s.particles, s.grid, s.decomp
        c0, c1 = d.owned
        _, leaving, _ = K.count_strays(p["x"], p["vol"], g.origin, g.inv_h, g.cells[0], g.cells[1], s.axis,
                                       c0, min(c1, g.cells[s.axis]))
        s.migrate(int(d.allreduce_sum(leaving)))

    def _start(self, s):
        """First call: the PETSc solver, the options, and Newmark's start accelerations."""
        if self.linear is not None:
            return
        krylov = None
        if self.options.get("newton") == "krylov":
            krylov = (self.options["krylov_tolerance"], self.options["krylov_iterations"])
        self.linear = LinearSolver(s.comm, self.petsc, krylov, kept_only=self.options.get("newton") == "accelerated")
        # what the effects add to the step (pmpm.core.implicit.terms)
        self.terms = [t for t in (e.implicit_term(s) for e in s.effects) if t is not None]
        if ACCELERATION not in s.particles.fields:
            s.particles.add_field(ACCELERATION, (2,))
            if self.dynamic and self.options.get("initial_static"):
                # the loads at the start are in equilibrium: a_0 = 0. Not M^-1 (f_ext + f_int)
                # re-evaluated at the moved particles: the static stage's equilibrium holds on
                # its own grid functions, and the shape functions at the particles' new
                # positions (the grid reset) leave an imbalance of the order of the sag over
                # the cell times the internal forces, which at the light nodes of the
                # material's edges is an acceleration of tens of m/s^2 (60 m/s^2 at 0.05 m
                # cells on the three-storey frame: Newmark's predictor then moved those nodes
                # by 1.5 mm and the first step of the record did not converge)
                self.initial_equilibrium(s)
                self.migrate_between_substeps(s)   # (the static stage moved the particles)
            elif self.dynamic:
                self.start_accelerations(s)

    # -- phases ------------------------------------------------------------------------------
    def grid_from_particles(self, s, t_load):
        """Mass, momentum, m a and the external forces at ``t_load`` on the grid, halo-summed."""
        p = s.particles
        s.reset_grid()
        s.particles_to_grid(momentum=True, forces=False)
        geometry = s._step_context().geometry   # (G, ox, oy, origin, inv_h, ncx, ncy, shape)
        IK.scatter_inertia_and_gravity(p["x"], p["m"], p[ACCELERATION] if self.dynamic else None,
                                       s.gravity, *geometry)
        _scatter_point_forces(s, t_load, geometry)
        s.exchange_halo(slice(0, 7))
        self.edges = self._edge_slaves(s)

    def _edge_slaves(self, s):
        """``edge_mass_ratio``: the step's slaved edge nodes, with the grid's mass, momentum,
        forces and m a folded onto their targets (pmpm.core.implicit.edges); None without."""
        ratio = self.options.get("edge_mass_ratio", 0.0)
        if not ratio:
            return None
        G = s.window.G
        edges = EdgeSlaves(G[..., MASS], s.mass_cutoff, s.window.bc_mask.astype(bool),
                           owned_mask(G.shape[:2], s._owned_local), s.decomp, ratio)
        fields = np.ascontiguousarray(G[..., :7])
        edges.fold(fields)
        s.decomp.fill(fields)   # (a ghost target's slaved node may lie past the window)
        G[..., :7] = fields
        self.stats["slaved_nodes"] = int(s.decomp.allreduce_sum(edges.count_owned))   # (the last step's)
        return edges

    def external_forces(self, s, t, x=None):
        """Halo-summed external nodal forces at time ``t`` (weight and point loads), in a
        window array of their own (HHT-alpha needs the step's start forces too), from the
        particles at ``x`` (default their current positions; after the commit moved them, the
        step's start positions ``GridProblem.x``)."""
        p, w, g = s.particles, s.window, s.grid
        x = p["x"] if x is None else x
        T = np.zeros(w.G.shape)
        geometry = (T, w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape)
        if s.gravity is not None:
            IK.scatter_inertia_and_gravity(x, p["m"], None, s.gravity, *geometry)
        _scatter_point_forces(s, t, geometry, x)
        F = np.ascontiguousarray(T[..., FORCE])
        if self.edges is not None:
            self.edges.fold(F)
        s.decomp.sum_halo(F)
        return F

    def nodal_start(self, s):
        """Nodal velocity and acceleration at the step's start (zero off the active nodes);
        held components take their prescribed velocity and no acceleration."""
        G = s.window.G
        m = G[..., MASS]
        active = (m > s.mass_cutoff)[..., None]
        safe = np.where(active[..., 0], m, 1.0)[..., None]
        v = np.where(active, G[..., MOMENTUM] / safe, 0.0)
        a = np.where(active, G[..., INERTIA] / safe, 0.0)
        held = s.window.bc_mask.astype(bool)
        return np.where(held, s.window.bc_vel, v), np.where(held, 0.0, a)

    def initial_equilibrium(self, s):
        """``initial_static``: the loads at the start time (gravity, the force sets' values at
        t0) brought to static equilibrium in one load step before the dynamics (time does not
        advance, the particles stay at rest); the supports' reaction is kept as
        ``initial_reaction``. The dynamic run then starts from that state with a_0 = 0 up to
        Newton's tolerance, so nothing moves until a load changes (the particles' accelerations
        stay zero: _start)."""
        self.dynamic = False
        try:
            self.substep(s, 0.0, s.t)
        except NewtonFailed as exc:
            raise UnstableRunError(f"the initial static equilibrium (solver.implicit.initial_static) did not "
                                   f"converge ({exc})") from None
        finally:
            self.dynamic = True
        self.initial_reaction = self.held_force.copy()
        if s.decomp.rank == 0:
            logger.info("initial static equilibrium: %d Newton iterations, supports carry %s N",
                        self.stats["newton_iterations"], np.array2string(self.initial_reaction, precision=6))

    def start_accelerations(self, s):
        """Newmark's a_0 = M^-1 (f_ext(t0) + f_int(sigma_0)) on the grid (lumped mass),
        interpolated to the particles: the start state's own equilibrium, so that a load
        applied at t = 0 is felt at once."""
        self.grid_from_particles(s, s.t)
        v, _ = self.nodal_start(s)
        problem = GridProblem(s, self.linear, None, s.window.G[..., FORCE].copy(), v, None, None, self.terms,
                              self.edges)
        zero = np.zeros(s.window.G.shape[:2] + (2,))
        force = problem.internal_force(zero) + s.window.G[..., FORCE]
        for f in problem.term_start:   # damping of the start velocities
            if f is not None:
                force += f
        m = s.window.G[..., MASS]
        active = (m > s.mass_cutoff)[..., None] & ~s.window.bc_mask.astype(bool)
        a0 = problem.expand(np.where(active, force / np.where(m > s.mass_cutoff, m, 1.0)[..., None], 0.0))
        p = s.particles
        dx = np.empty((p.n, 2))
        x = p["x"].copy()
        w, g = s.window, s.grid
        IK.newmark_particles(x, p["v"].copy(), p[ACCELERATION], zero, zero, a0, w.ox, w.oy, g.origin, g.inv_h,
                             g.cells[0], g.cells[1], s.shape, dx)

    def substep(self, s, h, t0):
        """One step of length ``h`` from time ``t0``; raises NewtonFailed (particles untouched)."""
        self.grid_from_particles(s, t0 + h)
        rule = Newmark(h, self.alpha) if self.dynamic else None
        v, a = self.nodal_start(s) if self.dynamic else (None, None)
        for term in self.terms if self.dynamic else ():
            term.prescribe_start(s, t0, v, a)
        start = self.external_forces(s, t0) if self.dynamic and self.alpha else None
        problem = GridProblem(s, self.linear, rule, s.window.G[..., FORCE].copy(), v, a, start, self.terms,
                              self.edges)
        u = rule.predictor(v, a) if self.dynamic else np.zeros(s.window.G.shape[:2] + (2,))
        u = np.where(problem.dofs.active[..., None], u, 0.0)
        held = problem.held_increment(h)
        for prescribe in s._hooks["prescribe_increment"]:   # a pushover's nodes: their displacement
            prescribe(s, t0, h, held)
        u = np.where(problem.dofs.held, held, u)
        for term in self.terms:   # supports that move (ground motion)
            term.prescribe(s, t0, h, u, None, None)
        if not self.dynamic and s._hooks["prescribe_increment"]:   # displacement control
            u = linear_predictor(problem, u, s.grid.inv_h)
        self.history = []
        try:
            if self.control is not None:
                iterations = self.control.step(s, problem, u, h, t0, self.options, self.history)
            else:
                iterations = newton(problem, u, self.options, self.history)
        except ArithmeticError as exc:   # a Krylov solve that diverged counts as a failure
            raise NewtonFailed(str(exc)) from None
        finally:
            self.stats["residual_evaluations"] += problem.evaluations
            self.stats["tangents"] += problem.tangents
            self.stats["factorisations"] = self.linear.factorisations
            self.stats["linear_iterations"] = self.linear.iterations
            if self.linear.kept is not None and not self.linear.kept_only:   # newton = "krylov": tangents whose unknowns had changed
                self.stats["remapped_tangents"] = self.linear.remapped
            if self.linear.kept_only:   # newton = "accelerated": steps mapped onto the kept factorisation
                self.stats["refits"] = self.stats.get("refits", 0) + problem.refits
        if not self.options_checked and self.linear.ksp is not None:   # after the first solve
            self.linear.check_unused()
            self.options_checked = True
        self.stats["newton_iterations"] += iterations
        self.stats["steps"] += 1
        self.commit(s, problem, u, rule, v, a, t0, h)

    def commit(self, s, problem, u, rule, v, a, t0, h):
        """The converged increment onto the particles: positions, velocities, accelerations
        (Newmark, FLIP increments), stresses and states pushed forward, volumes, strains, and
        the energy bookkeeping the solver's checks read."""
        p = s.particles
        if self.edges is not None:   # the slaved edge nodes' increments, which the particles read
            u = self.edges.expand(u.copy())
        R = problem.internal_force(u) + problem.fext     # also leaves S, state of u
        held = problem.dofs.held & problem.dofs.owned_active[..., None]
        self.held_force = s.decomp.allreduce_sum(np.where(held, R, 0.0).sum(axis=(0, 1)))
        w, g = s.window, s.grid
        dx = s._scratch("_dx_buf", (p.n, 2))
        if rule is not None:
            a_new = rule.acceleration(u, v, a)
            a_new = np.where(problem.dofs.active[..., None], a_new, 0.0)
            dv = rule.velocity_change(a, a_new)
            for term in self.terms:   # the supports' own velocity change and acceleration
                term.prescribe(s, t0, h, None, dv, a_new)
            # (after the supports' values: a slaved edge node's targets may be driven nodes)
            a_new, dv = problem.expand(a_new), problem.expand(dv)
            vmax, bad = IK.newmark_particles(p["x"], p["v"], p[ACCELERATION], u, dv, a_new, w.ox, w.oy,
                                             g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape, dx)
            if self.terms:
                self._support_work(s, problem, u, R, a_new, held)
        else:
            vmax, bad = IK.newmark_particles(p["x"], None, None, u, None, None, w.ox, w.oy,
                                             g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape, dx)
        # what grid-to-particles leaves for the solver's end of step (pmpm.core.fields does the
        # same): the moves, the speed and the count of non-finite particles
        s._dx = dx
        s._vmax_local, s._bad_local = vmax, bad
        self._work(s, problem, t0, h)
        IK.push_forward(problem.S, problem.f, p["stress"], p["vol"], p.fields.get("strain"), problem.E)
        for k, m in enumerate(s.materials):
            for name in m.state_fields:
                new = problem.state[k][name]
                if new is None:
                    continue
                if name in m.tensor_state_fields:
                    IK.push_forward(new, problem.f, new, None, None, problem.E)
                mine = p["mat"] == k if len(s.materials) > 1 else slice(None)
                p[name][mine] = new[mine]
        s._de = problem.E   # the step's strain increment, where the explicit phases leave it
        for term in self.terms:
            term.commit(s, problem, u)
        if s._hooks["after_implicit_step"] or s._hooks["prescribe_increment"]:   # reactions, a pushover
            self._supports(s, problem, u, R, a if rule is not None else None,
                           a_new if rule is not None else None, t0, h)

    def _supports(self, s, problem, u, R, a_start, a_new, t0, h):
        """The supports' forces on the held components, to the effects that read them
        (pmpm.core.effects.ConvergedStep). In statics the force is minus the free equations'
        residual there (f_int + f_ext), and its work over the held increments (the trapezoid of
        the step's start and end forces: a pushover's work) goes to the external work. In
        dynamics it is m a - (f_int + f_ext) - the terms' forces (Rayleigh's) at the end, and
        m a - (f_int + f_ext) at the start (the held nodes' start acceleration: zero, or the
        ground's; the start's damping forces at the supports are left out of the start value);
        the moving supports' work is :meth:`_support_work`'s there (fixed ones do none)."""
        held = problem.dofs.held
        # (the particles have moved: the start's forces from the step's start positions)
        start = -(problem.fint_start + self.external_forces(s, t0, problem.x))
        if a_new is None:
            end = -R
        else:
            start = start + problem.mass[..., None] * a_start
            R = R.copy()
            for term in self.terms:
                term.add_residual(problem, u, R)
            end = problem.mass[..., None] * a_new - R
        start, end = np.where(held, start, 0.0), np.where(held, end, 0.0)
        if a_new is None:
            mine = problem.dofs.owned_active[..., None]
            s.external_work += float(np.sum(np.where(mine, 0.5 * (start + end) * u, 0.0)))
        step = ConvergedStep(t0, h, a_new is None, end, None if a_new is None else start)
        for after in s._hooks["after_implicit_step"]:
            after(s, step)

    def _support_work(self, s, problem, u, R, a_new, held):
        """Work of the supports that move (ground motion) over the step, into the external
        work (the explicit step's grid update does the same): the force a held component
        needs, m a - f_int - f_ext - the terms' forces, by the trapezoid of the step's start
        (the last step's end) and end over the held increment."""
        R = R.copy()
        for term in self.terms:
            term.add_residual(problem, u, R)
        force = np.where(held, problem.mass[..., None] * a_new - R, 0.0)
        before = getattr(self, "_support_force", None)
        if before is None or before.shape != force.shape:
            before = force
        s.external_work += float(np.sum(0.5 * (before + force) * np.where(held, u, 0.0)))
        self._support_force = force

    def _work(self, s, problem, t0, h):
        """Internal work (trapezoid of the start and trial stresses over the step's strain) and
        the external work of gravity and the point loads (trapezoid of their start and end
        values over the particles' moves): the balance the solver's energy check reads."""
        p = s.particles
        mean = 0.5 * (problem.stress0[:, :3] + problem.S[:, :3])
        s.internal_work += float(np.sum(p["vol"] * np.einsum("pk,pk->p", mean, problem.E)))
        if self.control is not None:   # the loads scaled by the step's load factors
            s.external_work += self.control.external_work(s, t0, h, self.control.lam0, self.control.load_factor)
            return
        if s.gravity is not None:
            s.external_work += float(np.sum(p["m"] * (s._dx @ s.gravity)))
        loads = s.effect("loads")
        for t in (t0, t0 + h):
            point = loads.point_forces(p, t) if loads is not None else None
            if point is not None:
                idx, load_id, load_w, load_vec = point
                s.external_work += 0.5 * K.point_load_work(idx, s._dx, load_id, load_w, load_vec)


def _scatter_point_forces(s, t, geometry, x=None):
    """The force sets of the ``loads`` effect at time ``t`` onto the window array of
    ``geometry`` (none without the effect or without force sets), from the particles at ``x``
    (default their current positions)."""
    loads = s.effect("loads")
    point = loads.point_forces(s.particles, t) if loads is not None else None
    if point is not None:
        idx, load_id, load_w, load_vec = point
        K.scatter_point_loads(idx, s.particles["x"] if x is None else x, load_id, load_w, load_vec, *geometry)
