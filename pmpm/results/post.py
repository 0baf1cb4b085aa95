"""After a run: the section and reaction tables as CSV files and plots (rank 0 only).

``<stem>_section_<name>.csv`` has columns ``t, N, V, M`` (s, N, N, N m) and
``<stem>_reaction_<name>.csv`` ``t, Rx, Ry, M``, where ``<stem>`` is the results file's
(``<scene>[_<variant>]``). Names were checked to be file names when the scene was read.
"""
import json
import logging
import os

import h5py
import numpy as np

from pmpm.io import ownership
from pmpm.results.recorder import REACTION_COLUMNS, SECTION_COLUMNS, first_fracture, read_tables
from pmpm.io.plot import scene_stem
from pmpm.results import plots
from pmpm.results.capacity import write_capacity

__all__ = ["read_tables", "write_csv", "structural_outputs"]
logger = logging.getLogger(__name__)


def write_csv(h5_path, outdir, tables=None):
    """The CSV files of every section and reaction table of ``h5_path``; returns their paths."""
    tables = tables or read_tables(h5_path)
    stem = os.path.splitext(os.path.basename(h5_path))[0]
    paths = []
    with ownership.writing(scene_stem(h5_path)):  # claimed before written (pmpm.io.ownership)
        for group, kind, columns in (("sections", "section", SECTION_COLUMNS),
                                     ("reactions", "reaction", REACTION_COLUMNS)):
            for name, table in tables[group].items():
                path = ownership.claim(os.path.join(outdir, f"{stem}_{kind}_{name}.csv"))
                header = ",".join(("t",) + columns[1:])
                np.savetxt(path, np.column_stack([table[c] for c in columns]), delimiter=",",
                           header=header, comments="", fmt="%.9g")
                paths.append(path)
        if tables.get("fracture"):
            # the first fracture of each member (body) that fractured, earliest first
            path = ownership.claim(os.path.join(outdir, f"{stem}_first_fracture.csv"))
            with open(path, "w") as f:
                f.write("member,t\n")
                for name, t in first_fracture(tables["fracture"]).items():
                    f.write(f"{name},{t:.9g}\n")
            paths.append(path)
    return paths


def _hysteresis_spec(h5_path):
    with h5py.File(h5_path, "r") as f:
        scene = json.loads(f.attrs["scene"]) if "scene" in f.attrs else {}
    return (scene.get("output") or {}).get("hysteresis")


def structural_outputs(h5_path, outdir):
    """CSV files and plots of the structural results of one run (nothing if it has none)."""
    tables = read_tables(h5_path)
    if not tables["sections"] and not tables["reactions"]:
        return []
    stem = os.path.splitext(os.path.basename(h5_path))[0]

    def png(kind):  # claimed before it is drawn (pmpm.io.ownership)
        return ownership.claim(os.path.join(outdir, f"{stem}_{kind}.png"))

    with ownership.writing(scene_stem(h5_path)):
        made = write_csv(h5_path, outdir, tables)
        if tables["sections"]:
            made.append(plots.plot_sections(tables["sections"], png("sections"), stem))
            if any("Mp" in s["attrs"] for s in tables["sections"].values()):
                made.append(plots.plot_utilisation(tables["sections"], png("utilisation"), stem))
                made.append(plots.plot_hinge_map(h5_path, tables["sections"], png("hinges"), stem))
        if tables["reactions"]:
            made.append(plots.plot_reactions(tables["reactions"], png("reactions"), stem))
            made += write_capacity(h5_path, outdir)
        spec = _hysteresis_spec(h5_path)
        if spec and tables["reactions"]:
            made.append(plots.plot_hysteresis(h5_path, tables["reactions"], spec, png("hysteresis"), stem))
    return made
