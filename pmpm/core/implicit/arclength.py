"""Load-factor control of a static analysis (``[solver.static]``, docs/implicit.md): a load
pattern scaled by a load factor lambda that is an unknown of each step,

    R(u, lambda) = lambda f_ref + f_fixed + f_int(u) = 0,      c(u, lambda) = 0,

f_ref the pattern (the ``pattern``'s force sets at their full value, and the weight when
``gravity = "pattern"``), f_fixed the loads held at their value (the weight by default, the
force sets outside the pattern at their time functions), u the step's nodal displacement
increment (pmpm.core.implicit.problem.GridProblem), c the step's constraint:

- ``displacement``: the controlled point's displacement increment is prescribed,
  e . sum_I N_I(x_p) u_I = d (linear in u: the bordered system);
- ``arc_length``: Crisfield's cylindrical arc length, |u|^2 = dl^2 over the free components
  (Crisfield 1981), so that the path passes limit points where lambda falls.

Both are solved by Batoz and Dhatt's (1979) two back-substitutions with the same factorisation
at each iteration: K du_R = R (the out-of-balance force), K du_F = f_ref, the correction
du = du_R + d_lambda du_F with d_lambda from the constraint (linear: one value; arc length: the
quadratic's root whose new increment makes the smaller angle with the current one, Crisfield's
choice). The predictor is d_lambda du_F of the start state's tangent: its sign under arc length
follows the previous step's increment (the sign of u_prev . du_F: positive on the rising branch,
negative past a limit point where the tangent's du_F turns against the path; Feng et al. 1996).
The arc length follows the iterations the last step took, dl <- dl sqrt(target / iterations)
(Crisfield), within [1/2, 2] of its last value and at most ``MAX_ARC_GROWTH`` times the first.

A step's length h in pseudo-time scales the step: the displacement's increment is
displacement h / end_time and the arc length dl h / time_step, so that a step the scheme halves
after a failure (pmpm.core.implicit.scheme) is a half step. When the loads outside the pattern
are not zero, the first step brings them to equilibrium at lambda = 0 (plain Newton); the
controlled steps follow. ``max_load_factor``: a step that would pass it is solved again at
lambda = max_load_factor (load control), and the steps after it hold that load.

The convergence test is Newton's (pmpm.core.implicit.newton): the residual against the force
scale and the energy of the next correction; the constraint holds exactly after every
correction.
"""
import logging
import math

import numpy as np

from pmpm.core import kernels as K
from pmpm.core.implicit import kernels as IK
from pmpm.core.implicit.newton import NewtonFailed, newton
from pmpm.registry import lookup, names

__all__ = ["LoadFactorControl", "DisplacementControl", "ArcLength", "make_control", "control_names",
           "MAX_ARC_GROWTH"]
logger = logging.getLogger(__name__)

#: the arc length never grows past this many times the first step's
MAX_ARC_GROWTH = 4.0
#: the window array's external-force fields (pmpm.core.implicit.kernels)
FORCE = slice(3, 5)


