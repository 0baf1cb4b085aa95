"""Compile (and cache) pmpm's numba kernels from one process.

MPI ranks that start together would otherwise each compile, and may race writing the same
cache entry. ``setup.sh`` runs this once; ``python -m pmpm.warmup`` does it by hand.
"""
import logging
import time

logger = logging.getLogger(__name__)


def warm_up():
    """Run a tiny scene through every kernel combination the shipped cases use."""
    t0 = time.perf_counter()
    try:
        from .bench import warm_kernels
    except ImportError:  # the solver is not installed yet (early set-up)
        return 0.0
    warm_kernels()
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"pmpm.warmup: kernels compiled in {warm_up():.1f} s")
