"""The material interface: parameters, per-particle state, a numba stress kernel.

A material is chosen in the scene by ``type = "<name>"`` under ``[materials.<label>]``.
Adding a model means one new module with a ``Material`` subclass and its ``@njit`` kernel.

Conventions (Voigt, engineering shear):
    stress  (N, 4)  [sxx, syy, sxy, szz]   szz stays 0 in plane stress
    de      (N, 3)  [dexx, deyy, dgxy]      strain increment of this step
"""
import logging
import math

import numpy as np

from pmpm.core.effects import register_energy
from pmpm.errors import ConfigError

#: the energy a plastic material dissipates (J): its per-particle field ``plastic_work`` (J/m^3)
#: integrated over the volume, a part of the internal work
PLASTIC_WORK = register_energy("plastic_work", "plastic work, dissipated", outside=False)

# after plastic_work: the fracture option registers its fracture_work, the next energy column
from pmpm.physics.materials import fracture as fracture_option  # noqa: E402

__all__ = ["Material", "KinematicHardening", "Params", "FORMULATIONS"]
logger = logging.getLogger(__name__)

FORMULATIONS = ("plane_stress", "plane_strain")


class Params:
    """Reads and validates one material's TOML table; every error names its key.

    Parameters
    ----------
    table : dict
        The material's TOML table (``type`` already removed).
    key : str
        Dotted key of the table, e.g. ``materials.steel``.
    """

    def __init__(self, table, key):
        self._table = dict(table)
        self._key = key
        self._used = set()

    def number(self, name, *, default=None, low=None, high=None, low_open=False, high_open=False):
        """A float parameter with optional bounds (``low_open``: strictly greater)."""
        self._used.add(name)
        if name not in self._table:
            if default is None:
                raise ConfigError(f"{self._key}.{name}", "missing (required)")
            return float(default)
        value = self._table[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{self._key}.{name}", f"must be a finite number (got {value!r})")
        value = float(value)
        if low is not None and (value < low or (low_open and value == low)):
            rel = ">" if low_open else ">="
            raise ConfigError(f"{self._key}.{name}", f"must be {rel} {low:g} (got {value:g})")
        if high is not None and (value > high or (high_open and value == high)):
            rel = "<" if high_open else "<="
            raise ConfigError(f"{self._key}.{name}", f"must be {rel} {high:g} (got {value:g})")
        return value

    def table(self, name):
        """A sub-table (a dict) or None when absent; checking it is the caller's job."""
        self._used.add(name)
        return self._table.get(name)

    def finish(self):
        """Refuse keys the material does not know (typos must not pass silently)."""
        unknown = sorted(set(self._table) - self._used)
        if unknown:
            raise ConfigError(f"{self._key}.{unknown[0]}", "unknown key for this material type")


class Material:
    """Base class of all materials (registry key: ``name``).

    Subclasses set ``name``, ``state_fields`` and ``tensor_state_fields``, read their
    parameters in ``__init__`` and implement ``update_stress``.
    """

    name = None
    #: extra per-particle fields: name -> trailing shape (``()`` for a scalar); zero at start
    state_fields = {}
    #: state fields that rotate with the stress under the Jaumann rate (Voigt, same layout as stress)
    tensor_state_fields = ()
    #: state fields nothing in the step reads: kept only when the scene's output asks for them
    #: (the kernel receives None otherwise and its update of the field is compiled out)
    diagnostic_fields = ()
    #: formulations the model supports
    formulations = FORMULATIONS
    #: whether the model reads the deformation gradient (hyperelastic): the run then keeps F
    #: and the solver passes it as ``state["F"]`` (N, 5: Fxx, Fxy, Fyx, Fyy, Fzz)
    needs_deformation_gradient = False
    #: whether the model computes the stress from F alone at every step (hyperelastic, objective
    #: by construction): the objective rate's rotation of the stress before the update would be
    #: overwritten unread, so the solver skips the rotation (and the spin) when every material
    #: of the scene is such a model
    stress_from_F = False
    #: whether the model gives the implicit integrator its tangent (``tangent``,
    #: pmpm.core.implicit); a model without one is refused under ``solver.integrator = "implicit"``
    has_tangent = False

    def __init__(self, table, key, formulation):
        if formulation not in self.formulations:
            raise ConfigError(f"{key}.type", f"{self.name!r} does not support {formulation} "
                              f"(supported: {', '.join(self.formulations)})")
        self.key = key
        self.formulation = formulation
        p = Params(table, key)
        self.E = p.number("E", low=0.0, low_open=True)
        self.nu = p.number("nu", low=-1.0, high=0.5, low_open=True, high_open=True)
        self.density = p.number("density", low=0.0, low_open=True)
        self.read_params(p)
        p.finish()

    def read_params(self, p):
        """Read the model's own parameters from ``p`` (a :class:`Params`)."""
        if p.table("fracture") is not None:
            raise ConfigError(f"{self.key}.fracture", f"{self.name!r} cannot fracture (ductile fracture "
                              f"is an option of the plastic steel models: smooth_vonmises, bilinear_vonmises)")

    def use_cell_size(self, h):
        """Told the grid's cell size ``h`` once the run's grid is known (pmpm.build): a model
        with a length scale tied to the cell (the fracture's crack band) reads it here."""

    def use_integrator(self, name):
        """Told the run's integrator (``solver.integrator``) once by pmpm.build: a model whose
        update is tuned for one of them (the smooth model's sub-steps) chooses here."""

    # -- elasticity shared by every model ---------------------------------------------------
    @property
    def params(self):
        """The float64 parameter vector handed to the numba kernel."""
        return np.array([self.E, self.nu], dtype=np.float64)

    @property
    def plane_strain(self):
        return self.formulation == "plane_strain"

    def wave_speed(self):
        """Elastic dilatational wave speed of the formulation (the CFL speed)."""
        if self.plane_strain:
            modulus = self.E * (1 - self.nu) / ((1 + self.nu) * (1 - 2 * self.nu))
        else:
            modulus = self.E / (1 - self.nu ** 2)
        return math.sqrt(modulus / self.density)

    def elastic_energy_density(self, stress):
        """Recoverable strain energy per unit volume, 0.5 sigma : C^-1 : sigma, for (N, 4) stress."""
        sxx, syy, sxy, szz = stress[:, 0], stress[:, 1], stress[:, 2], stress[:, 3]
        E, nu = self.E, self.nu
        normal = sxx ** 2 + syy ** 2 + szz ** 2 - 2 * nu * (sxx * syy + syy * szz + szz * sxx)
        return 0.5 * normal / E + (1 + nu) / E * sxy ** 2

    def describe(self):
        """One line for the start-up log."""
        return f"{self.name} (E={self.E:g}, nu={self.nu:g}, density={self.density:g})"

    # -- the step --------------------------------------------------------------------------
    def update_stress(self, stress, de, state, mat_ids, which):
        """Advance ``stress`` (and ``state``) in place by the strain increments ``de``.

        Parameters
        ----------
        stress : ndarray (N, 4)
        de : ndarray (N, 3)
        state : dict of ndarray or None
            This material's ``state_fields`` arrays (first axis N); a ``diagnostic_fields``
            entry is None when the run does not keep it.
        mat_ids : ndarray (N,) int32
            Material index of each particle.
        which : int
            Update only particles with ``mat_ids == which``; -1 updates all.
        """
        raise NotImplementedError

    #: True when ``update_stress_power`` sums the stress power in the update's own pass
    sums_power = False

    def increment_matrix(self):
        """The stress update as one constant linear map, for a model whose update is one:
        the (4, 3) float64 matrix D with d(sxx, syy, sxy, szz) = D d(exx, eyy, gxy), the same
        for every particle at every step (no state, no dependence on the stress or on F). A
        transfer may then apply it in its own pass over the particles (the MLS scheme's G2P,
        pmpm.core.kernels.mls.g2p_mls, as Hu et al.'s G2P does), where the core needs a number
        and no law. None (this default) for every other model: the solver calls
        ``update_stress``."""
        return None

    def update_stress_power(self, stress, de, vol, state, mat_ids, which):
        """``update_stress`` that also returns sum_p V_p sigma_p : de_p (``vol`` (N,)) over the
        particles it updated, with their new stress: the second half of the step's trapezoid
        internal work in the update's pass rather than a pass of its own (a material that says
        ``sums_power``; the solver takes the separate pass for the others)."""
        raise NotImplementedError

    def tangent(self, stress0, state0, stress1, state1, de, D, mat_ids, which):
        """The stiffness of the stress update for the implicit integrator: into ``D`` (N, 3, 3)
        d(sxx, syy, sxy) / d(dexx, deyy, dgxy) of the increment ``de`` that took ``stress0``,
        ``state0`` (the step's start) to ``stress1``, ``state1`` (what ``update_stress`` made
        of them). Rows of particles of other materials (``which`` >= 0) are left as they are.

        Parameters
        ----------
        stress0, stress1 : ndarray (N, 4)
        state0, state1 : dict of ndarray
        de : ndarray (N, 3)
        D : ndarray (N, 3, 3)
        mat_ids : ndarray (N,) int32
        which : int
        """
        raise NotImplementedError(f"{self.name} has no tangent for the implicit integrator")


def keep_work_in_joules(work, de, mat_ids, which, damage=None):
    """Deflate the per-volume plastic work ``work`` of the points of material ``which`` (all
    when ``which`` < 0) by this step's volume ratio, before the step's plastic work is added.
    With fracture (``damage`` given) the failed points are left alone: the fracture epilogue
    freezes their plastic work in joules itself (pmpm.physics.materials.fracture._soften).

    The run counts ``plastic_work`` (J/m^3) times the particle's current volume, which the step
    has just scaled by 1 + tr(de) (pmpm.core.kernels.transfer; det of the step's in-plane
    deformation where the particles keep F, equal to second order). Work dissipated at the old
    volume, multiplied by the new one, would be counted again at each step: in plane stress,
    where the thickness is constant and incompressible plastic flow grows the in-plane area by
    about half the axial plastic strain, the energy balance showed a gain of some 5% of the
    external work at plastic strains of 0.2 (tests/unit/test_plastic_work_volume.py). Deflated,
    V w_p is the joules dissipated so far, and the step adds V_new mean(sigma) . d_eps_p, the
    volume the solver's internal work uses too.
    """
    scale = 1.0 / (1.0 + de[:, 0] + de[:, 1])
    if which < 0 and damage is None:
        work *= scale
        return
    sel = np.ones(len(work), bool) if which < 0 else mat_ids == which
    if damage is not None:
        sel &= damage < 1.0
    work[sel] *= scale[sel]


class KinematicHardening(Material):
    """Shared part of the von Mises models with Ziegler kinematic hardening: the plastic state
    every particle carries and the two parameters they all read (not a material by itself)."""

    state_fields = {"back_stress": (4,), "eps_p": (3,), "eps_p_eq": (), "plastic_work": ()}
    tensor_state_fields = ("back_stress",)
    # the plastic strain tensor is output only (24 bytes per particle); eps_p_eq stays, the
    # default colour of the deformed-shape plot
    diagnostic_fields = ("eps_p",)

    def read_params(self, p):
        """Read ``yield_stress`` and ``hardening``.

        Parameters
        ----------
        p : Params
        """
        self.yield_stress = p.number("yield_stress", low=0.0, low_open=True)
        # required: a silent default of 0 (perfect plasticity) would change results without notice
        self.hardening = p.number("hardening", low=0.0, high=1.0, high_open=True)
        self.read_fracture(p)

    # -- the ductile fracture option (pmpm.physics.materials.fracture) -----------------------
    #: the scene's fracture settings (None: the material cannot fracture in this run)
    fracture = None
    #: crack band width l_c: the scene's ``length``, else the grid's cell size (use_cell_size)
    fracture_length = None

    def read_fracture(self, p):
        """Read ``[<key>.fracture]`` if present: then the material keeps the fracture fields."""
        table = p.table("fracture")
        if table is None:
            return
        self.fracture = fracture_option.read_fracture(table, f"{self.key}.fracture")
        self.fracture_length = self.fracture["length"]
        self.state_fields = {**type(self).state_fields, **fracture_option.fracture_fields(self.fracture)}
        self.tensor_state_fields = (*type(self).tensor_state_fields, "effective_stress")

    #: whether the update keeps V plastic_work in joules (keep_work_in_joules): in a run, whose
    #: build tells every material the cell size (use_cell_size), the run counts per-volume
    #: fields times the particles' current volumes; a lone point (the constitutive tests) has
    #: no volume and keeps the per-volume identity d(U + w_p) = mean(sigma) . d_eps
    work_in_joules = False

    def use_cell_size(self, h):
        self.work_in_joules = True   # called by pmpm.build for every material of a run
        if self.fracture is not None:
            self.fracture_length = fracture_option.band_length(self.fracture, h)

    def update_stress(self, stress, de, state, mat_ids, which):
        """The material's plain kernel (:meth:`plastic_update`), between the fracture option's
        two passes when the scene names it (pmpm.physics.materials.fracture)."""
        if self.work_in_joules:
            keep_work_in_joules(state["plastic_work"], de, mat_ids, which,
                                state["damage"] if self.fracture is not None else None)
        if self.fracture is None:
            self.plastic_update(stress, de, state, mat_ids, which)
            return
        fp, damage, fwork, crack, eff = self.fracture_arguments(state)
        eq, work = state["eps_p_eq"], state["plastic_work"]
        ids, phase, old, eq0, work0 = fracture_option.prelude(stress, de, eq, work, mat_ids, which,
                                                              self.plane_strain, fp, damage, crack, eff)
        self.plastic_update(stress, de, state, ids, 0)
        # the local criterion accumulates the damage itself; the nonlocal one its local index
        index = state.get("vgm_index")
        fracture_option.epilogue(phase, old, eq0, work0, stress, de, eq, work, eff, crack, damage, fwork, fp,
                                 damage if index is None else index)

    def plastic_update(self, stress, de, state, mat_ids, which):
        """The plastic model's own stress update (its numba kernel): see :meth:`update_stress`."""
        raise NotImplementedError

    def fracture_arguments(self, state):
        """The fracture passes' arguments: (parameters, damage, fracture_work, crack_strain,
        effective_stress), all None without fracture."""
        if self.fracture is None:
            return None, None, None, None, None
        if self.fracture_length is None:
            raise RuntimeError(f"{self.key}: fracture needs the cell size (use_cell_size) or a length")
        fp = fracture_option.kernel_params(self.fracture, self.E, self.nu, self.fracture_length)
        return (fp, state["damage"], state["fracture_work"], state["crack_strain"], state["effective_stress"])
