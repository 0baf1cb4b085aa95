"""Rayleigh damping given as a ratio of critical damping at two periods (effect
``rayleigh_damping``: this module is the whole plug-in, its kernels included).

``[loads] damping = {ratio = 0.02, periods = [T1, T2]}`` asks for the damping matrix
C = a0 M + a1 K that damps the modes of periods T1 and T2 at ``ratio``:

    xi(omega) = a0 / (2 omega) + a1 omega / 2,     omega_k = 2 pi / T_k,
    a0 = 2 xi omega1 omega2 / (omega1 + omega2),   a1 = 2 xi / (omega1 + omega2)

(Chopra, *Dynamics of Structures*, section 11.4). Modes between T1 and T2 are damped a little
less, modes outside a little (mass part, long periods) or much (stiffness part, short periods)
more.

How each part acts in the step:

- mass part: the nodal force -a0 m v of the plain mass-proportional damping (the grid update
  kernel, pmpm/core/kernels/grid_ops.py); its work is ``damping_work``;
- stiffness part: a viscous stress on every particle, sigma_v = a1 C : D (C the material's
  elastic tangent, D = de / dt the rate of deformation), added to the stress in the internal
  force (the kernels below); its work sum V sigma_v : de is ``viscous_damping_work``.
  The viscous stress of a step is the previous step's rate (an explicit step knows no other):
  its force and its work use the same value, so the energy balance closes with it.

The stiffness part lowers the stable time step. An explicit step on a mode of circular
frequency omega damped at xi is stable for dt <= (2 / omega) (sqrt(1 + xi^2) - xi) (Belytschko,
Liu & Moran, *Nonlinear Finite Elements*, section 6.2). The grid's highest mode is the one the
undamped CFL limit C_u stands for, omega_max = 2 c / (C_u h) (c the wave speed), and the viscous
stress damps it at xi_max = a1 omega_max / 2 = a1 c / (C_u h). The step is therefore
C h / c times ``stable_step_factor`` = min(1, C_u (sqrt(1 + xi_max^2) - xi_max)), with C_u the
undamped limits docs/accuracy.md measured on the bar (cubic 2.57, quadratic 2.31, linear 1.69,
point interpolation), taken about 3% lower; 1 for the domain interpolations (not measured).
Measured on the cantilever of tests/unit/test_damping.py (a1 c / h = 3.4, CFL 0.9): 1.1 times
the step this rule gives runs, 1.2 times diverges within 120 steps. A scene that damps a short
period on a fine grid pays for it in steps; docs/effects.md gives figures.

Under the implicit integrator (``RayleighImplicit``, docs/implicit.md) the damping is the matrix
term C v_{n+1} = a0 M v_{n+1} + a1 K_0 v_{n+1} of Newmark's equation of motion at the step's end:
the mass part on the nodes' lumped masses, the stiffness part as the viscous stress a1 C : d of
the end velocities' rate of deformation d (small strain on the step's start positions, C the
elastic matrix, as the explicit step's viscous stress), so K_0 is the elastic stiffness whatever
the material does. v_{n+1} is linear in the step's displacement increment u (dv / du = gamma /
(beta dt)), so the term adds gamma / (beta dt) C to the tangent, exactly. Its work over a step is
the trapezoid u . C (v_n + v_{n+1}) / 2, the rule's own energy balance. No stable-step limit.
With slaved edge nodes (``[solver.implicit] edge_mass_ratio``) C is the folded system's,
T^T (a1 K_0) T + a0 M with M the step's (folded) lumped masses (``RayleighImplicit._force``).
"""
import math

import numba as nb
import numpy as np

from pmpm.core.effects import Effect, register_energy
from pmpm.core.implicit import kernels as IK
from pmpm.core.implicit.terms import ImplicitTerm
from pmpm.physics.damping import DAMPING_WORK
from pmpm.physics.materials.linear_elastic import elastic_increment

__all__ = ["RayleighDamping", "rayleigh_coefficients", "ratio_at", "undamped_cfl_limit", "viscous_stress",
           "add_viscous"]

#: the stiffness part's dissipation (J)
VISCOUS_DAMPING_WORK = register_energy(
    "viscous_damping_work", "work done by the viscous stress of Rayleigh damping (its stiffness part), "
                            "dissipated")

