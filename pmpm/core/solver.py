"""The explicit MPM solver: owns the grid window, particles, materials, scheme and loads.

One step (paper section 3, steps 1-10) is the scheme's ordered list of phases, each a short
method here that calls one numba kernel or one exchange::

    reset_grid -> particles_to_grid -> exchange_halo -> update_grid -> grid_to_particles
    -> [MUSL: exchange_halo (re-map) -> grid_velocity] -> update_strain -> update_stress
    -> migrate -> next time step

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
import time

import numpy as np
from mpi4py import MPI

from decomposition import alltoallv_fields, get_comm, wait_all
from pmpm.core import kernels as K
from pmpm.physics.boundary import apply_boundary_masks, check_boundaries, check_boxes_hold
from pmpm.physics.supports import HeldFaces
from pmpm.errors import ParticleExitError, UnstableRunError
from pmpm.core.grid import Grid, GridWindow, choose_tile
from pmpm.physics.damping import RayleighDamping, undamped_cfl_limit
from pmpm.physics.groundmotion import GroundMotion
from pmpm.physics.events import make_events
from pmpm.physics.pushover import Pushover
from pmpm.physics.loads import Loads
from pmpm.physics.materials import make_material
from pmpm.core.schemes import make_scheme
from pmpm.core.transfers import make_transfer
from pmpm.core.particles import OPTIONAL_FIELDS, start_deformation
from pmpm.scene.setup_particles import choose_axis, create_particles, make_decomposition, place_points
from pmpm.core.shape import CPDI_REACH, MAX_HALF_LENGTH, ghost_width, min_cells, shape_argument
from pmpm.errors import ConfigError
from pmpm.results.reactions import Reactions
from pmpm.results.sections import make_cuts
from pmpm.scene.limits import check_memory, check_time_step

__all__ = ["Solver", "needs_deformation_gradient", "numerical_loss"]
logger = logging.getLogger(__name__)

#: steps between energy checks (each is one pass over the particles and one allreduce)
ENERGY_CHECK_INTERVAL = 10
#: energy above (initial + external work) that counts as divergence, relative to the energies
#: in play: healthy runs stay within a few percent (tests show < 5%), diverging ones explode
ENERGY_GROWTH_LIMIT = 0.5


def needs_deformation_gradient(scene, materials):
    """Whether the run keeps the deformation gradient F per particle: a material that needs it
    (hyperelastic), the Green-Naghdi rate (the rotation of F), CPDI (its particle domains are
    F times the initial ones), or an output field ``F``.
    Otherwise F is neither stored nor updated (the kernels get None and compile it out).

    Parameters
    ----------
    scene : pmpm.scene.config.Scene
    materials : list of pmpm.physics.materials.Material
    """
    cfg = scene.solver
    return (any(m.needs_deformation_gradient for m in materials)
            or (cfg.large_rotations and cfg.objective_rate == "green_naghdi")
            or cfg.interpolation == "cpdi"
            or "F" in scene.output.fields)


def numerical_loss(initial, external, kinetic, strain, plastic, damping, viscous=0.0, removed=0.0):
    """The energy lost to the discretisation (J): what the loads and the initial state put in
    and no physical term holds, dissipated or took out of the run,
    ``initial + external - kinetic - strain - plastic - damping - viscous - removed``.

    ``initial`` is the energy at the start (``Solver.initial_energy``: the kinetic energy, the
    bodies start unstressed). Positive: energy lost (numerical damping of the transfers and
    the time integration); negative: energy gained. The stress power integrated over the
    steps (``internal_work``) is not used: the strain energy of the current stresses is what
    the body can give back, so a loss between the two shows here too.

    Parameters
    ----------
    initial, external, kinetic, strain, plastic, damping : float or numpy.ndarray
        The energies in J, as ``Solver.energies`` names them (plastic: the plastic work,
        damping: the work of mass-proportional damping).
    viscous, removed : float or numpy.ndarray, optional
        The work of Rayleigh damping's stiffness part and the energy of the particles a scene
        event removed (J; zero where the scene has neither).
    """
    return initial + external - kinetic - strain - plastic - damping - viscous - removed


def _scene_dir(scene):
    import os
    return os.path.dirname(scene.path) if os.path.isabs(scene.path) else "."


class Solver:
    """Explicit MPM on the ranks of ``comm`` (``None``: COMM_WORLD).

    Parameters
    ----------
    scene : pmpm.scene.config.Scene
    comm : mpi4py communicator, optional
    """

    def __init__(self, scene, comm=None):
        self.scene = scene
        self.comm = get_comm(comm)
        cfg = scene.solver
        self.grid = Grid(scene.grid.origin, scene.grid.cell_size, scene.grid.cells)
        self.interpolation = cfg.interpolation
        need = min_cells(cfg.shape_function, cfg.interpolation)
        if min(self.grid.cells) < need:
            raise ConfigError("grid.cells", f"{cfg.shape_function} B-splines"
                              f"{'' if cfg.interpolation == 'point' else ' with ' + cfg.interpolation}"
                              f" need at least {need} cells per axis")
        self.labels = list(scene.materials)
        self.materials = [make_material(scene.materials[k], f"materials.{k}", scene.formulation)
                          for k in self.labels]
        # before anything big is allocated: this rank's share of grid window and particles
        local = self.comm.Split_type(MPI.COMM_TYPE_SHARED) if self.comm.Get_size() > 1 else None
        check_memory(scene, self.comm.Get_size(), local.Get_size() if local else 1,
                     state_floats=sum(int(np.prod(f)) for m in self.materials for f in m.state_fields.values()))
        if local is not None:
            local.Free()
        self.scheme = make_scheme(cfg.scheme)
        self.transfer = make_transfer(cfg.transfer, **({"order": cfg.xpic_order} if cfg.transfer == "xpic" else {}))
        self.loads = Loads(scene.loads)
        check_boundaries(scene.boundaries, self.grid)
        self.ground = (GroundMotion(scene.loads.ground_motion, scene.boundaries, _scene_dir(scene))
                       if scene.loads.ground_motion else None)
        self.pushover = Pushover(scene.pushover, scene.boundaries) if scene.pushover else None
        self.events = make_events(scene.events, scene.bodies)   # [] without [[events]]
        # Rayleigh damping by ratio: its mass part is the nodal mass-proportional damping, its
        # stiffness part a viscous stress on the particles (None: neither exists in the step)
        self.rayleigh = (RayleighDamping(scene.loads.rayleigh, self.materials)
                         if scene.loads.rayleigh else None)
        mass_part = self.rayleigh.a0 if self.rayleigh is not None else scene.loads.damping
        self.damping = mass_part or None  # None compiles the damping out
        points = place_points(scene, self.grid, self.materials, self.labels)
        check_boxes_hold(scene.boundaries, self.grid, points["x"],
                         ghost_width(cfg.shape_function, cfg.interpolation))
        # supports attached to a body hold its face's particles (None: the scene has none)
        self.supports = (HeldFaces(scene.boundaries, scene.bodies, points, self.grid)
                         if any(b.body is not None for b in scene.boundaries) else None)
        if self.supports is not None and scene.contact is not None:
            k = self.supports.index[0]
            raise ConfigError(f"boundary[{k}]", "a boundary attached to a body does not work with [contact] "
                                                "(give it a box)")
        self.n_total = len(points["m"])
        # structural results the scene asks for (nothing is set up or computed otherwise)
        self.sections = make_cuts(scene, self.grid, points) if scene.output.sections else []
        self.reactions = (Reactions(scene.boundaries, self.grid, self.supports.centroids if self.supports else None)
                          if any(b.reaction for b in scene.boundaries) else None)
        self.axis = choose_axis(scene.parallel.axis, self.grid)
        self.decomp = make_decomposition(self.comm, self.grid, self.axis,
                                         ghost_width(cfg.shape_function, cfg.interpolation), points["x"])
        optional = [f for f in scene.output.fields
                    if f in OPTIONAL_FIELDS or any(f in m.diagnostic_fields for m in self.materials)]
        self.keeps_F = needs_deformation_gradient(scene, self.materials)
        # the objective rate rotates stresses only a rate-form material integrates: a model that
        # computes its stress from F (neo-Hookean) overwrites a rotated stress unread
        self.rotates_stress = cfg.large_rotations and not all(
            m.stress_from_F and not m.tensor_state_fields for m in self.materials)
        self.particles = create_particles(points, self._owned(points["x"]), self.materials, optional)
        if self.keeps_F:
            start_deformation(self.particles)
        if self.supports is not None:
            self.supports.mark(self.particles)
        if self.rayleigh is not None:
            self.rayleigh.add_fields(self.particles)
        for name, shape in self.transfer.fields.items():   # APIC's affine velocity; none for FLIP
            self.particles.add_field(name, shape)
        if self.interpolation != "point":
            self._add_domains()
        # CPDI: the kernels count corners whose support leaves the window here ([count, first
        # particle]); read and reset after every step (``_check_and_next_dt``)
        self._corner_escape = np.array([0, -1], dtype=np.int64)
        del points
        self.loads.assign(self.particles.fields, self.decomp.allreduce_sum)
        self._build_window()
        self.wave_speed = max(m.wave_speed() for m in self.materials)
        self.mass_cutoff = cfg.mass_cutoff * self.decomp.allreduce_max(
            float(self.particles["m"].max()) if self.particles.n else 0.0)
        self.t = 0.0
        self.step_count = 0
        self.external_work = 0.0   # this rank's share; summed when reported
        self.internal_work = 0.0   # likewise: sum of V sigma : d_eps over this rank's particles
        self.damping_work = 0.0    # energy taken out by mass-proportional damping (owned nodes)
        self.removed_energy = 0.0  # kinetic energy carried out by particles an event removed
        self.removed = 0
        self.rebalances = 0
        self.vmax = self.decomp.allreduce_max(self._local_speed())
        self.dt = self.stable_dt(self.vmax)
        check_time_step(scene, self.materials, self.vmax)  # positive, finite, not too many steps
        self._vmax_healthy = self.vmax
        self.healthy_step = -1  # step count of the newest state that passed check_energy
        self.initial_energy = self.energies()["total"]

    # -- set-up helpers ---------------------------------------------------------------------
    def _owned(self, x):
        cols = K.cell_columns(x, self.grid.origin, self.grid.inv_h, self.axis)
        return self.decomp.owner_of_columns(cols) == self.decomp.rank

    def _build_window(self):
        cfg = self.scene.solver
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
        apply_boundary_masks(self.window, self.scene.boundaries)
        if self.reactions is not None:
            self.reactions.bind(self.window, self.scene.boundaries)
        w0 = self.decomp.window[0]
        self._owned_local = np.array([self.axis, self.decomp.owned[0] - w0, self.decomp.owned[1] - w0])
        if self.ground is not None:
            self.ground.bind(self.window)
        if self.pushover is not None:
            self.pushover.bind(self.window)

    def _halo_columns(self):
        """Window columns at the lower and upper end that the halo exchange reads or writes:
        the ghost columns and the owned ones a neighbour holds as its ghosts (none without a
        neighbour)."""
        d = self.decomp
        (n0, n1), (w0, w1), g = d.owned, d.window, d.ghost
        lower = min(n0 + g, w1) - w0 if d.lower != MPI.PROC_NULL else 0
        upper = w1 - max(n1 - g, w0) if d.upper != MPI.PROC_NULL else 0
        return lower, upper

    def _initial_domains(self, vol, body):
        """The GIMP particle domains: half-lengths (cells) of the square of the particle's area,
        (h / ppc) / 2 for a body filled on a lattice, capped at ``MAX_HALF_LENGTH``."""
        thickness = np.array([b.thickness for b in self.scene.bodies])[body]
        half = 0.5 * np.sqrt(vol / thickness) * self.grid.inv_h
        return np.repeat(np.minimum(half, MAX_HALF_LENGTH)[:, None], 2, axis=1)

    def _add_domains(self):
        p = self.particles
        p["domain"] = self._initial_domains(p["vol"], p["body"])

    @property
    def shape(self):
        """The ``shape`` argument of the transfer kernels: the point B-spline tag, or the GIMP
        pair (tag, the particles' current domain array: rebuilt since sorting and migration
        replace the arrays), or the CPDI tuple (tag, domain, F, the step's corner report)."""
        f = self.particles.fields
        return shape_argument(self.scene.solver.shape_function, self.interpolation,
                              f.get("domain"), f.get("F"), self._corner_escape)

    def _local_speed(self):
        v = self.particles["v"]
        return float(np.sqrt((v * v).sum(axis=1)).max()) if len(v) else 0.0

    def stable_dt(self, vmax):
        """CFL time step C h / (c + |v|max), or the scene's fixed step."""
        if self.scene.solver.time_step is not None:
            return self.scene.solver.time_step
        dt = self.scene.solver.cfl * self.grid.h / (self.wave_speed + vmax)
        if self.rayleigh is not None:  # the viscous stress shortens the stable step
            cfg = self.scene.solver
            dt *= self.rayleigh.stable_step_factor(self.wave_speed + vmax, self.grid.h,
                                                   undamped_cfl_limit(cfg.shape_function, cfg.interpolation))
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

    def _scratch(self, name, shape):
        arr = getattr(self, name, None)
        if arr is None or arr.shape != shape:
            arr = np.empty(shape)
            setattr(self, name, arr)
        return arr

    # -- the phases --------------------------------------------------------------------------
    def reset_grid(self):
        """Step 1: zero the rank's grid window (owned and ghost nodes) and choose the tiles
        this step's node passes visit: those the particles' stencils reach (plus the halo)."""
        self.window.reset(self.particles["x"])

    def particles_to_grid(self, momentum, forces):
        """Steps 4-6 / eq. 2: mass and momentum and/or internal and external forces."""
        p = self.particles
        self.transfer.p2g(self, momentum, forces)
        point = self.loads.point_forces(p, self.t) if forces else None
        if point is not None:
            idx, load_id, load_w, load_vec = point
            K.scatter_point_loads(idx, p["x"], load_id, load_w, load_vec, *self._geometry())

    def force_stress(self):
        """The stress whose divergence is the internal force: the particles' stress, plus the
        viscous stress of Rayleigh damping when the scene asks for it, with the rows of a body
        being removed scaled down (pmpm.physics.events). Without either, the stress itself."""
        p = self.particles
        fading = [e for e in self.events if e.active(self.t)] if self.events else ()
        if self.rayleigh is None and not fading:
            return p["stress"]
        out = self._scratch("_force_stress_buf", (p.n, 3))
        if self.rayleigh is not None:
            self.rayleigh.force_stress(p["stress"], p[self.rayleigh.FIELD], out)
        else:
            out[...] = p["stress"][:, :3]
        for event in fading:
            event.scale_force_stress(p, out, self.t)
        return out

    def exchange_halo(self, fields):
        """HALO: every rank's contributions summed in the owned and the ghost columns alike
        (one round with each neighbour)."""
        self.decomp.sum_halo(self.window.G[..., fields])

    def update_grid(self, dt):
        """Steps 7-8 / eq. 3-4: (mv) += f dt (with damping if asked), essential BCs (moving
        with the ground if asked); fields become v and dv."""
        w = self.window
        if self.ground is not None:
            self.ground.apply(w, self.t + dt)
        if self.pushover is not None:
            self.pushover.apply(w, self.t + dt)
        react = self.reactions.kernel_arg() if self.reactions is not None else None
        damped, reactions = K.grid_update(w.G, dt, self.mass_cutoff, w.bc_mask, w.bc_vel,
                                          0, w.shape[0], 0, w.shape[1], self.damping, self._owned_local,
                                          react, w.tiles)
        self.damping_work += damped
        self.external_work += reactions  # supports are external: their work enters the balance
        if self.supports is not None:
            self.supports.project(self, K.MOM, impulse=True)

    def grid_velocity(self, source, target):
        """v = (mv)/m with BCs, e.g. of the MUSL re-mapped momentum (eq. 6)."""
        w = self.window
        K.momentum_to_velocity(w.G, source, target, w.bc_mask, w.bc_vel,
                               0, w.shape[0], 0, w.shape[1], w.tiles)
        if self.supports is not None:
            self.supports.project(self, target)

    def grid_to_particles(self, remap):
        """Step 9 / eq. 5: particle velocities by the scene's transfer (FLIP/PIC, APIC); MUSL
        also re-maps their momenta."""
        p = self.particles
        self._dx = self._scratch("_dx_buf", (p.n, 2))
        vmax, bad = self.transfer.g2p(self, remap)
        self._vmax_local, self._bad_local = vmax, bad
        if self.supports is not None:   # (the MUSL re-map above carried their FLIP velocity; the
            self.supports.hold_particles(self)   # re-mapped velocity is projected in grid_velocity)

    def _kinematics_outputs(self):
        """Arrays the kinematics kernels fill or advance this step, None where the scene does
        not ask for them: (de, dw, F, vol0, dq). ``dw`` is the spin increment (Jaumann),
        ``dq`` the cosine and sine of the change of the polar angle of F (Green-Naghdi)."""
        p, cfg = self.particles, self.scene.solver
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
        p = self.particles
        de, dw, F, vol0, dq = self._kinematics_outputs()
        self.external_work += K.g2p_kinematics(
            p["x"], p["m"], p["vol"], p.fields.get("strain"), de, dw, F, vol0, dq,
            velocity_field, self._dx if move else None, dt,
            self.loads.gravity, None, None, None, *self._geometry())
        if self.interpolation == "cpgimp":
            self._stretch_domains(de)
        if move:
            self._point_load_work()

    def _stretch_domains(self, de):
        """cpGIMP: each half-length follows the material's stretch along its axis, l *= 1 + de_ii
        (the diagonal of the step's I + dt L), capped at ``MAX_HALF_LENGTH`` (the 5-node support)."""
        d = self.particles["domain"]
        d *= 1.0 + de[:, :2]
        np.clip(d, 1e-6, MAX_HALF_LENGTH, out=d)

    def move_particles(self, dt):
        """Position update x += dt sum N v_i (USF: after the stress update)."""
        p = self.particles
        self.external_work += K.g2p_kinematics(
            p["x"], p["m"], p["vol"], None, None, None, None, None, None, 1, self._dx, dt,
            self.loads.gravity, None, None, None, *self._geometry())
        self._point_load_work()

    def _point_load_work(self):
        """Work of the set forces over this step's moves (the forces of the step's start)."""
        point = self.loads.point_forces(self.particles, self.t)
        if point is not None:
            idx, load_id, load_w, load_vec = point
            self.external_work += K.point_load_work(idx, self._dx, load_id, load_w, load_vec)

    def update_stress(self):
        """Stress increments through each material's tangent (eq. 6 / eq. 15)."""
        p = self.particles
        self._rotate(p["stress"])
        # internal work by the trapezoid rule, half before and half after the update; it closes
        # the energy balance exactly where 1/2 sigma : C^-1 : sigma (hypoelastic) does not
        self.internal_work += 0.5 * K.stress_power(p["stress"], self._de, p["vol"])
        several = len(self.materials) > 1
        thickness = self.keeps_F and self.scene.formulation == "plane_stress"
        for k, material in enumerate(self.materials):
            if thickness and not material.needs_deformation_gradient:
                trace_before = self._scratch("_trace_buf", (p.n,))
                K.in_plane_trace(p["stress"], trace_before)
            state = {name: p.fields.get(name) for name in material.state_fields}
            if material.needs_deformation_gradient:
                state["F"] = p["F"]
            for name in material.tensor_state_fields:
                self._rotate(p[name])
            material.update_stress(p["stress"], self._de, state, p["mat"], k if several else -1)
            if thickness and not material.needs_deformation_gradient:
                # F33 from szz = 0 (the hyperelastic models solve it themselves)
                K.advance_thickness_stretch(p["F"], self._de, p["stress"], trace_before,
                                            material.E, material.nu, p["mat"], k if several else -1)
        self.internal_work += 0.5 * K.stress_power(p["stress"], self._de, p["vol"])
        if self.rayleigh is not None:
            self.rayleigh.update(p, self._de, self._dt_step)
        for event in self.events:  # what a fading body's stress did not pass to the grid
            self.removed_energy -= event.released_work(p, self._de)

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

    def remove_body(self, event):
        """The particles of an event's body leave the run (collective: every rank at the same
        step). Their kinetic energy, strain energy and plastic work move to ``removed_energy``
        (the latter two out of the internal work, which they had entered)."""
        p = self.particles
        gone = event.leaving(p)
        part = p.take(gone)
        kinetic = K.kinetic_energy(part["m"], part["v"])
        several = len(self.materials) > 1
        held = sum(K.elastic_energy(part["stress"], part["vol"], m.E, m.nu, part["mat"], k if several else -1)
                   for k, m in enumerate(self.materials) if not m.needs_deformation_gradient)
        held += sum(m.strain_energy(part["F"], part["vol0"], part["mat"], k if several else -1)
                    for k, m in enumerate(self.materials) if m.needs_deformation_gradient)
        if "plastic_work" in part:
            held += float(np.sum(part["plastic_work"] * part["vol"]))
        self.removed_energy += kinetic + held
        self.internal_work -= held
        self.particles = p.take(~gone)
        event.done = True
        count = int(self.decomp.allreduce_sum(int(gone.sum())))
        mass = self.decomp.allreduce_sum(float(part["m"].sum()))
        self.removed_by_events = getattr(self, "removed_by_events", 0) + count
        if self.decomp.rank == 0:
            logger.info("t = %.6g s: body %r removed (%d particles, %.6g kg)", self.t, event.name, count, mass)

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
        par = self.scene.parallel
        if par.rebalance_threshold is None or self.decomp.size == 1:
            return False
        if self.decomp.imbalance(self.particles.n) <= par.rebalance_threshold:
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
        cfg = self.scene.solver
        if cfg.sort_interval and self.step_count % cfg.sort_interval == 0:
            self.sort_particles()
        dt = self.dt
        remaining = cfg.end_time - self.t
        if 0 < remaining < dt:  # land on the end time exactly
            dt = remaining
        self._dt_step = dt
        self.scheme.advance(self, dt)
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
        for event in self.events:
            if event.due(self.t):
                self.remove_body(event)
        if self.step_count % self.scene.parallel.rebalance_interval == 0:
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
        """Global energies (J): kinetic, recoverable strain (1/2 sigma : C^-1 : sigma V), plastic
        work, internal work (integrated stress power: strain + dissipation, exact for any
        material), external work, damping work (mass-proportional), viscous damping work (the
        stiffness part of Rayleigh damping), the energy removed particles carried out
        (``removed_energy``), and ``total`` = kinetic + internal work + both damping works +
        removed energy, which equals the external work plus the initial kinetic energy when the
        run conserves energy. ``summed``: ``local_energies()`` already summed over the ranks
        (by a reduction shared with other figures), else summed here (collective)."""
        if summed is None:
            summed = self.decomp.allreduce_sum(self.local_energies())
        ke, se, pw, wi, we, wd, wv, er = summed
        e0 = getattr(self, "initial_energy", ke + wi + wd + wv + er)   # at construction: this very state
        return {"kinetic": ke, "strain": se, "plastic_work": pw, "internal_work": wi,
                "external_work": we, "damping_work": wd, "viscous_damping_work": wv,
                "removed_energy": er, "total": ke + wi + wd + wv + er,
                "numerical_loss": numerical_loss(e0, we, ke, se, pw, wd, viscous=wv, removed=er)}

    def local_energies(self):
        """This rank's shares of the energies, in the order ``energies`` reads them."""
        p = self.particles
        kinetic = K.kinetic_energy(p["m"], p["v"])
        several = len(self.materials) > 1
        # hyperelastic models know their stored energy W(F); the others' is the recoverable
        # 1/2 sigma : C^-1 : sigma
        strain = sum(m.strain_energy(p["F"], p["vol0"], p["mat"], k if several else -1)
                     if m.needs_deformation_gradient else
                     K.elastic_energy(p["stress"], p["vol"], m.E, m.nu, p["mat"], k if several else -1)
                     for k, m in enumerate(self.materials))
        plastic = float(np.sum(p["plastic_work"] * p["vol"])) if "plastic_work" in p else 0.0
        return np.array([kinetic, strain, plastic, self.internal_work, self.external_work, self.damping_work,
                         self.viscous_damping_work, self.removed_energy])

    @property
    def viscous_damping_work(self):
        """This rank's share of the energy the viscous stress of Rayleigh damping dissipated."""
        return self.rayleigh.work if self.rayleigh is not None else 0.0

    @viscous_damping_work.setter
    def viscous_damping_work(self, value):
        if self.rayleigh is not None:
            self.rayleigh.work = value
