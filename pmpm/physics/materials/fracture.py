"""Ductile fracture of structural steel: damage from a triaxiality-dependent fracture strain,
then a Hillerborg-regularised release of the tension of a failed material point.

An option of the plastic steel materials (``smooth_vonmises``, ``bilinear_vonmises``), named in
the scene by a sub-table of the material::

    [materials.steel.fracture]
    model = "void_growth"      # Kanvinde & Deierlein's void growth model (docs/fracture.md)
    eta = 1.0                  # fracture strain at zero triaxiality (illustrative: docs/fracture.md)
    fracture_energy = 1.0e5    # G_f, J/m^2: energy per unit crack area the release dissipates
    length = 0.01              # l_c, m: width of the crack band (default: band_cells x the cell size)
    band_cells = 1.5           # or the band's width in cells (default 1; not with length)
    characteristic_length = 0.004   # l*, m: the criterion averaged over l* (default: at each point)
    band_lstar = 0.40          # the band's least width in l* (needs characteristic_length; not with
                               # length): l_c = max(band_cells x h, band_lstar x l*)

Damage (docs/fracture.md has the sources and the choice of model)
    dD = d(eps_p_eq) / eps_f(T),  eps_f(T) = eta exp(-1.5 T),  T = sigma_m / sigma_eq
    from the Cauchy stress at the end of each increment (szz included: 0 in plane stress, the
    stress's own szz in plane strain); no damage below the cut-off T <= -1/3 (Bao and
    Wierzbicki's: no ductile fracture under such compression). Under proportional loading
    the increments sum to eps_p_eq / eps_f(T): the point fails where its equivalent plastic
    strain reaches the locus, which is also the stress-modified critical strain criterion.
Nonlocal criterion (``characteristic_length`` l*)
    The increments above accumulate the point's own index (field ``vgm_index``), and the point
    fails when the index averaged over l* and its own index have both reached 1
    (:func:`fail_where`, called by the effect pmpm.physics.fracture_nonlocal, which computes the
    average on the grid); ``damage`` then holds the smaller of the two. Without l* the index is
    ``damage`` itself and a point fails where it reaches 1.
Failure (D = 1) and the release of its tension
    From then the material's own update advances an *effective* stress (field
    ``effective_stress``), and the stress the point transmits is its compressive principal
    part in full plus its tensile part scaled by 1 - w:

        sigma = sigma_eff^- + (1 - w) sigma_eff^+,   w = min(1, kappa / kappa_u)

    kappa is the equivalent plastic strain accumulated since failure (the opening of the smeared
    crack), kappa_u = 2 (G_f / l_c - U_f) / sigma_eq,f with U_f and sigma_eq,f the elastic
    energy density and von Mises stress at failure, so that a point in uniaxial tension without
    hardening dissipates exactly G_f / l_c per unit volume between failure and full release (the
    linear softening's triangle plus its stored elastic energy): the energy per unit crack area
    is G_f whatever the cell, when l_c is the width of the band the crack localises in.
    Once released (w = 1) the point is elastic in its effective stress (plasticity frozen), so
    a tensile opening after that must be closed again before the faces bear compression.
Energy
    ``fracture_work`` (J/m^3, an energy term of the run) collects everything a failed point
    dissipates: its increments are mean(sigma) . d_eps - d(1/2 sigma : C^-1 : sigma), the
    plastic work of a failed point is not counted twice, and both are kept in joules while
    the point's volume grows with the opening (the run multiplies them by the current volume,
    which the step scaled by 1 + tr(de)), so the energy balance of a failed point closes to
    round-off in joules (tests/unit/test_fracture_point.py).

The fracture option is two passes around the material's own, unchanged kernel (:func:`prelude`,
then the kernel on the points not yet released, then :func:`epilogue`;
KinematicHardening.update_stress): a scene that names no fracture runs the plain kernel alone,
so the option costs it nothing, and the materials' kernels (the smooth model's vectorised block
path included) serve the fracture runs as they are. :func:`fracture_point_reference` is the
NumPy twin of the per-point epilogue.
"""
import math