#: the undamped CFL limits of docs/accuracy.md (bar, MUSL, point interpolation), about 3% lower
UNDAMPED_CFL_LIMIT = {"cubic": 2.5, "quadratic": 2.25, "linear": 1.65}


def undamped_cfl_limit(shape_function, interpolation):
    """C_u of the stable-step rule (module doc): measured for point interpolation, 1 else."""
    return UNDAMPED_CFL_LIMIT.get(shape_function, 1.0) if interpolation == "point" else 1.0


def rayleigh_coefficients(ratio, periods):
    """(a0 in 1/s, a1 in s) that damp the two ``periods`` (s) at ``ratio`` of critical.

    Parameters
    ----------
    ratio : float
        Damping ratio, 0 <= ratio <= 1.
    periods : pair of float
        T1, T2 > 0 (s); equal periods give the pair that damps that one period at ``ratio``
        with half of it from each part.
    """
    w1, w2 = (2 * math.pi / T for T in periods)
    return 2 * ratio * w1 * w2 / (w1 + w2), 2 * ratio / (w1 + w2)


def ratio_at(a0, a1, omega):
    """Damping ratio of a mode of circular frequency ``omega`` (rad/s): a0/(2 w) + a1 w/2."""
    return a0 / (2 * omega) + a1 * omega / 2


class RayleighDamping(Effect):
    """Rayleigh damping by ratio (effect ``rayleigh_damping``): its mass part is the nodal
    mass-proportional damping (``damping_work``), its stiffness part the viscous stress on the
    particles (``viscous_damping_work``) and a shorter stable step.

    Parameters
    ----------
    config : dict
        ``{"ratio": xi, "periods": (T1, T2)}`` from the scene (pmpm.scene.config).
    materials : list of pmpm.physics.materials.Material
    """

    #: the particle field holding the viscous stress (sxx, syy, sxy); it migrates and is
    #: checkpointed with the particle like any field
    FIELD = "viscous_stress"

    name = "rayleigh_damping"
    energy_terms = (DAMPING_WORK, VISCOUS_DAMPING_WORK)

    @classmethod
    def create(cls, scene, setup):
        config = scene.loads.rayleigh
        return cls(config, setup.materials, undamped_cfl_limit(setup.shape_function, setup.interpolation)) \
            if config else None

    def __init__(self, config, materials, undamped_limit=1.0):
        self.ratio = config["ratio"]
        self.periods = tuple(config["periods"])
        self.a0, self.a1 = rayleigh_coefficients(self.ratio, self.periods)
        self.materials = materials
        self.undamped_limit = undamped_limit
        self.nodal_damping = self.a0 or None   # None compiles the grid's damping out
        self.damping_work = 0.0          # this rank's share of the mass part's dissipation (J)
        self.viscous_damping_work = 0.0  # this rank's share of the stiffness part's (J)

    @property
    def work(self):
        """This rank's share of the stiffness part's dissipation (J)."""
        return self.viscous_damping_work

    @work.setter
    def work(self, value):
        self.viscous_damping_work = value

    @property
    def stiffness(self):
        """True if the stiffness part is not zero (ratio > 0)."""
        return self.a1 > 0

    def stable_step_factor(self, wave_speed, h, undamped_limit):
        """min(1, C_u (sqrt(1 + xi^2) - xi)), xi = a1 c / (C_u h): the CFL step's reduction
        (module doc); ``undamped_limit`` is C_u (``undamped_cfl_limit``)."""
        xi = self.a1 * wave_speed / (undamped_limit * h)
        return min(1.0, undamped_limit * (math.sqrt(1 + xi * xi) - xi))

    def add_fields(self, particles, setup=None):
        """Give the particles their viscous stress (zero at the start)."""
        particles.add_field(self.FIELD, (3,))

    def force_stress(self, stress, sv, out):
        """The stress the internal force takes: ``stress`` + ``sv`` into ``out`` (N, 3)."""
        add_viscous(stress, sv, out)
        return out

    def update(self, particles, de, dt):
        """After the step's strain increment ``de``: the viscous stress's work over the step
        (added to ``work``) and the new viscous stress (a1 / dt) C de."""
        p = particles
        several = len(self.materials) > 1
        for k, m in enumerate(self.materials):
            self.work += viscous_stress(p[self.FIELD], de, p["vol"], dt, self.a1, m.E, m.nu,
                                        m.plane_strain, p["mat"], k if several else -1)

    # -- effect hooks
    implicit_support = True

    def implicit_term(self, s):
        """The damping matrix in the implicit step (module doc)."""
        return RayleighImplicit(self, s.materials)

    #: the term's forces and tangent are folded onto slaved edge nodes (RayleighImplicit._force)
    implicit_term_folded = True

    def limit_dt(self, dt, speed, s):
        """The viscous stress shortens the stable step (module doc)."""
        return dt * self.stable_step_factor(speed, s.grid.h, self.undamped_limit)

    def edits_force_stress(self, t):
        return True

    def add_force_stress(self, s, out):
        """The viscous stress joins the stress of the internal force."""
        self.force_stress(out, s.particles[self.FIELD], out)

    def after_grid_update(self, s, damped_work):
        self.damping_work += damped_work

    def after_stress_update(self, s):
        self.update(s.particles, s._de, s._dt_step)

    def describe(self):
        """The start-up log's effect line."""
        T1, T2 = self.periods
        return [f"Rayleigh damping {self.ratio:g} of critical at T = {T1:g} s and {T2:g} s "
                f"(a0 = {self.a0:.4g} 1/s on the nodes, a1 = {self.a1:.4g} s viscous stress)"]


