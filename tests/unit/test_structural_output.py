"""The files a run with cuts and reactions writes: HDF5 tables with SI units, the CSV files
``<stem>_section_<name>.csv`` (t, N, V, M) and ``<stem>_reaction_<name>.csv`` (t, Rx, Ry, M),
and the plots (also from ``pmpm plot``)."""
import h5py
import numpy as np
from mpi4py import MPI

from pmpm.io.post import postprocess
from pmpm.runner import Run
from pmpm.scene.config import parse_scene


def _scene(tmp_path):
    data = {"grid": {"cell_size": 0.25, "cells": [12, 6]},
            "materials": {"m": {"type": "smooth_vonmises", "E": 100.0, "nu": 0.3, "density": 1.0,
                                "yield_stress": 1.0, "hardening": 0.05, "smoothness": 10.0}},
            "bodies": [{"name": "col", "shape": "i_section", "material": "m", "start": [1.5, 0.0], "end": [1.5, 1.5],
                        "depth": 0.5, "flange_width": 0.3, "flange_thickness": 0.1, "web_thickness": 0.1}],
            "boundary": [{"name": "base", "type": "fixed", "lower": [0.0, 0.0], "upper": [3.0, 0.0]}],
            "loads": {"forces": [{"lower": [1.0, 1.3], "upper": [2.0, 1.5], "force": [0.01, 0.0]}]},
            "solver": {"end_time": 0.1},
            "output": {"directory": str(tmp_path), "reactions": True, "history_interval": 0.01,
                       "track": [{"name": "top", "point": [1.5, 1.5]}],
                       "hysteresis": {"track": "top"},
                       "section": [{"name": "low", "body": "col", "position": 0.5},
                                   {"name": "seg", "segment": [[1.0, 1.0], [2.0, 1.0]]}]}}
    return parse_scene(data, str(tmp_path / "col.toml"))


def test_tables_csv_and_plots(tmp_path):
    scene = _scene(tmp_path)
    summary = Run(scene, MPI.COMM_SELF).execute()
    made = postprocess([scene], [summary["output"]])
    names = {p.name for p in tmp_path.iterdir()}
    for f in ("col_section_low.csv", "col_section_seg.csv", "col_reaction_base.csv", "col_sections.png",
              "col_reactions.png", "col_utilisation.png", "col_hinges.png", "col_hysteresis.png"):
        assert f in names and str(tmp_path / f) in made, f
    assert (tmp_path / "col_section_low.csv").read_text().splitlines()[0] == "t,N,V,M"
    assert (tmp_path / "col_reaction_base.csv").read_text().splitlines()[0] == "t,Rx,Ry,M"
    with h5py.File(summary["output"]) as f:
        assert f["sections/low/M"].attrs["units"] == "N m" and f["reactions/base/Rx"].attrs["units"] == "N"
        assert f["sections/low"].attrs["Mp"] > f["sections/low"].attrs["My"] > 0   # sigma_y Z > sigma_y S
        csv = np.loadtxt(tmp_path / "col_section_low.csv", delimiter=",", skiprows=1)
        # the CSV carries 9 significant digits (fmt %.9g): relative rounding below 1e-8
        np.testing.assert_allclose(csv[:, 3], f["sections/low/M"][()], rtol=1e-8, atol=0)
        assert len(csv) == len(f["history/time"])