import numba as nb
import numpy as np

from pmpm.core.effects import register_energy
from pmpm.errors import ConfigError

__all__ = ["FractureModel", "VoidGrowth", "FRACTURE_MODELS", "read_fracture", "FRACTURE_FIELDS",
           "triaxiality", "fracture_strain", "release", "begin_point", "elastic_point",
           "prelude", "epilogue", "fail_where", "fracture_fields", "band_length", "NONLOCAL_FIELDS",
           "fracture_point_reference", "triaxiality_reference", "CUTOFF"]

#: the energy failed material points dissipate (J): the field ``fracture_work`` (J/m^3) over the
#: volume, a part of the internal work like the plastic work
FRACTURE_WORK = register_energy("fracture_work", "fracture energy dissipated by failed material points",
                                outside=False)

#: no damage at or below this triaxiality (Bao & Wierzbicki 2005)
CUTOFF = -1.0 / 3.0

#: per-particle fields a material with fracture keeps (zero at the start)
FRACTURE_FIELDS = {"damage": (), "fracture_work": (), "crack_strain": (2,), "effective_stress": (4,)}
#: and with a characteristic length (the nonlocal criterion): the local void growth index
NONLOCAL_FIELDS = {"vgm_index": ()}

# layout of the kernels' parameter vector
_MODEL, _ETA, _SPECIFIC, _E, _NU, _NONLOCAL = 0, 1, 2, 3, 4, 5


def fracture_fields(settings):
    """The per-particle fields of a material with these fracture settings."""
    if settings.get("characteristic_length") is None:
        return dict(FRACTURE_FIELDS)
    return {**FRACTURE_FIELDS, **NONLOCAL_FIELDS}


class FractureModel:
    """A fracture locus eps_f(T): its scene name, id in the kernels and parameters."""

    name = None
    model_id = -1

    def read(self, table, key):
        """The locus parameters from the TOML ``table`` at ``key`` (a dict; keys it uses removed)."""
        raise NotImplementedError


class VoidGrowth(FractureModel):
    """Kanvinde & Deierlein's void growth model: eps_f(T) = eta exp(-1.5 T) (module doc)."""

    name = "void_growth"
    model_id = 0

    def read(self, table, key):
        return {"eta": _positive(table, key, "eta")}


#: the fracture models by scene name
FRACTURE_MODELS = {cls.name: cls() for cls in (VoidGrowth,)}