def elastic_matrices(materials, mat_ids, n):
    """(n, 3, 3): each particle's in-plane elastic matrix (engineering shear) of its material."""
    D = np.zeros((n, 3, 3))
    for k, m in enumerate(materials):
        E, nu = m.E, m.nu
        if m.plane_strain:
            lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
            a, b, g = lam + 2 * mu, lam, mu
        else:
            c = E / (1 - nu * nu)
            a, b, g = c, c * nu, 0.5 * c * (1 - nu)
        mine = mat_ids == k if len(materials) > 1 else slice(None)
        D[mine] = np.array([[a, b, 0.0], [b, a, 0.0], [0.0, 0.0, g]])
    return D


class RayleighImplicit(ImplicitTerm):
    """C = a0 M + a1 K_0 in the implicit step's residual and tangent (module doc)."""

    def __init__(self, effect, materials):
        self.effect, self.materials = effect, materials
        self.sv_start = self.sv = None

    def _velocity(self, problem, u):
        """v_{n+1} of the increment u (Newmark), on the window (the slaved edge nodes' values are
        ``_force``'s to extrapolate)."""
        rule = problem.rule
        return problem.v + rule.velocity_change(problem.a, rule.acceleration(u, problem.v, problem.a))

    def _force(self, problem, vel):
        """(-C vel on the nodes, halo-complete; the viscous stress a1 C : d(vel) of the particles).

        With slaved edge nodes (``edge_mass_ratio``, pmpm.core.implicit.edges) C is the folded
        system's, T^T (a1 K_0) T + a0 M: the particles read the expanded velocities T vel, their
        viscous forces are folded (T^T) before the halo sum as the internal force is
        (GridProblem.fold_and_sum), and the mass part is on the step's lumped masses, which
        are already the folded ones (the inertia's M: the row sums of the extended basis, a
        diagonal matrix; not T^T M T)."""
        s, e = problem.s, self.effect
        p = s.particles
        n = p.n
        # (Newmark's rule is linear node by node: T v_n+1 is the rule's of T u, T v_n and T a_n)
        vel = problem.expand(vel.copy())
        f, E = np.empty((n, 4)), np.empty((n, 3))
        IK.deformation_increment(problem.x, vel, *problem.geometry, f, E)
        rate = np.stack([f[:, 0] - 1.0, f[:, 3] - 1.0, f[:, 1] + f[:, 2]], axis=1)
        if self.D is None or len(self.D) != n:
            self.D = elastic_matrices(self.materials, p["mat"], n)
        sv = e.a1 * np.einsum("prs,ps->pr", self.D, rate)
        F = np.zeros(problem.mass.shape + (2,))
        IK.internal_force(problem.x, problem.vol, sv, self.identity(n), F, *problem.geometry)
        problem.fold_and_sum(F)
        F -= e.a0 * problem.mass[..., None] * vel   # (zero on the slaved nodes: no mass of their own)
        return F, sv

    def identity(self, n):
        out = np.zeros((n, 4))
        out[:, 0] = out[:, 3] = 1.0
        return out

    def begin(self, problem):
        """The damping force of the step's start velocities (HHT's start forces, Newmark's a_0)."""
        self.D = None
        self.blocks = None   # gamma / (beta dt) a1 K_0: the same at every iteration of the step
        if problem.v is None:
            return None
        F, self.sv_start = self._force(problem, problem.v)
        return F

    def add_residual(self, problem, u, R):
        if problem.rule is None:   # statics: no velocities
            return
        F, self.sv = self._force(problem, self._velocity(problem, u))
        R += F

    def add_tangent(self, problem, u, Kb):
        """gamma / (beta dt) (a0 M + a1 K_0): K_0 with the start positions' linear B."""
        rule = problem.rule
        if rule is None:
            return
        c = rule.gamma / (rule.beta * rule.dt)
        d, e = problem.dofs, self.effect
        centre = (d.span * d.span) // 2
        m = problem.mass[d.active]
        Kb[:, centre, 0, 0] += e.a0 * c * m
        Kb[:, centre, 1, 1] += e.a0 * c * m
        if self.blocks is None or self.blocks.shape != Kb.shape:   # once a step (K_0: start positions)
            n = problem.s.particles.n
            # (T^T K_0 T with slaved edge nodes: GridProblem.assemble)
            self.blocks = problem.assemble(np.zeros((n, 3)), self.identity(n), e.a1 * c * self.D)
        Kb += self.blocks

    def commit(self, s, problem, u):
        """The step's dissipation, u . C (v_n + v_{n+1}) / 2 (the rule's trapezoid), into the
        effect's energy terms; the particles keep the end's viscous stress (output)."""
        if problem.rule is None:
            return
        e = self.effect
        vel = self._velocity(problem, u)
        F, sv = self._force(problem, vel)
        own = problem.dofs.owned_active[..., None] & ~problem.dofs.held   # held rows: the supports' reaction
        e.damping_work += float(np.sum(np.where(own, e.a0 * problem.mass[..., None] * u * 0.5 * (problem.v + vel),
                                                0.0)))
        f = problem.f   # of the converged u (the commit evaluated it last)
        strain = np.stack([f[:, 0] - 1.0, f[:, 3] - 1.0, f[:, 1] + f[:, 2]], axis=1)
        e.viscous_damping_work += float(np.sum(problem.vol * np.einsum("pk,pk->p", 0.5 * (self.sv_start + sv),
                                                                       strain)))
        s.particles[RayleighDamping.FIELD][:] = sv


