"""Load-factor control of a static analysis (``[solver.static]``, docs/implicit.md): a load
pattern scaled by a load factor lambda that is an unknown of each step,

    R(u, lambda) = lambda f_ref + f_fixed + f_int(u) = 0,      c(u, lambda) = 0,

f_ref the pattern (the ``pattern``'s force sets at their full value, and the weight when
``gravity = "pattern"``), f_fixed the loads held at their value (the weight by default, the
force sets outside the pattern at their time functions), u the step's nodal displacement
increment (pmpm.core.implicit.problem.GridProblem), c the step's constraint:

- ``displacement``: the controlled point's displacement is prescribed, e . sum_I N_I(x_p) u_I
  = d (linear in u: the bordered system), d what the schedule displacement t / end_time
  leaves at the step's end;
- ``arc_length``: Crisfield's (1981) cylindrical arc length |u|_m = dl over the free
  components, the norm weighted by the nodes' masses (``ArcLength``), so that the path passes
  limit points where lambda falls.

Both are solved by Batoz and Dhatt's (1979) two back-substitutions with the same factorisation
at each iteration: K du_R = R (the out-of-balance force), K du_F = f_ref, the correction
du = du_R + d_lambda du_F with d_lambda from the constraint (linear: one value; arc length: the
quadratic's root whose new increment turns least from the current one, Crisfield's choice, or
Riks' normal plane where the line misses the arc). Predictors: displacement control, K^-1 f_ref
scaled to the increment; arc length, K^-1 f_ref in the first step and in a retried one (its
sign the path's: u_prev . W du_F, Feng et al. 1996), else the last step's increment scaled to
the arc (the secant). The arc follows the iterations the last step took, dl <- dl sqrt(target /
iterations) (Crisfield), within [1/2, 2] of its last value and at most ``MAX_ARC_GROWTH`` times
the first.

An arc-length step first balances its start (``ArcLength.balance``): the particles have moved
across the grid since the last step converged, and on the new step's grid the converged state
is off balance by a force that a tangent softened by yielding turns into a correction longer
than a short arc (no real root, however short the arc). Displacement control needs no balance:
its linear constraint on the whole increment absorbs it. A step's length h in pseudo-time
scales the step (the point's schedule is in t; the arc is dl h / time_step), so that a step the
scheme halves after a failure (pmpm.core.implicit.scheme) is a half step. ``max_load_factor``:
a step that would pass it is solved again at lambda = max_load_factor (load control), and the
steps after it hold that load.

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

#: nodes whose mass is below this fraction of the largest node's are left out of the arc
#: length's norm (the cubic splines' tails beyond a body's edge: their stiffness is as tiny
#: as their mass and their increments are the ill-conditioned rows' (1.7 km on the column)
EDGE_MASS = 1e-2
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
    #: the names of the path's columns after (t, load factor, iterations)
    columns = ()

    def __init__(self, options, time_step, end_time):
        self.options = dict(options)
        self.time_step, self.end_time = time_step, end_time
        self.max_load_factor = self.options["max_load_factor"]
        self.load_factor = 0.0
        self.path = []            # (t, load factor, iterations) of every converged step
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

    def load_vectors(self, s, x, t, edges=None):
        """(f_fixed, f_ref) on the window (nx, ny, 2), halo-summed, from the particles at ``x``
        (the step's start positions: dead loads); with slaved edge nodes (``edges``,
        pmpm.core.implicit.edges) folded onto their targets before the halo sum, as the
        scheme's external forces are."""
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
            if edges is not None:
                edges.fold(F)
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
        fixed, ref = self.load_vectors(s, problem.x, t0 + h, problem.edges)
        d = problem.dofs
        free = problem.free
        rf = d.owned_values(ref).copy()
        rf[~free] = 0.0
        if self.finished:
            # max_load_factor reached: the steps hold it (load control)
            problem.fext = fixed + self.load_factor * ref
            problem.force_scale = self._scale(problem, fixed, ref, abs(self.load_factor))
            iterations = newton(problem, u, opts, history)
            self.after_step(problem, u)
            self._record(t0 + h, iterations)
            self._log(s)
            return iterations
        # the start state on this step's grid (the control's own rule: ``balance``); the
        # constraint measures the increment from the balanced start ``base``
        problem.fext = fixed + self.load_factor * ref
        problem.force_scale = self._scale(problem, fixed, ref, abs(self.load_factor))
        base = np.zeros_like(u)
        lam_start, balance = self.balance(problem, base, fixed, ref, rf, opts)
        self.t_step = t0 + h
        # a step that starts where the last attempt started is its retry after a failure
        self.retry = getattr(self, "_attempt", None) == (t0, self.load_factor)
        self._attempt = (t0, self.load_factor)
        dlam, du = self.predict(problem, rf, h, base)
        u[...] = problem.add(base, du, 1.0)
        problem.force_scale = self._scale(problem, fixed, ref, max(abs(lam_start), abs(lam_start + dlam)))
        energy0 = None
        base_owned = d.owned_values(base).copy()
        for k in range(opts["max_iterations"] + 1):
            lam = lam_start + dlam
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
        lam = lam_start + dlam
        if lam > self.max_load_factor >= lam_start:
            # past the largest load factor asked: the step again at exactly that load, from the
            # converged increment scaled back (load control)
            u[...] = base + (u - base) * ((self.max_load_factor - lam_start) / dlam)
            problem.fext = fixed + self.max_load_factor * ref
            iterations += newton(problem, u, opts, history)
            lam, self.finished = self.max_load_factor, True
        self.previous = u - base   # (a window array: the next step's unknowns may differ)
        self.previous_dlam = lam - lam_start
        self.load_factor = lam
        self.adapt(iterations)   # (the controlled iterations: the balance's are the grid's, not the arc's)
        self.after_step(problem, u)
        self._record(t0 + h, iterations + balance)
        self._log(s)
        return iterations + balance

    def balance(self, problem, base, fixed, ref, rf, opts):
        """Bring the step's start to equilibrium on this step's grid, in ``base`` (window, zero
        on entry); returns (the load factor there, iterations). Here: nothing (a constraint on
        the whole increment, such as a point's displacement, absorbs the start's imbalance)."""
        return self.load_factor, 0

    def _scale(self, problem, fixed, ref, lam):
        """The step's force scale: the start's internal force and the loads at ``lam``."""
        d, free = problem.dofs, problem.free
        fi = d.owned_values(problem.fint_start)[free]
        fe = d.owned_values(fixed + lam * ref)[free]
        return float(math.sqrt(problem.dot(fi, fi) + problem.dot(fe, fe)))

    def _record(self, t, iterations):
        self.path.append((t, self.load_factor, iterations))

    def _log(self, s):
        if s.decomp.rank == 0:
            row = self.path[-1]
            logger.info("t = %.6g: load factor %.8g (%d iterations%s)", row[0], row[1], row[2],
                        "".join(f", {name} {value:.6g}" for name, value in zip(self.columns, row[3:])))

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
    ``displacement`` at end_time, linear in pseudo-time: the point's displacement is
    displacement t / end_time at the end of every step, the fixed loads' share and the steps'
    balances included): the particle nearest ``point`` by its initial position (the rule of
    ``[[output.track]]``), followed by its id."""

    name = "displacement"
    columns = ("point displacement (m)",)

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
        increment (the commit moves a particle by sum_I N_I(x_p) u_I); with slaved edge nodes
        the weights are folded (T^T c: the particle moves by the expanded increment T u)."""
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
        problem.fold_and_sum(C)
        c = problem.dofs.owned_values(C).copy()
        c[~problem.free] = 0.0
        return c

    def predict(self, problem, rf, h, base):
        uF = tangent_direction(problem, rf, base)
        self.c = self.weights(problem)
        # the point follows the schedule displacement t / end_time exactly: this step's increment
        # from the balanced start is what remains of it after the earlier steps and the balance
        scheduled = self.options["displacement"] * self.t_step / self.end_time
        self.target = scheduled - self.point_displacement - problem.dot(self.c, problem.dofs.owned_values(base))
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
    """Crisfield's cylindrical arc length, |u|_m^2 = dl^2 over the free components (module doc),
    the norm weighted by the nodes' masses over their mean, |u|_m^2 = sum_I m_I |u_I|^2 / m_mean:
    the material's displacement. The plain norm counts the nodes at the edges of the bodies,
    whose few particles (a cubic spline's tail) carry a tiny stiffness and whose increments are
    the under-integrated modes', as much as a node inside; on the column past its limit point
    they held most of a step's |u| and were inactive in the next step (the secant predictor's
    length came out 8 times short, and the path turned back). The first step's arc is
    ``load_factor_increment`` |K^-1 f_ref|_m."""

    name = "arc_length"
    columns = ("arc length (m)",)

    def __init__(self, options, time_step, end_time):
        super().__init__(options, time_step, end_time)
        self.arc = None     # the arc length of a whole step (m)
        self.arc0 = None
        self.missed = 0     # corrections whose line missed the arc (no real root)

    def _weights(self, problem):
        """Owned weights m_I / m_mean per component (zero on held components)."""
        d = problem.dofs
        m = d.owned_values(np.repeat(problem.mass[..., None], 2, axis=2)).copy()
        m[~problem.free] = 0.0
        largest = problem.s.decomp.allreduce_max(float(m.max()) if m.size else 0.0)
        m[m < EDGE_MASS * largest] = 0.0
        count = problem.s.decomp.allreduce_sum(float(np.count_nonzero(m)))
        mean = problem.s.decomp.allreduce_sum(float(m.sum())) / max(count, 1.0)
        self.w = m / mean if mean > 0.0 else m

    def norm_dot(self, problem, a, b):
        return problem.dot(self.w * a, b)

    def balance(self, problem, base, fixed, ref, rf, opts):
        """The last step's converged state is not exactly in equilibrium on this step's grid (the
        grid is reset and the particles have moved across it), and that out-of-balance force,
        through a tangent softened by yielding, takes the first correction off a short arc (the
        quadratic has no real root however short the arc). So the start is balanced first: in
        the first step by Newton at the start's load factor (the fixed loads to equilibrium at
        lambda = 0), later by corrections held normal to the last step's increment p (Riks'
        normal plane, p . W (base + du_R + d_lambda du_F) = 0, so lambda moves too): at fixed
        lambda a start past a limit point has no equilibrium near it to find, and Newton
        diverged there."""
        self._weights(problem)
        r, norm = problem.residual(base)
        tol = opts["residual_tolerance"] * problem.force_scale
        logger.debug("  balance 0: lambda %.6g residual %.3g", self.load_factor, norm)
        if norm <= tol:
            return self.load_factor, 0
        if self.previous is None:
            return self.load_factor, newton(problem, base, opts)
        p = problem.dofs.owned_values(self.previous).copy()
        p[~problem.free] = 0.0
        p *= self.w
        lam = self.load_factor
        for k in range(1, opts["max_iterations"] + 1):
            problem.tangent(base)
            uR, uF = problem.solve(r), problem.solve(rf)
            slope = problem.dot(p, uF)
            dl = -problem.dot(p, problem.dofs.owned_values(base) + uR) / slope if slope != 0.0 else 0.0
            base[...] = problem.add(base, uR + dl * uF, 1.0)
            lam += dl
            problem.fext = fixed + lam * ref
            r, norm = problem.residual(base)
            logger.debug("  balance %d: lambda %.6g residual %.3g (d_lambda %.3g)", k, lam, norm, dl)
            if not math.isfinite(norm):
                break
            if norm <= tol:
                logger.debug("step start balanced in %d iterations: lambda %.6g -> %.6g", k, self.load_factor, lam)
                return lam, k
        # the balance diverged (a start the normal plane cannot bring back, a yielding hinge's
        # tangent): the arc starts from the unbalanced start instead, its iterations carry the
        # imbalance (and the step is halved if they cannot)
        logger.debug("the step's start did not balance (residual %.3g): the arc starts from it", norm)
        base[...] = 0.0
        problem.fext = fixed + self.load_factor * ref
        return self.load_factor, opts["max_iterations"]

    def predict(self, problem, rf, h, base):
        """The first step: along the start tangent's K^-1 f_ref. Later steps: along the last
        step's increment (u_prev, d_lambda_prev) scaled to the arc, the secant predictor: the
        start tangent of a yielding structure is the elastic one (a point on the yield surface
        with no increment yet is elastic), and its predictor overshoots the limit load by the
        whole elastic reserve; the secant follows the path through the limit point (its sign
        is the path's)."""
        self._weights(problem)
        if self.previous is not None and not self.retry:
            prev = problem.dofs.owned_values(self.previous).copy()
            prev[~problem.free] = 0.0
            length = math.sqrt(self.norm_dot(problem, prev, prev))
            if length > 0.0:
                self.dl = self.arc * h / self.time_step
                logger.debug("secant predictor: |u_prev| %.4g, d_lambda_prev %.4g, dl %.4g", length,
                             self.previous_dlam, self.dl)
                return self.previous_dlam * self.dl / length, prev * (self.dl / length)
        uF = tangent_direction(problem, rf, base)
        length = math.sqrt(self.norm_dot(problem, uF, uF))
        if length == 0.0 or not math.isfinite(length):
            raise NewtonFailed("arc length: the pattern moves nothing")
        if self.arc is None:
            self.arc0 = self.arc = self.options["load_factor_increment"] * length
        self.dl = self.arc * h / self.time_step
        # (a retry after a failed secant step: the tangent's direction, its sign the path's, the
        # sign of u_prev . W du_F; Feng et al.)
        sign = 1.0
        if self.previous is not None:
            prev = problem.dofs.owned_values(self.previous).copy()
            prev[~problem.free] = 0.0
            sign = -1.0 if self.norm_dot(problem, prev, uF) < 0.0 else 1.0
        return sign * self.dl / length, uF * (sign * self.dl / length)

    def correct(self, problem, u, uR, uF, h):
        dot = self.norm_dot
        base = u + uR
        a = dot(problem, uF, uF)
        b = 2.0 * dot(problem, uF, base)
        c = dot(problem, base, base) - self.dl ** 2
        disc = b * b - 4.0 * a * c
        logger.debug("arc length: |u| %.3g |u_R| %.3g |u_F| %.3g dl %.3g disc %.3g", math.sqrt(dot(problem, u, u)),
                     math.sqrt(dot(problem, uR, uR)), math.sqrt(a), self.dl, disc)
        if a == 0.0:
            raise NewtonFailed("arc length: the pattern moves nothing")
        if disc < 0.0:
            # no point of the correction's line on the arc: the out-of-balance force's correction
            # alone leaves it. Linearise the constraint instead (the plane normal to the current
            # increment u through its tip: u . W u_new = dl^2, Riks' plane; Crisfield's remedy
            # short of cutting the arc): the next iterations, from nearer equilibrium, meet the
            # arc again (or the step fails and is halved).
            self.missed += 1
            along = dot(problem, uF, u)
            if along != 0.0:
                return (self.dl ** 2 - dot(problem, base, u)) / along
            return -0.5 * b / a
        q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
        roots = (q / a, c / q) if q != 0.0 else (0.0, 0.0)
        # Crisfield's choice: the root whose new increment turns least from the current one
        # (the new increments have the same length, so the larger dot product)
        cosines = [dot(problem, u, base) + r * dot(problem, u, uF) for r in roots]
        return roots[int(np.argmax(cosines))]

    def adapt(self, iterations):
        factor = min(2.0, max(0.5, math.sqrt(self.options["target_iterations"] / max(iterations, 1))))
        self.arc = min(self.arc * factor, MAX_ARC_GROWTH * self.arc0)

    def _record(self, t, iterations):
        self.path.append((t, self.load_factor, iterations, math.nan if self.arc is None else self.arc))


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