def _positive(table, key, name, required=True):
    """``table[name]`` as a finite number > 0 (None when absent and not required)."""
    if name not in table:
        if required:
            raise ConfigError(f"{key}.{name}", "missing (required)")
        return None
    value = table.pop(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{key}.{name}", f"must be a finite number (got {value!r})")
    if value <= 0:
        raise ConfigError(f"{key}.{name}", f"must be > 0 (got {value:g})")
    return float(value)


def read_fracture(table, key):
    """Validate a material's ``fracture`` sub-table; returns a dict of its settings.

    Parameters
    ----------
    table : dict
        The TOML sub-table.
    key : str
        Its dotted key, e.g. ``materials.steel.fracture``.
    """
    if not isinstance(table, dict):
        raise ConfigError(key, "must be a table ([materials.<label>.fracture])")
    table = dict(table)
    model = table.pop("model", None)
    if model is None:
        raise ConfigError(f"{key}.model", f"missing; one of: {', '.join(FRACTURE_MODELS)}")
    if model not in FRACTURE_MODELS:
        raise ConfigError(f"{key}.model", f"unknown fracture model {model!r}; one of: {', '.join(FRACTURE_MODELS)}")
    settings = {"model": model, **FRACTURE_MODELS[model].read(table, key)}
    settings["fracture_energy"] = _positive(table, key, "fracture_energy")
    settings["length"] = _positive(table, key, "length", required=False)
    settings["characteristic_length"] = _positive(table, key, "characteristic_length", required=False)
    # the crack band's width in cells, for the default l_c (band_cells x the cell size)
    band = _positive(table, key, "band_cells", required=False)
    if band is not None and settings["length"] is not None:
        raise ConfigError(f"{key}.band_cells", "give either length (m) or band_cells (cells), not both")
    settings["band_cells"] = 1.0 if band is None else band
    # the band's least width in units of l*: once the grid resolves l* the failed band's width
    # follows l*, not the cell (docs/fracture.md, "The release length once l* is resolved")
    lstar_band = _positive(table, key, "band_lstar", required=False)
    if lstar_band is not None:
        if settings["characteristic_length"] is None:
            raise ConfigError(f"{key}.band_lstar", "needs characteristic_length (the l* it is a fraction of)")
        if settings["length"] is not None:
            raise ConfigError(f"{key}.band_lstar", "give either length (m) or band_lstar (with band_cells), not both")
        if lstar_band > 1.0:
            raise ConfigError(f"{key}.band_lstar", f"must be <= 1: a band wider than the criterion's l* "
                                                   f"(got {lstar_band:g})")
    settings["band_lstar"] = lstar_band
    if table:
        raise ConfigError(f"{key}.{sorted(table)[0]}", "unknown key for this fracture model")
    return settings


def band_length(settings, h):
    """The release length l_c of a run whose cell is ``h`` (m): the scene's ``length``, else the
    crack band's width, max(band_cells x h, band_lstar x l*) (the second only with ``band_lstar``):
    the band is at least ``band_cells`` cells wide, and at least ``band_lstar`` l* wide once the
    grid resolves l* (docs/fracture.md)."""
    if settings.get("length") is not None:
        return settings["length"]
    lc = settings.get("band_cells", 1.0) * float(h)
    if settings.get("band_lstar") is not None:
        lc = max(lc, settings["band_lstar"] * settings["characteristic_length"])
    return lc


def kernel_params(settings, E, nu, length):
    """The kernels' parameter vector [model id, eta, G_f / l_c, E, nu, nonlocal (1.0 or 0.0)]
    (float64)."""
    model = FRACTURE_MODELS[settings["model"]]
    nonlocal_ = 0.0 if settings.get("characteristic_length") is None else 1.0
    return np.array([model.model_id, settings["eta"], settings["fracture_energy"] / length, E, nu, nonlocal_],
                    dtype=np.float64)


# -- point functions shared by the materials' kernels ----------------------------------------
@nb.njit(cache=True, inline="always")
def _von_mises(sxx, syy, sxy, szz):
    return math.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy * sxy)


@nb.njit(cache=True, inline="always")
def triaxiality(sxx, syy, sxy, szz):
    """sigma_m / sigma_eq of a stress (0 for a stress-free point)."""
    seq = _von_mises(sxx, syy, sxy, szz)
    if seq <= 0.0:
        return 0.0
    return (sxx + syy + szz) / (3.0 * seq)


@nb.njit(cache=True, inline="always")
def fracture_strain(fp, T):
    """eps_f(T) of the model of parameters ``fp``; inf at or below the cut-off."""
    if T <= CUTOFF:
        return math.inf
    return fp[_ETA] * math.exp(-1.5 * T)


@nb.njit(cache=True, inline="always")
def _energy_density(E, nu, sxx, syy, sxy, szz):
    """1/2 sigma : C^-1 : sigma (the solver's strain energy, pmpm.core.kernels.elastic_energy)."""
    normal = sxx * sxx + syy * syy + szz * szz - 2.0 * nu * (sxx * syy + syy * szz + szz * sxx)
    return 0.5 * normal / E + (1.0 + nu) / E * sxy * sxy