class LoadFactorControl:
    """A static step whose load factor is an unknown (module doc); subclasses give the
    constraint (``predict``, ``correct``).

    Parameters
    ----------
    options : dict
        ``[solver.static]`` as pmpm.core.implicit.options.read_static gives it.
    time_step, end_time : float
        The scene's step and end (pseudo-time).
    """

    name = None

    def __init__(self, options, time_step, end_time):
        self.options = dict(options)
        self.time_step, self.end_time = time_step, end_time
        self.max_load_factor = self.options["max_load_factor"]
        self.load_factor = 0.0
        self.path = []            # (t, load factor, iterations) of every converged step
        self.equilibrated = False  # the fixed loads brought to equilibrium (first step)
        self.finished = False     # max_load_factor reached: the steps hold it
        self.previous = None      # the last controlled step's increment (window array)
        self._pattern_ids = None

    # -- the loads ---------------------------------------------------------------------------
    def _pattern(self, loads):
        if self._pattern_ids is None:
            sets = loads.forces if loads is not None else ()
            wanted = self.options["pattern"]
            self._pattern_ids = [k for k, f in enumerate(sets) if wanted is None or f.name in wanted]
        return self._pattern_ids

    def _vectors(self, loads, t):
        """(fixed, reference) (n_sets, 2) totals of the force sets: the pattern's at their full
        value in the reference, the others at their time functions in the fixed loads."""
        fixed = loads.vectors(t).copy()
        ref = np.zeros_like(fixed)
        for k in self._pattern(loads):
            ref[k] = loads.forces[k].force
            fixed[k] = 0.0
        return fixed, ref

    def load_vectors(self, s, x, t):
        """(f_fixed, f_ref) on the window (nx, ny, 2), halo-summed, from the particles at ``x``
        (the step's start positions: dead loads)."""
        p, w, g = s.particles, s.window, s.grid
        out = []
        for which in ("fixed", "pattern"):
            T = np.zeros(w.G.shape)
            geometry = (T, w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], s.shape)
            if s.gravity is not None and self.options["gravity"] == which:
                IK.scatter_inertia_and_gravity(x, p["m"], None, s.gravity, *geometry)
            loads = s.effect("loads")
            point = loads.point_forces(p, t) if loads is not None else None
            if point is not None:
                idx, load_id, load_w, _ = point
                vec = self._vectors(loads, t)[0 if which == "fixed" else 1]
                K.scatter_point_loads(idx, x, load_id, load_w, vec, *geometry)
            F = np.ascontiguousarray(T[..., FORCE])
            s.decomp.sum_halo(F)
            out.append(F)
        return out[0], out[1]

    def external_work(self, s, t0, h, lam0, lam1):
        """Work of the loads over the step's particle moves ``s._dx`` (trapezoid of the start
        and end values: the fixed loads' time functions, the pattern's load factors)."""
        p, dx = s.particles, s._dx
        work = 0.0
        if s.gravity is not None:
            weight = float(np.sum(p["m"] * (dx @ s.gravity)))
            work += weight * (0.5 * (lam0 + lam1) if self.options["gravity"] == "pattern" else 1.0)
        loads = s.effect("loads")
        point = loads.point_forces(p, t0) if loads is not None else None
        if point is not None:
            idx, load_id, load_w, _ = point
            for t, lam in ((t0, lam0), (t0 + h, lam1)):
                fixed, ref = self._vectors(loads, t)
                work += 0.5 * K.point_load_work(idx, dx, load_id, load_w, fixed + lam * ref)
        return work

    # -- one step ----------------------------------------------------------------------------
    def step(self, s, problem, u, h, t0, opts, history):
        """Solve the step (``u``, the window's increment, zero on entry, is overwritten by the
        converged one; ``problem.fext`` is left at the converged loads for the commit).
        Returns the iterations taken; raises NewtonFailed (nothing kept) when it fails."""
        self.lam0 = self.load_factor
        fixed, ref = self.load_vectors(s, problem.x, t0 + h)
        d = problem.dofs
        free = problem.free
        rf = d.owned_values(ref).copy()
        rf[~free] = 0.0
        fixed_free = d.owned_values(fixed)[free]
        has_fixed = problem.dot(fixed_free, fixed_free) > 0.0
        if self.finished or (has_fixed and not self.equilibrated):
            # the loads held at their value (first step), or max_load_factor reached: load control
            problem.fext = fixed + self.load_factor * ref
            problem.force_scale = self._scale(problem, fixed, ref, abs(self.load_factor))
            iterations = newton(problem, u, opts, history)
            self.equilibrated = True
            self.after_step(problem, u)
            self._record(t0 + h, iterations)
            return iterations
        self.equilibrated = True
        # the start state on this step's grid: the last step's converged state is not exactly in
        # equilibrium on it (the grid is reset and the particles have moved across it), and that
        # out-of-balance force, through a tangent softened by yielding, would take the first
        # correction off the arc (no real root) however short the arc. So the step first brings
        # its start back to equilibrium at the start's load factor (plain Newton, fixed lambda),
        # and the constraint measures the increment from there.
        problem.fext = fixed + self.load_factor * ref
        problem.force_scale = self._scale(problem, fixed, ref, abs(self.load_factor))
        base = np.zeros_like(u)
        r0, n0 = problem.residual(base)
        balance = 0
        if n0 > opts["residual_tolerance"] * problem.force_scale:
            balance = newton(problem, base, opts)
        logger.debug("step start: lambda %.6g, residual %.3g (%d iterations to balance it)", self.load_factor,
                     n0, balance)
        dlam, du = self.predict(problem, rf, h, base)
        u[...] = problem.add(base, du, 1.0)
        problem.force_scale = self._scale(problem, fixed, ref, max(abs(self.load_factor),
                                                                   abs(self.load_factor + dlam)))
        energy0 = None
        base_owned = d.owned_values(base).copy()
        for k in range(opts["max_iterations"] + 1):
            lam = self.load_factor + dlam
            problem.fext = fixed + lam * ref
            r, norm = problem.residual(u)
            if not math.isfinite(norm):
                raise NewtonFailed(f"residual not finite at iteration {k}")
            if k == 0:
                scale = max(problem.force_scale, norm)
            logger.debug("  iteration %d: lambda %.6g residual %.3g (scale %.3g)", k, lam, norm, scale)
            if k > 0 and norm <= opts["residual_tolerance"] * scale:
                # the energy of the next correction, with the last factorisation (as Newton's)
                uR = problem.solve(r)
                energy = abs(problem.dot(uR, r))
                if history is not None:
                    history.append((norm, energy))
                if energy <= opts["energy_tolerance"] * energy0:
                    break
            if k == opts["max_iterations"]:
                raise NewtonFailed(f"{self.name} control: no convergence in {opts['max_iterations']} iterations "
                                   f"(residual {norm:.3g}, {norm / scale:.3g} of the force scale)")
            problem.tangent(u)
            uR = problem.solve(r)      # K du_R = R
            uF = problem.solve(rf)     # K du_F = f_ref, the same factorisation
            energy = abs(problem.dot(uR, r))
            if energy0 is None:
                energy0 = energy * (scale / norm) ** 2 if energy > 0.0 and norm > 0.0 else 1.0
            if history is not None and not (k > 0 and norm <= opts["residual_tolerance"] * scale):
                history.append((norm, energy))
            increment = d.owned_values(u) - base_owned
            dl = self.correct(problem, increment, uR, uF, h)
            u[...] = problem.add(u, uR + dl * uF, 1.0)
            dlam += dl
        iterations = k
        lam = self.load_factor + dlam
        if lam > self.max_load_factor >= self.load_factor:
            # past the largest load factor asked: the step again at exactly that load, from the
            # converged increment scaled back (load control)
            u[...] = base + (u - base) * ((self.max_load_factor - self.load_factor) / dlam)
            problem.fext = fixed + self.max_load_factor * ref
            iterations += newton(problem, u, opts, history)
            lam, self.finished = self.max_load_factor, True
        self.previous = u - base   # (a window array: the next step's unknowns may differ)
        self.previous_dlam = lam - self.load_factor
        self.load_factor = lam
        self.adapt(iterations)   # (the controlled iterations: the balance's are the grid's, not the arc's)
        self.after_step(problem, u)
        self._record(t0 + h, iterations + balance)
        return iterations + balance

    def _scale(self, problem, fixed, ref, lam):
        """The step's force scale: the start's internal force and the loads at ``lam``."""
        d, free = problem.dofs, problem.free
        fi = d.owned_values(problem.fint_start)[free]
        fe = d.owned_values(fixed + lam * ref)[free]
        return float(math.sqrt(problem.dot(fi, fi) + problem.dot(fe, fe)))

    def _record(self, t, iterations):
        self.path.append((t, self.load_factor, iterations))

    def adapt(self, iterations):
        """After a converged controlled step (arc length: the next arc's length)."""

    def after_step(self, problem, u):
        """After every converged step, with its increment ``u`` (window)."""

    def predict(self, problem, rf, h, base):
        """(d_lambda, the owned increment) of the step's first guess from the balanced start."""
        raise NotImplementedError

    def correct(self, problem, u, uR, uF, h):
        """d_lambda of the correction du_R + d_lambda du_F to the increment ``u`` (owned, from
        the balanced start) that keeps the constraint."""
        raise NotImplementedError


