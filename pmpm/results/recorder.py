"""Time histories of the section cuts and support reactions a scene asks for, and of the
failed points of each body (member) in a run with ductile fracture.

Sampled at the history times (``output.history_interval``) with ONE allreduce per sample for
all cuts and reactions together; a scene without cuts and reactions has no recorder at all.
Rows are buffered and written with the other histories (``/sections/<name>`` and
``/reactions/<name>`` in the HDF5 file, columns with SI units as attributes). With ductile
fracture (the ``fracture`` effect, pmpm.physics.fracture_record) each body's count of failed
points is sampled in the same reduction into ``/fracture/<body>`` (``time``, ``failed``): a
frame's members are its bodies, so :func:`first_fracture` gives each member's first fracture at
the history's resolution (the run summary's ``first_fracture`` has the step's).
"""
import logging

import h5py
import numpy as np

__all__ = ["StructuralRecorder", "read_tables", "first_fracture", "SECTION_COLUMNS", "REACTION_COLUMNS",
           "FRACTURE_COLUMNS", "UNITS"]
logger = logging.getLogger(__name__)

SECTION_COLUMNS = ("time", "N", "V", "M")
REACTION_COLUMNS = ("time", "Rx", "Ry", "M")
FRACTURE_COLUMNS = ("time", "failed")
UNITS = {"time": "s", "N": "N", "V": "N", "M": "N m", "Rx": "N", "Ry": "N", "failed": "1"}