@nb.njit(cache=True, inline="always")
def release(w, sxx, syy, sxy, szz):
    """sigma^- + (1 - w) sigma^+ of an effective stress: principal parts in the plane, szz apart."""
    mean = 0.5 * (sxx + syy)
    half = 0.5 * (sxx - syy)
    r = math.sqrt(half * half + sxy * sxy)
    l1 = mean + r
    l2 = mean - r
    k1 = l1 if l1 < 0.0 else (1.0 - w) * l1
    k2 = l2 if l2 < 0.0 else (1.0 - w) * l2
    kz = szz if szz < 0.0 else (1.0 - w) * szz
    m = 0.5 * (k1 + k2)
    if r > 0.0:
        f = 0.5 * (k1 - k2) / r   # the deviator's direction (half, -half, sxy) / r kept
    else:
        f = 0.0
    return (m + f * half, m - f * half, f * sxy, kz)


@nb.njit(cache=True, inline="always")
def begin_point(p, stress, eff, crack, damage):
    """Before the material's update of failed point ``p``: put its effective stress where the
    update reads it. Returns (state, the transmitted stress at the start): state 0 intact,
    1 softening (the material updates the effective stress), 2 released (elastic)."""
    old = (stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3])
    if damage[p] < 1.0:
        return 0, old
    for k in range(4):
        stress[p, k] = eff[p, k]
    if crack[p, 0] >= crack[p, 1]:
        return 2, old
    return 1, old


@nb.njit(cache=True)
def _fail(p, stress, eff, crack, damage, fp):
    """Point ``p`` fails: damage capped at 1, its release range, its effective stress."""
    sxx, syy, sxy, szz = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
    damage[p] = 1.0   # its release starts with the next increment
    seq = _von_mises(sxx, syy, sxy, szz)
    room = fp[_SPECIFIC] - _energy_density(fp[_E], fp[_NU], sxx, syy, sxy, szz)
    crack[p, 0] = 0.0
    crack[p, 1] = 2.0 * room / seq if room > 0.0 and seq > 0.0 else 0.0
    for k in range(4):
        eff[p, k] = stress[p, k]


@nb.njit(cache=True)
def _soften(p, phase, old, eq0, work0, stress, de, eps_eq, work, eff, crack, fwork, fp):
    """A failed point after the material's update of its effective stress: the release of its
    tension and its fracture work (module doc). ``old``: its transmitted stress at the start."""
    E, nu = fp[_E], fp[_NU]
    sxx, syy, sxy, szz = stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3]
    for k in range(4):
        eff[p, k] = stress[p, k]
    if phase == 1:
        crack[p, 0] += eps_eq[p] - eq0
    # The run counts a per-volume field times the particle's current volume, which this step
    # scaled by 1 + tr(de) (pmpm.core.kernels.transfer). An opening crack inflates a failed
    # point's volume by its opening strain, which would inflate the energy it already holds:
    # its plastic work is frozen in joules from failure (its dissipation since is fracture work,
    # not counted twice; base.keep_work_in_joules leaves failed points to this line) and its
    # fracture work holds its joules plus this step's.
    inflate = 1.0 / (1.0 + de[p, 0] + de[p, 1])
    work[p] = work0 * inflate
    w = 1.0
    if crack[p, 0] < crack[p, 1]:
        w = crack[p, 0] / crack[p, 1]
    nxx, nyy, nxy, nzz = release(w, sxx, syy, sxy, szz)
    stress[p, 0], stress[p, 1], stress[p, 2], stress[p, 3] = nxx, nyy, nxy, nzz
    power = 0.5 * ((old[0] + nxx) * de[p, 0] + (old[1] + nyy) * de[p, 1] + (old[2] + nxy) * de[p, 2])
    # in joules: V_new (power - U_new) + V_old U_old, with the stored energy's own volume
    fwork[p] = ((fwork[p] + _energy_density(E, nu, old[0], old[1], old[2], old[3])) * inflate
                + power - _energy_density(E, nu, nxx, nyy, nxy, nzz))