class DisplacementControl(LoadFactorControl):
    """The controlled point's displacement component prescribed (``point``, ``component``,
    ``displacement`` at end_time, linear in pseudo-time): the particle nearest ``point`` by
    its initial position (the rule of ``[[output.track]]``), followed by its id."""

    name = "displacement"

    def __init__(self, options, time_step, end_time):
        super().__init__(options, time_step, end_time)
        self.particle = None
        self.point_displacement = 0.0   # the point's controlled component, summed over the steps

    def _find(self, s):
        """The id of the particle nearest ``point`` by initial position (collective)."""
        p, d = s.particles, s.decomp
        best, pid = math.inf, -1
        if p.n:
            dist = np.sum((p["x0"] - np.asarray(self.options["point"])) ** 2, axis=1)
            k = int(np.argmin(dist))
            best, pid = float(dist[k]), int(p["id"][k])
        nearest = d.allreduce_min(best)
        return int(d.allreduce_min(pid if best == nearest else np.iinfo(np.int64).max))

    def weights(self, problem):
        """The constraint's vector c (owned values): e . N_I(x_p) on the nodes of the point's
        stencil at the step's start position, so that c . u is the point's displacement
        increment (the commit moves a particle by sum_I N_I(x_p) u_I)."""
        s = problem.s
        if self.particle is None:
            self.particle = self._find(s)
        rows = np.flatnonzero(s.particles["id"] == self.particle) if s.particles.n else np.empty(0, np.int64)
        w, g = s.window, s.grid
        T = np.zeros(w.G.shape)
        direction = np.zeros(2)
        direction[self.options["component"]] = 1.0
        x = np.ascontiguousarray(problem.x[rows])
        IK.scatter_inertia_and_gravity(x, np.ones(len(rows)), None, direction, T, w.ox, w.oy, g.origin, g.inv_h,
                                       g.cells[0], g.cells[1], s.shape)
        C = np.ascontiguousarray(T[..., FORCE])
        s.decomp.sum_halo(C)
        c = problem.dofs.owned_values(C).copy()
        c[~problem.free] = 0.0
        return c

    def predict(self, problem, rf, h, base):
        uF = tangent_direction(problem, rf, base)
        self.c = self.weights(problem)
        self.target = self.options["displacement"] * h / self.end_time
        slope = problem.dot(self.c, uF)
        if slope == 0.0 or not math.isfinite(slope):
            raise NewtonFailed("displacement control: the pattern does not move the controlled point")
        return self.target / slope, (self.target / slope) * uF

    def correct(self, problem, u, uR, uF, h):
        slope = problem.dot(self.c, uF)
        if slope == 0.0 or not math.isfinite(slope):
            raise NewtonFailed("displacement control: the pattern no longer moves the controlled point")
        return (self.target - problem.dot(self.c, u) - problem.dot(self.c, uR)) / slope

    def after_step(self, problem, u):
        # the point's move in this step, whatever drove it (the fixed loads' first step too)
        c = self.weights(problem)
        self.point_displacement += problem.dot(c, problem.dofs.owned_values(u))

    def _record(self, t, iterations):
        self.path.append((t, self.load_factor, iterations, self.point_displacement))