class StructuralRecorder:
    """Samples the solver's section cuts and reactions.

    Parameters
    ----------
    solver : Solver
        Its effects ``sections`` (pmpm.results.sections.SectionCuts) and ``reactions``
        (pmpm.results.reactions.Reactions), either or both.
    """

    def __init__(self, solver):
        self.solver = solver
        sections = solver.effect("sections")
        self.cuts = sections.cuts if sections is not None else []
        self.reactions = solver.effect("reactions")
        self.reaction_names = self.reactions.names if self.reactions is not None else []
        fracture = solver.effect("fracture")
        self.fracture_bodies = list(fracture.body_names) if fracture is not None else []
        self._phi, self._phi_of = None, None
        # the cuts' band particles by id (all ranks), found once: _band_table
        self._band = self._band_table() if self.cuts else None
        self.rows = []   # (t, sections (n, 3), reactions (m, 3))
        if self.reactions is not None:
            self.reactions.since = solver.t  # impulses are summed from the start (or restart)

    def _band_table(self):
        """(ids, phi): every particle in any cut's band, over all ranks, sorted by id, with its
        band fraction in each cut (n_band, n_cuts). A band fraction depends on the particle's
        initial position and body only, so it is found once, at the start (collective)."""
        p, nc = self.solver.particles, len(self.cuts)
        phi = (np.stack([c.weights(p["x0"], p["body"]) for c in self.cuts], axis=1)
               if p.n else np.zeros((0, nc)))
        keep = phi.any(axis=1)
        parts = self.solver.comm.allgather((p["id"][keep], phi[keep]))
        ids = np.concatenate([a for a, _ in parts])
        phi = np.concatenate([b for _, b in parts]).reshape(-1, nc)
        order = np.argsort(ids)
        return ids[order], phi[order]

    def _weights(self):
        """Band fractions of every cut for the local particles, [(rows, phi)] per cut, rows in
        increasing order: looked up by id in the band table again only when the particle arrays
        were replaced (sorting, migration, removal), which costs one search of the band's few
        ids instead of the cuts' geometry over every particle."""
        p = self.solver.particles
        if not self.cuts:
            return []
        if self._phi_of is not p["id"]:
            band_ids, band_phi = self._band
            ids = p["id"]
            rows = np.zeros(0, dtype=np.int64)
            if len(band_ids) and len(ids):
                at = np.minimum(np.searchsorted(band_ids, ids), len(band_ids) - 1)
                rows = np.flatnonzero(band_ids[at] == ids)
            phi = band_phi[at[rows]] if rows.size else np.zeros((0, len(self.cuts)))
            self._phi = [(rows[phi[:, k] > 0], phi[phi[:, k] > 0, k]) for k in range(len(self.cuts))]
            self._phi_of = ids
        return self._phi

    def local_sections(self):
        """(n_cuts, 3) this rank's partial N, V, M."""
        p = self.solver.particles
        out = np.zeros((len(self.cuts), 3))
        for k, (cut, (idx, phi)) in enumerate(zip(self.cuts, self._weights())):
            out[k] = cut.resultants(p["x"][idx], p["stress"][idx], p["vol"][idx], phi)
        return out

    def local_rows(self):
        """This rank's partial sums of one sample, flat: the cuts' N, V, M, then the reactions'
        impulse sums (a caller may reduce them with other figures in one reduction)."""
        local = [self.local_sections()]
        if self.reactions is not None:
            local.append(self.reactions.sums.copy())
        if self.fracture_bodies:
            local.append(self.local_failed())
        return np.concatenate(local).ravel()

    def local_failed(self):
        """(n_bodies, 3): this rank's count of failed points (damage 1) per body, in the first
        column (rows of three, as the other figures of the reduction)."""
        p = self.solver.particles
        out = np.zeros((len(self.fracture_bodies), 3))
        damage = p.fields.get("damage")
        if damage is not None and p.n:
            failed = damage[:p.n] >= 1.0
            body = p["body"][:p.n][failed]
            out[:, 0] = np.bincount(body[body >= 0], minlength=len(self.fracture_bodies))[:len(self.fracture_bodies)]
        return out

    def sample(self, summed=None):
        """Record one row at the solver's time; returns (sections, reactions) arrays.
        ``summed``: :meth:`local_rows` already summed over the ranks, else summed here."""
        s = self.solver
        nc = len(self.cuts)
        if summed is None:
            summed = s.decomp.allreduce_sum(self.local_rows())
        total = np.asarray(summed).reshape(-1, 3)
        sections = total[:nc]
        nr = len(self.reaction_names)
        reactions = (self.reactions.take(s.t, None, summed=total[nc:nc + nr])
                     if self.reactions is not None else np.zeros((0, 3)))
        failed = total[nc + nr:nc + nr + len(self.fracture_bodies), 0].copy()
        self.rows.append((s.t, sections, reactions, failed))
        return sections, reactions

    def attributes(self):
        """{group path: attrs}: what each table describes (geometry, capacities, points)."""
        out = {}
        for cut in self.cuts:
            out[f"sections/{cut.name}"] = {"center": cut.center, "normal": cut.normal,
                                           "width": cut.width, **(cut.properties or {})}
        for k, name in enumerate(self.reaction_names):
            out[f"reactions/{name}"] = {"moment_about": self.reactions.points[k]}
        for name in self.fracture_bodies:
            out[f"fracture/{name}"] = {"body": name}
        return out

    def drain(self):
        """{group path: {column: array}} of the buffered rows (then forgotten)."""
        if not self.rows:
            return {}
        t = np.array([r[0] for r in self.rows])
        sec = np.array([r[1] for r in self.rows]).reshape(len(t), -1, 3)
        rea = np.array([r[2] for r in self.rows]).reshape(len(t), -1, 3)
        failed = np.array([r[3] for r in self.rows]).reshape(len(t), -1)
        self.rows = []
        out = {}
        for k, cut in enumerate(self.cuts):
            out[f"sections/{cut.name}"] = dict(zip(SECTION_COLUMNS, (t, *sec[:, k].T)))
        for k, name in enumerate(self.reaction_names):
            out[f"reactions/{name}"] = dict(zip(REACTION_COLUMNS, (t, *rea[:, k].T)))
        for k, name in enumerate(self.fracture_bodies):
            out[f"fracture/{name}"] = {"time": t, "failed": failed[:, k]}
        return out


def read_tables(h5_path):
    """{"sections": {name: {column: array, "attrs": dict}}, "reactions": {...}, "fracture": {...}}."""
    out = {"sections": {}, "reactions": {}, "fracture": {}}
    with h5py.File(h5_path, "r") as f:
        for group in out:
            for name, g in f.get(group, {}).items():
                table = {c: g[c][()] for c in g}
                table["attrs"] = {k: v for k, v in g.attrs.items()}
                out[group][name] = table
    return out


def first_fracture(fracture_tables):
    """{body (member) name: the first sampled time at which it has a failed point} from the
    ``fracture`` tables ({name: {"time", "failed"}}), earliest first; members that never
    fracture are left out."""
    first = {}
    for name, table in fracture_tables.items():
        failed = np.asarray(table["failed"]) > 0
        if failed.any():
            first[name] = float(np.asarray(table["time"])[np.argmax(failed)])
    return dict(sorted(first.items(), key=lambda kv: kv[1]))
