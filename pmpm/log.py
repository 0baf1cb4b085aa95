"""Rank-aware logging: rank 0 speaks at INFO, the others only warn (the dedalus.cfg pattern)."""
import logging
import sys

__all__ = ["setup_logging"]


def setup_logging(rank=0, quiet=False):
    """Configure the ``pmpm`` logger for this rank."""
    level = logging.WARNING if (rank != 0 or quiet) else logging.INFO
    handler = logging.StreamHandler(sys.stdout if rank == 0 else sys.stderr)
    fmt = "%(message)s" if rank == 0 else f"[rank {rank}] %(levelname)s %(message)s"
    handler.setFormatter(logging.Formatter(fmt))
    root = logging.getLogger("pmpm")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False
