"""Output of pmpm runs: the HDF5 results file, checkpoints, XDMF, VTU export, plots.

- :mod:`pmpm.io.hdf5`: :class:`OutputFile`, the one-per-run HDF5 file (frames in
  particle-id order, track histories, energies), written collectively with the
  ``"mpio"`` driver or gathered to rank 0 (``"gather"``); readers for it.
- :mod:`pmpm.io.checkpoint`: :func:`write_checkpoint` / :func:`read_checkpoint`,
  two alternating restart files, readable on any rank count.
- :mod:`pmpm.io.xdmf`: :func:`write_xdmf`, the ParaView sidecar.
- :mod:`pmpm.io.export`: :func:`export` to a VTU series (meshio).
- :mod:`pmpm.io.plot`: :func:`plot_results`, :func:`plot_deformed`.

``export`` and the plot functions are imported on first use: matplotlib and meshio
cost most of a second to import, which every rank of a run would otherwise pay.
"""

import importlib
import logging

from .checkpoint import checkpoint_paths, latest_checkpoint, read_checkpoint, write_checkpoint
from .hdf5 import OutputFile, read_attrs, read_energies, read_frame, read_history
from .xdmf import write_xdmf

__all__ = [
    "OutputFile",
    "read_attrs",
    "read_frame",
    "read_history",
    "read_energies",
    "write_checkpoint",
    "read_checkpoint",
    "checkpoint_paths",
    "latest_checkpoint",
    "write_xdmf",
    "export",
    "plot_results",
    "plot_deformed",
    "energy_balance_error",
]

logger = logging.getLogger(__name__)

_LAZY = {
    "export": ".export",
    "plot_results": ".plot",
    "plot_deformed": ".plot",
    "energy_balance_error": ".plot",
}


def __getattr__(name):
    """Import the heavy post-processing functions on first access (PEP 562)."""
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