@nb.njit(cache=True, inline="always")
def elastic_point(p, stress, de, plane_strain, E, nu):
    """The effective stress of a released point advances elastically (its plasticity frozen)."""
    if plane_strain:
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        tr = de[p, 0] + de[p, 1]
        stress[p, 0] += lam * tr + 2 * mu * de[p, 0]
        stress[p, 1] += lam * tr + 2 * mu * de[p, 1]
        stress[p, 2] += mu * de[p, 2]
        stress[p, 3] += lam * tr
    else:
        c = E / (1 - nu * nu)
        stress[p, 0] += c * (de[p, 0] + nu * de[p, 1])
        stress[p, 1] += c * (de[p, 1] + nu * de[p, 0])
        stress[p, 2] += c * 0.5 * (1 - nu) * de[p, 2]


# -- the passes around the material's own kernel --------------------------------------------
@nb.njit(cache=True)
def prelude(stress, de, eps_eq, work, mat_ids, which, plane_strain, fp, damage, crack, eff):
    """Before the material's plain kernel: each failed point's effective stress put where the
    kernel reads it, a released point's advanced elastically here. Returns the kernel's
    material ids (0: update, -1: leave alone) and what :func:`epilogue` needs: each point's
    state (-1: another material's), transmitted stress, eps_p_eq and plastic work before."""
    n = stress.shape[0]
    ids = np.empty(n, np.int32)
    phase = np.empty(n, np.int8)
    old = np.empty((n, 4))
    eq0 = np.empty(n)
    work0 = np.empty(n)
    E, nu = fp[_E], fp[_NU]
    for p in range(n):
        if which >= 0 and mat_ids[p] != which:
            ids[p] = -1
            phase[p] = -1
            continue
        ph, o = begin_point(p, stress, eff, crack, damage)
        phase[p] = ph
        for k in range(4):
            old[p, k] = o[k]
        eq0[p] = eps_eq[p]
        work0[p] = work[p]
        if ph == 2:   # released: elastic in its effective stress, no plasticity
            elastic_point(p, stress, de, plane_strain, E, nu)
            ids[p] = -1
        else:
            ids[p] = 0
    return ids, phase, old, eq0, work0


@nb.njit(cache=True)
def epilogue(phase, old, eq0, work0, stress, de, eps_eq, work, eff, crack, damage, fwork, fp, index):
    """After the material's plain kernel: the void growth index of the intact points (written
    out here: through an inlined point function numba made this loop several times slower),
    the failure of those reaching 1, the release and fracture work of the failed ones
    (functions of their own: rare). ``index`` is ``damage`` itself for the local criterion;
    with a characteristic length it is the local index (field ``vgm_index``), and the points
    fail in :func:`fail_where` when its nonlocal average reaches 1 (pmpm.physics.fracture_nonlocal)."""
    local = fp[_NONLOCAL] == 0.0
    for p in range(stress.shape[0]):
        ph = phase[p]
        if ph < 0:    # another material's point
            continue
        if ph == 0:   # intact
            deq = eps_eq[p] - eq0[p]
            if deq > 0.0:
                index[p] += deq / fracture_strain(fp, triaxiality(stress[p, 0], stress[p, 1], stress[p, 2],
                                                                  stress[p, 3]))
                if local and index[p] >= 1.0:
                    _fail(p, stress, eff, crack, damage, fp)
        else:
            _soften(p, ph, old[p], eq0[p], work0[p], stress, de, eps_eq, work, eff, crack, fwork, fp)


