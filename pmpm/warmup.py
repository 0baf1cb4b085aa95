"""Compile (and cache) pmpm's numba kernels from one process.

MPI ranks that start together would otherwise each compile, and may race writing the same
cache entry. ``setup.sh`` runs this once; ``python -m pmpm.warmup`` does it by hand.
"""
import logging
import time

logger = logging.getLogger(__name__)


def warm_kernels(verbose=False):
    """Compile every kernel specialisation the shipped cases and tests use (fills the cache)."""
    from mpi4py import MPI
    from pmpm.build import build_solver
    from pmpm.benchmarks.block import block_scene
    for shape in ("cubic", "quadratic", "linear"):
        for scheme in ("musl", "usl", "usf", "mls"):
            for loads in (False, True):
                s = build_solver(block_scene(400, shape, scheme, gravity=loads, force=loads), MPI.COMM_SELF)
                for _ in range(2):
                    s.step()
                if verbose:
                    print(f"warm: {shape} {scheme} loads={loads}")
    # the shipped cases' extra specialisations: plasticity, and multi-field contact
    from pmpm.scene.config import load_scene
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for case, variant in (("portal_frame.toml", "elastoplastic"),
                          ("disks_contact.toml", None),   # multi-field contact
                          ("fracture_notched_plate.toml", None),   # the ductile fracture passes
                          # CPDI (cubic) with neo_hookean and with Green-Naghdi
                          ("hard/cantilever_large_rotation.toml", "neo_hookean_h0.25"),
                          ("hard/cantilever_large_rotation.toml", "linear_elastic_h0.25")):
        path = os.path.join(root, "cases", case)
        if os.path.exists(path):
            s = build_solver(load_scene(path, variant)[0], MPI.COMM_SELF)
            for _ in range(2):
                s.step()
    # the implicit integrator's kernels (elastic and plastic tangents, dynamics and statics)
    from pmpm.benchmarks.implicit import warm_implicit
    warm_implicit()


def warm_up():
    """Run a tiny scene through every kernel combination the shipped cases use."""
    t0 = time.perf_counter()
    try:
        import pmpm.core.solver  # noqa: F401
    except ImportError:  # the solver is not installed yet (early set-up)
        return 0.0
    warm_kernels()
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"pmpm.warmup: kernels compiled in {warm_up():.1f} s")
