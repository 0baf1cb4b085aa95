"""Which of a run's materials the step may update (and sum the energy of) in one pass.

A material's stress kernel runs over every particle and updates those of its own id
(``mat_ids == which``), so a scene of k materials pays k passes over the particles per step,
and k more per energy sum. Scenes often hold materials that differ in what the stress update
does not read: the frame front end (pmpm.scene.frame) makes a copy of the steel per lumped
mass, differing only in its density (the mass is in the particles, set once), which gives the
three-storey frame ten materials of one law. Such materials update every particle exactly as
one material of theirs with ``which = -1`` does (the same kernel with the same parameters on
the same row: the same bits), so the solver runs that one pass.
"""
import numpy as np

__all__ = ["same_law", "single_law", "same_elastic_energy"]

#: attributes of a material its stress update never reads: its scene key (a name for
#: messages) and its density (the particles' masses are set from it once, at the start; the
#: solver reads each material's wave speed from the material itself)
NOT_READ_BY_THE_UPDATE = ("key", "density")


def _equal(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype \
            and np.array_equal(a, b)
    try:
        same = a == b
    except Exception:   # an object that cannot compare: not shown to be equal
        return False
    return same is True or (isinstance(same, (bool, np.bool_)) and bool(same))


def same_law(a, b):
    """True when materials ``a`` and ``b`` update a particle's stress and state identically:
    the same class and every attribute equal but those of ``NOT_READ_BY_THE_UPDATE``. An
    attribute that cannot be compared counts as a difference (the safe answer: separate passes)."""
    if type(a) is not type(b):
        return False
    va = {k: v for k, v in vars(a).items() if k not in NOT_READ_BY_THE_UPDATE}
    vb = {k: v for k, v in vars(b).items() if k not in NOT_READ_BY_THE_UPDATE}
    return va.keys() == vb.keys() and all(_equal(va[k], vb[k]) for k in va)


def single_law(materials):
    """True when every material of ``materials`` has the law of the first (one pass with
    ``which = -1`` updates all the particles)."""
    return all(same_law(materials[0], m) for m in materials[1:])


def same_elastic_energy(materials):
    """True when the recoverable energy 1/2 sigma : C^-1 : sigma of every material's particles
    is one sum over all particles: no material computes its energy from F (hyperelastic) and
    all share E and nu (the only constants of that energy)."""
    return (not any(m.needs_deformation_gradient for m in materials)
            and len({(m.E, m.nu) for m in materials}) == 1)