@nb.njit(cache=True)
def fail_where(average, index, mat_ids, which, stress, eff, crack, damage, fp):
    """The nonlocal criterion's decision: each intact point of the material (``which``; -1:
    every point) fails where both its own void growth index (``index``) and the index's nonlocal
    average over l* (``average``, computed by pmpm.physics.fracture_nonlocal) have reached 1: the
    criterion exceeded at the point and over l* around it (Kanvinde and Deierlein's condition).
    The average alone would also fail the points beside a crack whose own index is below 1 (the
    average spreads the crack path's index over l*): the failed band would widen with l* / h
    and dissipate more than G_f per unit crack area (docs/fracture.md). An intact point's damage
    is the smaller of the two. Returns the count of points that failed."""
    count = 0
    for p in range(stress.shape[0]):
        if (which >= 0 and mat_ids[p] != which) or damage[p] >= 1.0:
            continue
        if average[p] >= 1.0 and index[p] >= 1.0:
            _fail(p, stress, eff, crack, damage, fp)
            count += 1
        else:
            damage[p] = max(min(average[p], index[p]), 0.0)
    return count


# -- the NumPy reference twin ----------------------------------------------------------------
def triaxiality_reference(stress):
    """sigma_m / sigma_eq of (N, 4) stresses with NumPy's eigenvalues (0 where stress-free)."""
    s = np.asarray(stress, dtype=np.float64)
    full = np.zeros((len(s), 3, 3))
    full[:, 0, 0], full[:, 1, 1], full[:, 2, 2] = s[:, 0], s[:, 1], s[:, 3]
    full[:, 0, 1] = full[:, 1, 0] = s[:, 2]
    dev = full - np.trace(full, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    seq = np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(seq > 0, np.trace(full, axis1=1, axis2=2) / 3 / np.where(seq > 0, seq, 1), 0.0)


def _release_reference(w, s):
    """sigma^- + (1 - w) sigma^+ by an eigendecomposition of the in-plane stress."""
    vals, vecs = np.linalg.eigh(np.array([[s[0], s[2]], [s[2], s[1]]]))
    vals = np.where(vals < 0, vals, (1 - w) * vals)
    t = vecs @ np.diag(vals) @ vecs.T
    return np.array([t[0, 0], t[1, 1], t[0, 1], s[3] if s[3] < 0 else (1 - w) * s[3]])


def fracture_point_reference(phase, old, new, de, deq, damage, crack, fwork, settings, E, nu, length):
    """One point's epilogue in NumPy (the twin of :func:`epilogue`), on copies.

    Parameters
    ----------
    phase : int
        0 intact, 1 softening, 2 released (as :func:`begin_point`).
    old, new : array (4,)
        Transmitted stress at the start; the material's updated (effective) stress.
    de : array (3,)
    deq : float
        Equivalent plastic strain of the increment.
    damage, crack, fwork : float, array (2,), float

    Returns
    -------
    (stress, damage, crack, fwork) after the increment.
    """
    crack = np.array(crack, dtype=np.float64)
    new = np.asarray(new, dtype=np.float64)
    g = settings["fracture_energy"] / length

    def energy(s):
        sv = np.array([[s[0], s[2], 0], [s[2], s[1], 0], [0, 0, s[3]]])
        strain = ((1 + nu) * sv - nu * np.trace(sv) * np.eye(3)) / E
        return 0.5 * np.sum(sv * strain)

    if phase == 0:
        T = triaxiality_reference(new[None])[0]
        if deq > 0 and T > CUTOFF:
            damage += deq / (settings["eta"] * np.exp(-1.5 * T))
        if damage >= 1.0:
            damage = 1.0
            seq = np.sqrt(0.5 * ((new[0] - new[1]) ** 2 + (new[1] - new[3]) ** 2 + (new[3] - new[0]) ** 2)
                          + 3 * new[2] ** 2)
            room = g - energy(new)
            crack = np.array([0.0, 2 * room / seq if room > 0 and seq > 0 else 0.0])
        return new.copy(), damage, crack, fwork
    if phase == 1:
        crack[0] += deq
    w = min(1.0, crack[0] / crack[1]) if crack[1] > 0 else 1.0
    out = _release_reference(w, new)
    fwork = ((fwork + energy(old)) / (1 + de[0] + de[1]) + 0.5 * np.dot(np.asarray(old)[:3] + out[:3], de)
             - energy(out))
    return out, damage, crack, fwork