# -- the kernels (numba compiles them only for scenes that ask for Rayleigh damping;
# pmpm.core.kernels.reference.viscous_stress_reference is the NumPy twin, tests/unit/test_damping.py)
@nb.njit(cache=True)
def viscous_stress(sv, de, vol, dt, a1, E, nu, plane_strain, mat_ids, which):
    """Advance the viscous stress ``sv`` (N, 3: sxx, syy, sxy) to this step's rate and return
    the work it did over the step.

    The viscous stress that acted during the step (in its internal force) is the one of the
    previous step; its work is V sv_old : de, de the step's strain increment (engineering
    shear: the product is the stress power times dt). Then sv = (a1 / dt) C de. Particles
    of other materials (``which`` >= 0 and ``mat_ids`` != which) are skipped.

    Returns
    -------
    float
        sum of V sv_old : de over the particles visited (J): the energy the stiffness part of
        the damping dissipated in the step.
    """
    work = 0.0
    c = a1 / dt
    for p in range(sv.shape[0]):
        if which >= 0 and mat_ids[p] != which:
            continue
        work += vol[p] * (sv[p, 0] * de[p, 0] + sv[p, 1] * de[p, 1] + sv[p, 2] * de[p, 2])
        ds = elastic_increment(E, nu, plane_strain, de[p, 0], de[p, 1], de[p, 2])
        sv[p, 0] = c * ds[0]
        sv[p, 1] = c * ds[1]
        sv[p, 2] = c * ds[2]
    return work


@nb.njit(cache=True)
def add_viscous(stress, sv, out):
    """out[:, :3] = stress[:, :3] + sv: the stress the internal force sees."""
    for p in range(sv.shape[0]):
        out[p, 0] = stress[p, 0] + sv[p, 0]
        out[p, 1] = stress[p, 1] + sv[p, 1]
        out[p, 2] = stress[p, 2] + sv[p, 2]
