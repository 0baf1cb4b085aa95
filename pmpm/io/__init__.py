"""Output of pmpm runs: the HDF5 results file, checkpoints, XDMF, VTU export, plots.

- :mod:`pmpm.io.hdf5`: :class:`OutputFile`, the one-per-run HDF5 file (frames in
  particle-id order, track histories, energies and other series groups, SI units on
  every dataset), written collectively with the ``"mpio"`` driver or gathered to
  rank 0 (``"gather"``); readers for it.
- :mod:`pmpm.io.schema`: the units and meaning of every dataset and column.
- :mod:`pmpm.io.checkpoint`: :func:`write_checkpoint` / :func:`read_checkpoint`,
  two alternating restart files, readable on any rank count.
- :mod:`pmpm.io.xdmf`: :func:`write_xdmf`, the sidecar ParaView and meshio open, over
  per-frame virtual datasets (:func:`write_views`); docs/output.md says why.
- :mod:`pmpm.io.export`: :func:`export` to a VTU series (meshio).
- :mod:`pmpm.io.plot`: :func:`plot_results`, :func:`plot_deformed`.

matplotlib and meshio are imported inside the functions that need them: they cost
most of a second to import, which every rank of a run would otherwise pay.
"""

import logging

from pmpm.io.checkpoint import checkpoint_paths, latest_checkpoint, read_checkpoint, write_checkpoint
from pmpm.io.export import export
from pmpm.io.hdf5 import (
    OutputFile,
    check_results_file,
    read_attrs,
    read_energies,
    read_frame,
    read_history,
    read_series,
)
from pmpm.io.plot import energy_balance_error, plot_deformed, plot_results
from pmpm.io.xdmf import write_views, write_xdmf

__all__ = [
    "OutputFile",
    "read_attrs",
    "read_frame",
    "read_history",
    "read_energies",
    "read_series",
    "check_results_file",
    "write_checkpoint",
    "read_checkpoint",
    "checkpoint_paths",
    "latest_checkpoint",
    "write_xdmf",
    "write_views",
    "export",
    "plot_results",
    "plot_deformed",
    "energy_balance_error",
]

logger = logging.getLogger(__name__)

