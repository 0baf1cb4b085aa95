"""What every dataset of a results file means: SI units and a one-line description.

The writer (:class:`pmpm.io.hdf5.OutputFile`) stores ``units`` and ``description``
attributes on every dataset from these tables, so a file read years later, by h5py,
ParaView or another program, says what its numbers are without pmpm's source.  Units
are SI strings (``"m"``, ``"m/s"``, ``"Pa"``, ``"J"``); ``"1"`` means dimensionless
(also for counts, indices and ids).  Pmpm is 2-D with an out-of-plane thickness per
particle, so mass, volume and energies are those of the 3-D body (kg, m^3, J).
"""

from __future__ import annotations

import pmpm.physics  # noqa: F401  (registers the energy terms of the materials and effects)
from pmpm.core.effects import energy_terms

__all__ = ["FIELDS", "HISTORY", "ENERGIES", "meta", "UNKNOWN"]

#: units of a quantity no table describes (a test asserts a real run's file has none)
UNKNOWN = "unknown"

#: frame fields ``/frames/<name>``: name -> (units, description)
FIELDS = {
    "time": ("s", "simulation time of each frame (NaN: a frame cut short by a crash)"),
    "step": ("1", "step number of each frame"),
    "id": ("1", "particle id; row i of every frame field is the particle with id i"),
    "x": ("m", "current position x, y"),
    "x0": ("m", "initial position x, y"),
    "v": ("m/s", "velocity vx, vy"),
    "m": ("kg", "mass"),
    "vol": ("m^3", "current volume: area times out-of-plane thickness"),
    "stress": ("Pa", "Cauchy stress sxx, syy, sxy, szz (szz = 0 in plane stress)"),
    "back_stress": ("Pa", "back stress of kinematic hardening, xx, yy, xy, zz"),
    "strain": ("1", "accumulated small strain exx, eyy, gxy; gxy is the ENGINEERING shear "
                    "strain (2 exy)"),
    "F": ("1", "deformation gradient Fxx, Fxy, Fyx, Fyy, Fzz (identity at the start)"),
    "vol0": ("m^3", "initial volume (vol = vol0 det F where F is kept)"),
    "eps_p": ("1", "plastic strain epxx, epyy, gpxy (gpxy engineering: 2 epxy)"),
    "eps_p_eq": ("1", "equivalent plastic strain (sum of the plastic multiplier increments)"),
    "plastic_work": ("J/m^3", "plastic work per unit volume"),
    "damage": ("1", "ductile damage D = sum d(eps_p_eq) / eps_f(triaxiality) (with a characteristic "
                    "length: its average over l*); 1: the point has failed (docs/fracture.md)"),
    "vgm_index": ("1", "the point's own void growth index sum d(eps_p_eq) / eps_f(triaxiality), whose "
                       "average over the characteristic length decides failure (docs/fracture.md)"),
    "fracture_work": ("J/m^3", "energy a failed point dissipated since its failure, per unit volume"),
    "crack_strain": ("1", "kappa (equivalent plastic strain since failure) and kappa_u (where the "
                          "tension is fully released) of a failed point"),
    "effective_stress": ("Pa", "the failed point's undamaged stress sxx, syy, sxy, szz; it transmits "
                               "the compressive part and (1 - kappa/kappa_u) of the tensile part"),
    "mat": ("1", "index of the particle's material in the scene (-1: particle removed)"),
    "body": ("1", "index of the body the particle was created in (-1: particle removed)"),
}

#: columns of each track's history row ``/history/<track>``: name -> (units, description)
HISTORY = {
    "time": ("s", "time of each history row"),
    "ux": ("m", "displacement x - x0"),
    "uy": ("m", "displacement y - y0"),
    "vx": ("m/s", "velocity x"),
    "vy": ("m/s", "velocity y"),
    "x": ("m", "position x"),
    "y": ("m", "position y"),
    "sxx": ("Pa", "stress xx"),
    "syy": ("Pa", "stress yy"),
    "sxy": ("Pa", "shear stress xy"),
}

#: energy columns ``/energies/<name>``: name -> (units, description)
ENERGIES = {
    "time": ("s", "time of each energy row"),
    "kinetic": ("J", "kinetic energy 1/2 m v^2"),
    "strain_energy": ("J", "recoverable elastic strain energy 1/2 sigma : C^-1 : sigma V "
                           "(not the strain field /frames/strain)"),
    "internal_work": ("J", "integrated stress power: strain energy plus dissipation"),
    "external_work": ("J", "work of loads, boundary motion and ground motion"),
    "total": ("J", "kinetic + internal_work + damping_work + viscous_damping_work + removed_energy; equals external_work plus the "
                   "initial kinetic energy when the run conserves energy"),
    "numerical_loss": ("J", "energy lost to the discretisation (numerical damping): initial energy "
                            "+ external_work - kinetic - strain_energy - plastic_work - damping_work; "
                            "positive is lost, negative gained"),
}
#: the registered energy terms (pmpm.core.effects: plastic work, damping works, removed energy,
#: ...), each described where it is registered
ENERGIES.update({t.name: ("J", t.meaning) for t in energy_terms()})


def meta(table, name):
    """Return ``(units, description)`` of ``name`` in ``table``, or ``(UNKNOWN, "")``.

    Parameters
    ----------
    table : dict
        :data:`FIELDS`, :data:`HISTORY` or :data:`ENERGIES` (or a caller's own).
    name : str

    Returns
    -------
    tuple of str
    """
    entry = table.get(name)
    if entry is None:
        return UNKNOWN, ""
    if isinstance(entry, str):
        return entry, ""
    return tuple(entry)
