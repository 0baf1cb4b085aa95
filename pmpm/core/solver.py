"""The explicit MPM solver: the step's fixed phases over the parts of a run.

One step (paper section 3, steps 1-10) is the scheme's ordered list of phases, each a short
method here that calls one numba kernel or one exchange::

    reset_grid -> particles_to_grid -> exchange_halo -> update_grid -> grid_to_particles
    -> [MUSL: exchange_halo (re-map) -> grid_velocity] -> update_strain -> update_stress
    -> migrate -> next time step

The optional physics a scene names (loads, ground motion, damping, supports, events, ...) are
effects (pmpm.core.effects): the phases call their hooks at fixed places, and know none of them
by name. The solver is built from a scene by pmpm.build.build_solver and holds no scene.

The serial run is the one-rank case of the same code: the halo exchange and the migration are
no-ops there, nothing else changes.

Where the ranks wait for each other (docs/performance.md, "Synchronisation points"): each
halo exchange is one round with the neighbours (``SlabDecomposition.sum_halo``: the ghost sums
and the owners' totals in one message each way), and the step's end is one reduction of the
next time step's speed and every rank's troubles, which carries the energy check's sums on the
steps that check (``_check_and_next_dt``). A MUSL step on several ranks: two halo rounds and
one reduction.
"""
import logging
import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from decomposition import alltoallv_fields, wait_all
from pmpm.core import kernels as K
from pmpm.core.effects import EffectList, energy_terms
from pmpm.core.fields import GridFields
from pmpm.core.grid import GridWindow, choose_tile
from pmpm.core.material_groups import same_elastic_energy, single_law
from pmpm.core.shape import CPDI_REACH, MAX_HALF_LENGTH, ghost_width, shape_argument
from pmpm.core.step import SchemeContext
from pmpm.core.transfers import StepContext
from pmpm.errors import ParticleExitError, UnstableRunError

__all__ = ["Solver", "StepOptions", "numerical_loss"]
logger = logging.getLogger(__name__)

#: steps between energy checks (each is one pass over the particles and one allreduce)
ENERGY_CHECK_INTERVAL = 10
#: energy above (initial + external work) that counts as divergence, relative to the energies
#: in play: healthy runs stay within a few percent (tests show < 5%), diverging ones explode
ENERGY_GROWTH_LIMIT = 0.5


def numerical_loss(initial, external, kinetic, strain, *held):
    """The energy lost to the discretisation (J): what the loads and the initial state put in
    and no physical term holds, dissipated or took out of the run,
    ``initial + external - kinetic - strain - sum(held)``.

    ``initial`` is the energy at the start (``Solver.initial_energy``: the kinetic energy, the
    bodies start unstressed). Positive: energy lost (numerical damping of the transfers and
    the time integration); negative: energy gained. The stress power integrated over the
    steps (``internal_work``) is not used: the strain energy of the current stresses is what
    the body can give back, so a loss between the two shows here too.

    Parameters
    ----------
    initial, external, kinetic, strain : float or numpy.ndarray
        The energies in J, as ``Solver.energies`` names them.
    *held : float or numpy.ndarray
        Every registered energy term (pmpm.core.effects): what the materials dissipated
        (plastic work) and what the effects took out (damping works, energy an event removed).
    """
    loss = initial + external - kinetic - strain
    for term in held:
        loss = loss - term
    return loss


@dataclass(frozen=True)
class StepOptions:
    """The settings the step reads (the scene's ``[solver]`` and ``[parallel]``, resolved by
    pmpm.build): basis, time step rule, end time, sorting, rebalancing and exits."""

    shape_function: str = "cubic"
    interpolation: str = "point"
    end_time: float = 1.0
    cfl: float = 0.5
    time_step: float = None
    sort_interval: int = 0
    on_particle_exit: str = "error"
    objective_rate: str = "jaumann"
    plane_stress: bool = True
    rebalance_threshold: float = None
    rebalance_interval: int = 1


