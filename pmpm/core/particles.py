"""Material points as a structure of arrays.

``Particles`` is a thin ordered dict of numpy arrays that all share their first dimension.
Everything that moves a particle (sorting, migration, removal, restart) works on every field at
once, so a material's extra state (back stress, plastic strain, ...) travels with the particle
without anyone naming it.
"""
import logging

import numpy as np
from pmpm.core.kernels import is_identity

__all__ = ["Particles", "CORE_FIELDS", "OPTIONAL_FIELDS", "DEFORMATION_FIELDS", "start_deformation"]
logger = logging.getLogger(__name__)

#: fields every particle has: name -> (trailing shape, dtype)
CORE_FIELDS = {
    "id": ((), np.int64),        # global, stable: output is ordered by it
    "x": ((2,), np.float64),     # position
    "x0": ((2,), np.float64),    # initial position (displacements, tracked points)
    "v": ((2,), np.float64),     # velocity
    "m": ((), np.float64),       # mass
    "vol": ((), np.float64),     # current volume (area x out-of-plane thickness)
    "stress": ((4,), np.float64),  # sxx, syy, sxy, szz
    "mat": ((), np.int32),       # index of the particle's material in the scene
    "body": ((), np.int32),      # index of the body it was created in
}


#: fields kept only when the scene asks for them (they cost memory and traffic): ``strain`` by
#: [output] fields, the deformation gradient ``F`` (with ``vol0``) also when a material, the
#: objective rate or the interpolation needs it (pmpm.core.solver.needs_deformation_gradient)
OPTIONAL_FIELDS = {
    "strain": ((3,), np.float64),  # exx, eyy, gxy (engineering shear), accumulated increments
    "F": ((5,), np.float64),       # deformation gradient Fxx, Fxy, Fyx, Fyy, Fzz (identity at start)
    "vol0": ((), np.float64),      # initial volume: vol = vol0 det F where F is kept
}

#: the fields kept together when the deformation gradient is
DEFORMATION_FIELDS = ("F", "vol0")


def start_deformation(particles):
    """Give ``particles`` the deformation gradient of the undeformed state (F = I, vol0 = vol).

    Parameters
    ----------
    particles : Particles
    """
    particles.add_field("F", OPTIONAL_FIELDS["F"][0])
    particles.add_field("vol0", ())
    F = particles["F"]
    F[...] = 0.0
    F[:, 0] = F[:, 3] = F[:, 4] = 1.0
    particles["vol0"][...] = particles["vol"]


class Particles:
    """Structure of arrays of the particles a rank owns.

    Parameters
    ----------
    fields : dict of str -> ndarray
        All arrays share the first dimension (the particle count).
    """

    def __init__(self, fields):
        self.fields = dict(fields)
        sizes = {len(a) for a in self.fields.values()}
        if len(sizes) > 1:
            raise ValueError(f"particle fields disagree in length: {sizes}")

    @classmethod
    def empty(cls, spec):
        """Zero particles with the fields of ``spec`` (name -> (shape, dtype))."""
        return cls({k: np.zeros((0, *shape), dtype) for k, (shape, dtype) in spec.items()})

    @property
    def n(self):
        return len(self.fields["id"])

    def __len__(self):
        return self.n

    def __getitem__(self, name):
        return self.fields[name]

    def __setitem__(self, name, value):
        self.fields[name] = value

    def __contains__(self, name):
        return name in self.fields

    def add_field(self, name, shape, dtype=np.float64, fill=0):
        """Add a zero-filled (or ``fill``) field if it is not there yet."""
        if name not in self.fields:
            self.fields[name] = np.full((self.n, *shape), fill, dtype=dtype)

    def spec(self):
        """name -> (trailing shape, dtype) of every field."""
        return {k: (a.shape[1:], a.dtype) for k, a in self.fields.items()}

    def take(self, index):
        """A new ``Particles`` holding rows ``index`` (integer array or boolean mask)."""
        return Particles({k: np.ascontiguousarray(a[index]) for k, a in self.fields.items()})

    def reorder(self, order):
        """Permute every field (``order`` is a permutation of 0..n-1), one field at a time so
        that at most one field's worth of memory is in flight (the particle arrays are most of a
        run's memory). Gathering into a new array streams its writes; following the
        permutation's cycles in place would save that memory but costs twice the cache misses,
        and a sort after a few particles changed cell shifts every row behind them."""
        if is_identity(order):  # the usual case in solids: nobody changed cell since the last sort
            return
        for k in list(self.fields):
            self.fields[k] = np.take(self.fields[k], order, axis=0)

    @staticmethod
    def concatenate(parts):
        """Join several ``Particles`` with the same fields."""
        keys = parts[0].fields.keys()
        return Particles({k: np.concatenate([p.fields[k] for p in parts]) for k in keys})