class ArcLength(LoadFactorControl):
    """Crisfield's cylindrical arc length, |u|^2 = dl^2 over the free components (module doc):
    the first step's arc is ``load_factor_increment`` |K^-1 f_ref|."""

    name = "arc_length"

    def __init__(self, options, time_step, end_time):
        super().__init__(options, time_step, end_time)
        self.arc = None     # the arc length of a whole step (m)
        self.arc0 = None
        self.missed = 0     # corrections whose line missed the arc (no real root)

    def predict(self, problem, rf, h, base):
        """The first step: along the start tangent's K^-1 f_ref. Later steps: along the last
        step's increment (u_prev, d_lambda_prev) scaled to the arc, the secant predictor: the
        start tangent of a yielding structure is the elastic one (a point on the yield surface
        with no increment yet is elastic), and its predictor overshoots the limit load by the
        whole elastic reserve; the secant follows the path through the limit point (its sign
        is the path's)."""
        if self.previous is not None:
            prev = problem.dofs.owned_values(self.previous).copy()
            prev[~problem.free] = 0.0
            length = math.sqrt(problem.dot(prev, prev))
            if length > 0.0:
                self.dl = self.arc * h / self.time_step
                return self.previous_dlam * self.dl / length, prev * (self.dl / length)
        uF = tangent_direction(problem, rf, base)
        length = math.sqrt(problem.dot(uF, uF))
        if length == 0.0 or not math.isfinite(length):
            raise NewtonFailed("arc length: the pattern moves nothing")
        if self.arc is None:
            self.arc0 = self.arc = self.options["load_factor_increment"] * length
        self.dl = self.arc * h / self.time_step
        return self.dl / length, uF * (self.dl / length)

    def correct(self, problem, u, uR, uF, h):
        base = u + uR
        a = problem.dot(uF, uF)
        b = 2.0 * problem.dot(uF, base)
        c = problem.dot(base, base) - self.dl ** 2
        disc = b * b - 4.0 * a * c
        logger.debug("arc length: |u| %.3g |u_R| %.3g |u_F| %.3g dl %.3g disc %.3g", math.sqrt(problem.dot(u, u)),
                     math.sqrt(problem.dot(uR, uR)), math.sqrt(a), self.dl, disc)
        if a == 0.0:
            raise NewtonFailed("arc length: the pattern moves nothing")
        if disc < 0.0:
            # no point of the correction's line on the arc: the out-of-balance force's correction
            # alone leaves it (the start's residual, from the particles' new positions on the
            # grid, through a tangent softened by yielding). Take the line's point nearest the
            # arc (the quadratic's real part, Crisfield's remedy short of cutting the arc): the
            # next iterations, from nearer equilibrium, meet the constraint again.
            self.missed += 1
            return -0.5 * b / a
        q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
        roots = (q / a, c / q) if q != 0.0 else (0.0, 0.0)
        # Crisfield's choice: the root whose new increment turns least from the current one
        u_u = problem.dot(u, u)
        cosines = [problem.dot(u, base) + r * problem.dot(u, uF) for r in roots]
        if u_u == 0.0:
            return max(roots)
        return roots[int(np.argmax(cosines))]

    def adapt(self, iterations):
        factor = min(2.0, max(0.5, math.sqrt(self.options["target_iterations"] / max(iterations, 1))))
        self.arc = min(self.arc * factor, MAX_ARC_GROWTH * self.arc0)

    def _record(self, t, iterations):
        self.path.append((t, self.load_factor, iterations, self.arc))


def tangent_direction(problem, rf, base):
    """K^-1 f_ref with the tangent at the step's balanced start ``base`` (factorised here)."""
    problem.tangent(base)
    return problem.solve(rf)


def make_control(static, time_step, end_time):
    """The load-factor control of ``[solver.static]`` (None: the loads' time functions)."""
    if static is None:
        return None
    return lookup(LoadFactorControl, static["control"])(static, time_step, end_time)


def control_names():
    return names(LoadFactorControl)