class Solver:
    """Explicit MPM on the ranks of ``decomp``: the step's fixed phases over the parts a run is
    built from (pmpm.build.build_solver builds them from a scene).

    Parameters
    ----------
    grid : pmpm.core.grid.Grid
    decomp : decomposition.SlabDecomposition
        Also the communicator (``decomp.comm``) and the slab axis.
    particles : pmpm.core.particles.Particles
        This rank's particles, every field the run keeps already there.
    materials : list of pmpm.physics.materials.Material
    scheme, transfer : the strategies of pmpm.core.schemes and pmpm.core.transfers
    effects : iterable of pmpm.core.effects.Effect
        The effects the scene names (pmpm.core.effects), in registry order.
    options : StepOptions
    n_total : int
        Particles of the whole run (the ids are 0 .. n_total - 1).
    mass_cutoff : float
        The scene's relative nodal mass cutoff (times the largest particle mass here).
    keeps_F, rotates_stress : bool
        Whether the particles keep F, and whether the objective rate rotates the stresses.
    grid_fields : pmpm.core.fields.GridFields, optional
        The grid's velocity fields (default one shared field; contact: one per body).
    """

    def __init__(self, grid, decomp, particles, materials, scheme, transfer, effects, options, n_total,
                 mass_cutoff=0.0, keeps_F=False, rotates_stress=False, grid_fields=None):
        self.grid, self.decomp, self.particles = grid, decomp, particles
        self.grid_fields = grid_fields if grid_fields is not None else GridFields()
        self.comm = decomp.comm
        self.axis = decomp.axis
        self.materials = materials
        # materials of one law (copies of a steel that differ in density only) are updated, and
        # their energy summed, in one pass over the particles instead of one per material
        self._stress_passes = ([(materials[0], -1)] if single_law(materials) else
                               [(m, k if len(materials) > 1 else -1) for k, m in enumerate(materials)])
        self._one_energy_sum = same_elastic_energy(materials)
        self.scheme, self.transfer = scheme, transfer
        self.options = options
        self.interpolation = options.interpolation
        self.n_total = n_total
        self.keeps_F, self.rotates_stress = keeps_F, rotates_stress
        self.set_effects(effects)
        # CPDI: the kernels count corners whose support leaves the window here ([count, first
        # particle]); read and reset after every step (``_check_and_next_dt``)
        self._corner_escape = np.array([0, -1], dtype=np.int64)
        # a G2P with the step's later particle passes folded in (``grid_to_particles(tail=
        # True)``) leaves here the first half of the internal work and the strays it counted,
        # which update_stress and the step-end check then take instead of their own passes
        self._power_before = None
        self._strays = None
        # ... and, where it applied the materials' stress update too (``_stress_map``), the
        # second half of the internal work: update_stress then only adds the two halves
        self._power_after = None
        self._stress_map = self._point_stress_map()
        self._build_window()
        self.wave_speed = max(m.wave_speed() for m in self.materials)
        self.mass_cutoff = mass_cutoff * self.decomp.allreduce_max(
            float(self.particles["m"].max()) if self.particles.n else 0.0)
        self.t = 0.0
        self.step_count = 0
        self.external_work = 0.0   # this rank's share; summed when reported
        self.internal_work = 0.0   # likewise: sum of V sigma : d_eps over this rank's particles
        self.removed = 0
        self.rebalances = 0
        self.vmax = self.decomp.allreduce_max(self._local_speed())
        self.dt = self.stable_dt(self.vmax)
        self._vmax_healthy = self.vmax
        self.healthy_step = -1  # step count of the newest state that passed check_energy
        self.initial_energy = self.energies()["total"]

    def set_effects(self, effects):
        """Run with ``effects`` (pmpm.core.effects) from now on: their hooks and the kernels'
        body acceleration and nodal damping (tests switch one off to compare)."""
        self.effects = effects if isinstance(effects, EffectList) else EffectList(effects)
        self.gravity = self.effects.body_acceleration    # None compiles gravity out
        self.damping = self.effects.nodal_damping        # None compiles the damping out
        self._hooks = self.effects.hooks

    def effect(self, name):
        """The run's effect registered as ``name`` (pmpm.core.effects), or None."""
        return self.effects.get(name)

    # -- set-up helpers ---------------------------------------------------------------------
    def _build_window(self):
        cfg = self.options
        self.window = GridWindow(self.grid, self.axis, self.decomp.window,
                                 reach=ghost_width(cfg.shape_function, cfg.interpolation),
                                 halo=self._halo_columns())
        # CPDI: a corner may lie further from its particle than ghost_width says on one rank
        # (only a slab boundary stops such a run), so no tile marking can bound its support
        if cfg.interpolation != "cpdi":
            self.window.use_tiles(choose_tile(self.window.G.shape[0] * self.window.G.shape[1],
                                              self.particles.n))
        else:
            self.window.use_tiles(0)
        w0 = self.decomp.window[0]
        self._owned_local = np.array([self.axis, self.decomp.owned[0] - w0, self.decomp.owned[1] - w0])
        self.grid_fields.on_window(self)
        for bind in self._hooks["on_window"]:   # boundary masks, reactions, driven nodes
            bind(self)

    def _halo_columns(self):
        """Window columns at the lower and upper end that the halo exchange reads or writes:
        the ghost columns and the owned ones a neighbour holds as its ghosts (none without a
        neighbour)."""
        d = self.decomp
        (n0, n1), (w0, w1), g = d.owned, d.window, d.ghost
        lower = min(n0 + g, w1) - w0 if d.lower != MPI.PROC_NULL else 0
        upper = w1 - max(n1 - g, w0) if d.upper != MPI.PROC_NULL else 0
        return lower, upper

    @property
    def shape(self):
        """The ``shape`` argument of the transfer kernels: the point B-spline tag, or the GIMP
        pair (tag, the particles' current domain array: rebuilt since sorting and migration
        replace the arrays), or the CPDI tuple (tag, domain, F, the step's corner report)."""
        f = self.particles.fields
        return shape_argument(self.options.shape_function, self.interpolation,
                              f.get("domain"), f.get("F"), self._corner_escape)

    def _local_speed(self):
        v = self.particles["v"]
        return float(np.sqrt((v * v).sum(axis=1)).max()) if len(v) else 0.0

    def stable_dt(self, vmax):
        """CFL time step C h / (c + |v|max) (shortened by the effects that damp the highest
        modes), or the scene's fixed step."""
        if self.options.time_step is not None:
            return self.options.time_step
        dt = self.options.cfl * self.grid.h / (self.wave_speed + vmax)
        for limit in self._hooks["limit_dt"]:
            dt = limit(dt, self.wave_speed + vmax, self)
        return dt

    def critical_dt(self):
        """The largest stable step by the CFL rule with C = 1 (for warnings and messages), with
        the particle speed at the last energy check that passed (a diverging run's speed means
        nothing)."""
        return self.grid.h / (self.wave_speed + self._vmax_healthy)

    # -- arguments shared by the transfer kernels --------------------------------------------
    def _geometry(self):
        w, g = self.window, self.grid
        return (w.G, w.ox, w.oy, g.origin, g.inv_h, g.cells[0], g.cells[1], self.shape)

    @property
    def geometry(self):
        """The transfer kernels' grid arguments (G, ox, oy, origin, inv_h, ncx, ncy, shape)."""
        return self._geometry()

    @property
    def owned_local(self):
        """The owned node range of the window: (slab axis, first, end) in window indices."""
        return self._owned_local

    def _step_context(self, forces=False, kinematics=None, tail=None, impulse=False):
        """What the transfer sees of this step (pmpm.core.transfers.StepContext): the force
        pass's stress and body acceleration when ``forces``; the strain outputs
        (``kinematics``) when the transfer gathers the strain in its velocity pass; ``tail``
        (``tail_arguments()``) when it folds the step's later particle passes in too;
        ``impulse`` when the force pass scatters the force's impulse with the momentum."""
        return StepContext(self.particles, self.window, self._geometry(), self.decomp.sum_halo,
                           self.force_stress() if forces else None, self.gravity if forces else None,
                           getattr(self, "_dx", None), getattr(self, "_dt_step", 0.0), kinematics, tail,
                           impulse)

    def _scratch(self, name, shape):
        arr = getattr(self, name, None)
        if arr is None or arr.shape != shape:
            arr = np.empty(shape)
            setattr(self, name, arr)
        return arr

    def scratch(self, name, shape):
        """A float array of ``shape`` kept between steps under ``name`` (a scheme's buffers)."""
        return self._scratch("_scheme_" + name, shape)

    def new_moves(self):
        """The particles' moves of this step (N, 2), filled by grid-to-particles."""
        self._dx = self._scratch("_dx_buf", (self.particles.n, 2))
        return self._dx

    def report_speed(self, vmax, bad):
        """This rank's largest particle speed and count of non-finite particles after the
        velocity update, reduced at the step's end (``_check_and_next_dt``)."""
        self._vmax_local, self._bad_local = vmax, bad

    # -- the phases (the grid's share is the run's grid fields: pmpm.core.fields) --------------
    def reset_grid(self):
        """Step 1: zero the rank's grid window and choose the tiles this step's node passes visit."""
        self.grid_fields.reset_grid(self)

    def particles_to_grid(self, momentum, forces, impulse=False):
        """Steps 4-6 / eq. 2: mass and momentum and/or internal and external forces (with
        ``impulse``, only where ``impulse_fusable``: the force's impulse dt f scattered with the
        momentum where the transfer can; the grid update's (m v + dt f) / m is the same sum)."""
        if impulse:
            self.grid_fields.particles_to_grid(self, momentum, forces, impulse=True)
        else:
            self.grid_fields.particles_to_grid(self, momentum, forces)

    @property
    def impulse_fusable(self):
        """Whether the force pass may scatter the force's impulse with the momentum: the grid
        update needs the momentum apart from the force for nothing else (no nodal damping, no
        hook after the grid update reading its velocity change: supports, damping works), and
        the grid fields are the default one."""
        return (self.damping is None and not self._hooks["after_grid_update"]
                and self.grid_fields.scene_key is None)

    def force_stress(self):
        """The stress whose divergence is the internal force: the particles' stress as the
        effects edit it (the viscous stress of Rayleigh damping added, the rows of a body being
        removed scaled down: pmpm.physics), in registry order. Without an effect editing it
        this step, the stress array itself."""
        p = self.particles
        editors = [e for e in self.effects.stress_editors if e.edits_force_stress(self.t)]
        if not editors:
            return p["stress"]
        out = self._scratch("_force_stress_buf", (p.n, 3))
        out[...] = p["stress"][:, :3]
        for effect in editors:
            effect.add_force_stress(self, out)
        return out

    def exchange_halo(self, fields):
        """HALO: the contributions of every rank summed (one round with each neighbour)."""
        self.grid_fields.exchange_halo(self, fields)

    def update_grid(self, dt):
        """Steps 7-8 / eq. 3-4: the momentum update with the essential BCs."""
        self.grid_fields.update_grid(self, dt)

    def grid_velocity(self, source, target):
        """v = (mv)/m with BCs, e.g. of the MUSL re-mapped momentum (eq. 6)."""
        self.grid_fields.grid_velocity(self, source, target)

    def grid_to_particles(self, remap, strain=False, tail=False):
        """Step 9 / eq. 5: particle velocities (and MUSL's re-map of their momenta; with
        ``strain``, the strain increment, volume and F of a transfer that gathers them in the
        same pass; with ``tail`` (only where ``tail_fusable``), also the move, the step-end
        count of strays and the first half of the internal work: no move_particles then)."""
        if tail:
            self.grid_fields.grid_to_particles(self, remap, strain=True, tail=True)
        elif strain:
            self.grid_fields.grid_to_particles(self, remap, strain=True)
        else:
            self.grid_fields.grid_to_particles(self, remap)

    @property
    def tail_fusable(self):
        """Whether the step's particle passes after the G2P (the move, the first half of the
        internal work, the strays count) may run inside it: nothing of the run acts on the
        particles' velocities between the G2P and the move (no ``after_g2p`` hook: held
        particles), and the grid fields are the default one (contact's have their own G2P)."""
        return not self._hooks["after_g2p"] and self.grid_fields.scene_key is None

    def tail_arguments(self):
        """What a G2P with the step's later passes folded in needs: (m, body acceleration,
        the stress for the first half of the internal work (None when the stress is rotated
        first: the solver's pass takes it then), the owned cell columns (axis, c0, c1), the
        materials' stress update as one linear map (``_point_stress_map``; None: update_stress
        runs the materials), whether anything reads the moves ``_dx`` after the pass (point
        loads' work: the ``after_move`` hooks), whether anything reads the increments ``_de``
        after it (the materials' update, ``after_stress_update`` hooks)). Arrays nothing reads
        are not written (pmpm.core.kernels.mls.g2p_mls)."""
        c0, c1 = self.decomp.owned
        return (self.particles["m"], self.gravity, None if self.rotates_stress else self.particles["stress"],
                (self.axis, c0, min(c1, self.grid.cells[self.axis])), self._stress_map,
                bool(self._hooks["after_move"]),
                self._stress_map is None or bool(self._hooks["after_stress_update"]))

    def take_tail(self, work, power, outside, leaving, inverted, power_after=0.0):
        """The results of a G2P with the later passes folded in: the body force's work over the
        moves, the first half of the internal work (kept for update_stress when it was taken),
        the strays (kept for the step-end check) and, where the G2P updated the stress
        (``_stress_map``), the second half."""
        self.external_work += work
        self._power_before = None if self.rotates_stress else power
        self._power_after = None if self._stress_map is None else power_after
        self._strays = (outside, leaving, inverted)
        self._work_of_moves()

    def _point_stress_map(self):
        """The materials' stress update as one linear map a G2P may apply per particle in its
        own pass (the 12 entries of Material.increment_matrix row by row), or None: the update
        is one pass of one material over every particle (one law), whose model hands such a map
        (linear elasticity), with nothing between the G2P and the update (no objective rate
        rotating the stress first, no plane-stress thickness of a run keeping F, no state)."""
        if len(self._stress_passes) != 1 or self.rotates_stress or (self.keeps_F and self.options.plane_stress):
            return None
        material, which = self._stress_passes[0]
        if which != -1 or material.state_fields or material.tensor_state_fields:
            return None
        D = material.increment_matrix()
        return None if D is None else tuple(float(d) for d in D.ravel())

    def _kinematics_outputs(self):
        """Arrays the kinematics kernels fill or advance this step, None where the scene does
        not ask for them: (de, dw, F, vol0, dq). ``dw`` is the spin increment (Jaumann),
        ``dq`` the cosine and sine of the change of the polar angle of F (Green-Naghdi)."""
        p, cfg = self.particles, self.options
        de = self._scratch("_de", (p.n, 3))
        dw = dq = None
        if self.rotates_stress:
            if cfg.objective_rate == "green_naghdi":
                dq = self._scratch("_dq_buf", (p.n, 2))
            else:
                dw = self._scratch("_dw_buf", (p.n,))
        self._de, self._dw, self._dq = de, dw, dq
        return de, dw, p.fields.get("F"), p.fields.get("vol0"), dq

    def update_strain(self, dt, velocity_field, move=True):
        """Step 10 / eq. 6: strain increment, volume (and F) update, and (``move``) positions."""
        self.grid_fields.update_strain(self, dt, velocity_field, move)

    def _stretch_domains(self, de):
        """cpGIMP: each half-length follows the material's stretch along its axis, l *= 1 + de_ii
        (the diagonal of the step's I + dt L), capped at ``MAX_HALF_LENGTH`` (the 5-node support)."""
        d = self.particles["domain"]
        d *= 1.0 + de[:, :2]
        np.clip(d, 1e-6, MAX_HALF_LENGTH, out=d)

    def move_particles(self, dt):
        """Position update x += dt sum N v_i (USF: after the stress update)."""
        self.grid_fields.move_particles(self, dt)

    def _work_of_moves(self):
        """Work of the effects' forces over this step's moves (point loads)."""
        for after in self._hooks["after_move"]:
            after(self)

    def update_stress(self):
        """Stress increments through each material's tangent (eq. 6 / eq. 15)."""
        p = self.particles
        if self._power_after is not None:   # the G2P applied the update (``_stress_map``)
            self.internal_work += 0.5 * self._power_before
            self.internal_work += 0.5 * self._power_after
            self._power_before = self._power_after = None
            for after_update in self._hooks["after_stress_update"]:
                after_update(self)
            return
        self._rotate(p["stress"])
        # internal work by the trapezoid rule, half before and half after the update; it closes
        # the energy balance exactly where 1/2 sigma : C^-1 : sigma (hypoelastic) does not
        before, self._power_before = self._power_before, None   # taken in the G2P's pass?
        if before is None:
            before = K.stress_power(p["stress"], self._de, p["vol"])
        self.internal_work += 0.5 * before
        thickness = self.keeps_F and self.options.plane_stress
        # the tensor state fields (back stress) are shared by the materials: rotated once
        for name in dict.fromkeys(n for m in self.materials for n in m.tensor_state_fields):
            self._rotate(p[name])
        # the second half in the updates' own passes where every material sums it there (each
        # pass sums the particles it updates: together all of them)
        summed = not thickness and all(material.sums_power for material, _ in self._stress_passes)
        power_after = 0.0
        for material, which in self._stress_passes:
            if thickness and not material.needs_deformation_gradient:
                trace_before = self._scratch("_trace_buf", (p.n,))
                K.in_plane_trace(p["stress"], trace_before)
            state = {name: p.fields.get(name) for name in material.state_fields}
            if material.needs_deformation_gradient:
                state["F"] = p["F"]
            if summed:
                power_after += material.update_stress_power(p["stress"], self._de, p["vol"], state, p["mat"], which)
            else:
                material.update_stress(p["stress"], self._de, state, p["mat"], which)
            if thickness and not material.needs_deformation_gradient:
                # F33 from szz = 0 (the hyperelastic models solve it themselves)
                K.advance_thickness_stretch(p["F"], self._de, p["stress"], trace_before,
                                            material.E, material.nu, p["mat"], which)
        if not summed:
            power_after = K.stress_power(p["stress"], self._de, p["vol"])
        self.internal_work += 0.5 * power_after
        for after in self._hooks["after_stress_update"]:   # viscous stress, fading bodies
            after(self)

    def _rotate(self, t):
        """Rotate the Voigt tensors ``t`` by this step's objective rate (if large rotations)."""
        if self._dw is not None:
            K.jaumann_rotate(t, self._dw)
        elif self._dq is not None:
            K.rotate(t, self._dq)

    # -- after the phases ---------------------------------------------------------------------
    def _check_and_next_dt(self, energy_due=False):
        """One rendezvous of the ranks: the next time step's speed (max over ranks) and every
        rank's troubles, and (``energy_due``) the energy check's sums in the same wait.
        Returns (bad, outside, leaving, summed energies or None)."""
        g, d = self.grid, self.decomp
        c0, c1 = d.owned
        if self._strays is not None:   # counted in the G2P's pass, after the move
            (outside, leaving, inverted), self._strays = self._strays, None
        else:
            outside, leaving, inverted = K.count_strays(
                self.particles["x"], self.particles["vol"], g.origin, g.inv_h, g.cells[0], g.cells[1],
                self.axis, c0, min(c1, g.cells[self.axis]))
        vmax = self._vmax_local if math.isfinite(self._vmax_local) else math.inf
        bad = self._bad_local + inverted + (0 if math.isfinite(vmax) else 1)
        bad_F, self._first_bad_F = K.check_deformation(self.particles["F"]) if self.keeps_F else (0, -1)
        escaped, self._first_escaped = int(self._corner_escape[0]), int(self._corner_escape[1])
        self._corner_escape[:] = (0, -1)
        sums = d.start_allreduce(self.local_energies(), MPI.SUM) if energy_due else None
        flags = d.start_allreduce(np.array([vmax, bad, outside, leaving, bad_F, escaped], dtype=np.float64))
        wait_all(flags.requests + (sums.requests if sums is not None else []))
        flags = flags.result()
        self.vmax = flags[0]
        if flags[4]:
            raise UnstableRunError(self._bad_F_report())
        if flags[5]:
            raise UnstableRunError(self._escaped_corner_report())
        return int(flags[1]), int(flags[2]), int(flags[3]), (sums.result() if sums is not None else None)

    def _bad_F_report(self):
        """The message of a deformation gradient that turned singular, inverted or non-finite:
        the first such particle of every rank, gathered (every rank raises the same text)."""
        p, k = self.particles, self._first_bad_F
        row = None
        if k >= 0:
            F = p["F"][k]
            det = (F[0] * F[3] - F[1] * F[2]) * F[4]
            row = (int(p["id"][k]), float(p["x"][k, 0]), float(p["x"][k, 1]), float(det))
        rows = [r for r in self.comm.allgather(row) if r is not None]
        i, x, y, det = min(rows)
        return (f"the deformation gradient of particle id {i} at ({x:.4g}, {y:.4g}) is inverted or "
                f"not finite (det F = {det:.4g}) at t = {self.t + self._dt_step:.6g} s "
                f"(step {self.step_count + 1}, dt = {self._dt_step:.3g} s; the stable step is about "
                f"{self.critical_dt():.3g} s)")

    def _escaped_corner_report(self):
        """The message of a CPDI particle domain reaching beyond its slab's grid window (the
        ghost width, pmpm.core.shape.ghost_width): the first such particle of every rank."""
        p, k = self.particles, self._first_escaped
        row = (int(p["id"][k]), float(p["x"][k, 0]), float(p["x"][k, 1])) if k >= 0 else None
        rows = [r for r in self.comm.allgather(row) if r is not None]
        i, x, y = min(rows)
        return (f"the CPDI domain of particle id {i} at ({x:.4g}, {y:.4g}) reaches beyond its slab's "
                f"ghost nodes at t = {self.t + self._dt_step:.6g} s (step {self.step_count + 1}): the "
                f"particle is stretched more than {CPDI_REACH} cells across a slab boundary; run on "
                f"fewer ranks, or with more particles per cell (smaller domains)")

    def migrate(self, leaving):
        """Step 11: particles that left the slab move to the neighbour with all their state."""
        if leaving == 0:
            return
        p = self.particles
        cols = K.cell_columns(p["x"], self.grid.origin, self.grid.inv_h, self.axis)
        self.particles.fields = self.decomp.migrate(p.fields, self.decomp.owner_of_columns(cols))

    def remove_outside(self):
        """Drop particles that left the grid (scene: on_particle_exit = "remove")."""
        keep = self.grid.inside(self.particles["x"])
        self.removed += int(self.decomp.allreduce_sum(int((~keep).sum())))
        self.particles = self.particles.take(keep)

    def held_energy(self, part):
        """The strain energy and the material energy terms (plastic work, ...) that the
        particles ``part`` (a Particles selection) hold: what leaves the internal work with
        them (pmpm.physics.events)."""
        held = self._strain_energy(part)
        for term in energy_terms():
            if not term.outside and term.name in part:
                held += float(np.sum(part[term.name] * part["vol"]))
        return held

    def outside_report(self, limit=5):
        """'id (x, y)' of particles outside the grid, from every rank (rank 0 gets the text)."""
        p = self.particles
        out = ~self.grid.inside(p["x"])
        rows = [(int(i), float(x[0]), float(x[1])) for i, x in zip(p["id"][out][:limit], p["x"][out][:limit])]
        rows = sum(self.comm.allgather(rows), [])[:limit]
        return ", ".join(f"id {i} at ({x:.4g}, {y:.4g})" for i, x, y in rows)

    def sort_particles(self):
        """Order particles by cell so that neighbours in memory share grid nodes."""
        w, g = self.window, self.grid
        order = K.cell_order(self.particles["x"], g.origin, g.inv_h, w.ox, w.ox + w.shape[0],
                             w.oy, w.oy + w.shape[1])
        self.particles.reorder(order)

    def rebalance(self):
        """Move slab boundaries by the particle count per column if the imbalance is too big."""
        threshold = self.options.rebalance_threshold
        if threshold is None or self.decomp.size == 1:
            return False
        if self.decomp.imbalance(self.particles.n) <= threshold:
            return False
        cols = K.cell_columns(self.particles["x"], self.grid.origin, self.grid.inv_h, self.axis)
        weights = np.bincount(cols, minlength=self.grid.nodes[self.axis]).astype(np.float64)
        if not self.decomp.rebalance(self.decomp.allreduce_sum(weights)):
            return False
        dest = self.decomp.owner_of_columns(cols)
        self.particles.fields = alltoallv_fields(self.comm, self.particles.fields, dest)
        self._build_window()
        self.rebalances += 1
        return True

    # -- one step ---------------------------------------------------------------------------
    def step(self):
        """Advance one time step; raises on instability or particles leaving the grid."""
        cfg = self.options
        if cfg.sort_interval and self.step_count % cfg.sort_interval == 0:
            self.sort_particles()
        dt = self.dt
        remaining = cfg.end_time - self.t
        if 0 < remaining < dt:  # land on the end time exactly
            dt = remaining
        self._dt_step = dt
        self._power_before = self._power_after = self._strays = None   # (nothing of a step cut short carries over)
        self.scheme.advance(SchemeContext(self, dt))
        energy_due = (self.step_count + 1) % ENERGY_CHECK_INTERVAL == 0
        bad, outside, leaving, sums = self._check_and_next_dt(energy_due)
        if bad:
            raise UnstableRunError(f"non-finite velocity or inverted volume at t = {self.t + dt:.6g} s "
                                   f"(step {self.step_count + 1}, dt = {dt:.3g} s; the stable step is "
                                   f"about {self.critical_dt():.3g} s)")
        if outside or energy_due:
            self.check_energy(dt, summed=sums)
        if outside:
            if cfg.on_particle_exit == "error":
                raise ParticleExitError(f"{outside} particle(s) left the grid at t = {self.t + dt:.6g} s: "
                                        f"{self.outside_report()}")
            self.remove_outside()
        self.migrate(leaving)
        self.t += dt
        self.step_count += 1
        for after in self._hooks["after_step"]:   # bodies an event removes
            after(self)
        if self.step_count % cfg.rebalance_interval == 0:
            self.rebalance()
        self.dt = self.stable_dt(self.vmax)
        return dt

    def check_energy(self, dt, pending=True, summed=None):
        """Stop a run whose energy grows beyond what the loads put in (a diverging run grows
        exponentially; a healthy one stays within a few percent). ``pending``: called inside
        a step of ``dt`` not yet counted (else on the state at ``self.t``). ``summed``: the
        energies' sums over the ranks already reduced (``local_energies``), else reduced here."""
        t_now, step_now = (self.t + dt, self.step_count + 1) if pending else (self.t, self.step_count)
        e = self.energies(summed)
        supplied = self.initial_energy + e["external_work"]
        scale = abs(self.initial_energy) + abs(e["external_work"]) + abs(e["internal_work"])
        # kinetic energy alone as well: a diverging run can turn volumes (and the internal work
        # integrated over them) negative, which hides the growth in the total
        grown = max(e["total"], e["kinetic"]) - supplied
        if not math.isfinite(grown) or (grown > ENERGY_GROWTH_LIMIT * scale and scale > 0):
            raise UnstableRunError(
                f"the run diverged at t = {t_now:.6g} s (step {step_now}): energy "
                f"{e['total']:.4g} J exceeds the initial energy plus external work {supplied:.4g} J; "
                f"dt = {dt:.3g} s, the stable step is about {self.critical_dt():.3g} s")
        self._vmax_healthy = self.vmax
        self.healthy_step = step_now

    def check_health(self):
        """Collective: raise UnstableRunError unless every particle value is finite and the
        energy is bounded now (what a checkpoint or the last good state must satisfy)."""
        p = self.particles
        bad = any(not np.all(np.isfinite(a)) for a in p.fields.values() if a.dtype.kind == "f")
        if self.decomp.allreduce_max(float(bad)):
            raise UnstableRunError(f"non-finite particle values at t = {self.t:.6g} s (step "
                                   f"{self.step_count}, dt = {self.dt:.3g} s; the stable step is "
                                   f"about {self.critical_dt():.3g} s)")
        self.check_energy(self.dt, pending=False)

    # -- reporting ----------------------------------------------------------------------------
    def energies(self, summed=None):
        """Global energies (J): kinetic, recoverable strain (1/2 sigma : C^-1 : sigma V, or the
        stored energy W(F) of a hyperelastic model), internal work (integrated stress power:
        strain + dissipation, exact for any material), external work, every registered energy
        term (pmpm.core.effects: the plastic work, the damping works, the energy removed
        particles carried out, ...), ``total`` = kinetic + internal work + the terms done
        outside it, which equals the external work plus the initial energy when the run
        conserves energy, and ``numerical_loss``. ``summed``: ``local_energies()`` already
        summed over the ranks (by a reduction shared with other figures), else summed here
        (collective)."""
        if summed is None:
            summed = self.decomp.allreduce_sum(self.local_energies())
        ke, se, wi, we = summed[:4]
        terms = energy_terms()
        values = dict(zip((t.name for t in terms), summed[4:]))
        total = ke + wi
        for t in terms:
            if t.outside:
                total += values[t.name]
        e0 = getattr(self, "initial_energy", total)   # at construction: this very state
        return {"kinetic": ke, "strain": se, "internal_work": wi, "external_work": we, **values,
                "total": total, "numerical_loss": numerical_loss(e0, we, ke, se, *values.values())}

    def local_energies(self):
        """This rank's shares of the energies, in the order ``energies`` reads them: kinetic,
        strain, internal work, external work, then the registered energy terms (a material's
        from its per-particle field integrated over the volume, an effect's from its own
        accumulator)."""
        p = self.particles
        kinetic = K.kinetic_energy(p["m"], p["v"])
        terms = [self.effects.energy(t.name) if t.outside else
                 (float(np.sum(p[t.name] * p["vol"])) if t.name in p else 0.0) for t in energy_terms()]
        return np.array([kinetic, self._strain_energy(p), self.internal_work, self.external_work, *terms])

    def _strain_energy(self, p):
        """The stored energy of particles ``p``: hyperelastic models know W(F); the others' is
        the recoverable 1/2 sigma : C^-1 : sigma."""
        if self._one_energy_sum:   # one E and nu: one sum over every particle
            m = self.materials[0]
            return K.elastic_energy(p["stress"], p["vol"], m.E, m.nu, p["mat"], -1)
        several = len(self.materials) > 1
        return sum(m.strain_energy(p["F"], p["vol0"], p["mat"], k if several else -1)
                   if m.needs_deformation_gradient else
                   K.elastic_energy(p["stress"], p["vol"], m.E, m.nu, p["mat"], k if several else -1)
                   for k, m in enumerate(self.materials))
