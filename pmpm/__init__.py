"""pmpm: explicit dynamic Material Point Method for elastoplastic structures, over MPI.

Public API (docs/api.md)::

    import pmpm
    res = pmpm.run("cases/bar.toml", overrides={"solver.end_time": 2.5})
    res.histories["free_end"]["ux"]
    pmpm.load_results("bar_results/bar.h5")

and the pieces: ``load_scene``, ``Solver``, ``Run``.
"""
__version__ = "0.1.0"

__all__ = ["__version__", "run", "load_results", "Result", "load_scene", "Solver", "Run"]

from pmpm.jitcache import use_versioned_cache as _use_versioned_cache  # noqa: E402

# before any kernel module is imported: numba's cache, one directory per version of the kernel
# sources, so that no stale kernel can load (pmpm/jitcache.py)
_use_versioned_cache()

from pmpm.mpidefaults import choose_mpi_defaults as _choose_mpi_defaults  # noqa: E402

# before MPI is initialised: Open MPI's waiting ranks yield the core unless the user said
# otherwise (pmpm/mpidefaults.py)
_choose_mpi_defaults()


def __getattr__(name):
    # lazy: `pmpm --help` and scene validation must not pay for numba compilation
    if name == "load_scene":
        from pmpm.scene.config import load_scene
        return load_scene
    if name == "Solver":
        from pmpm.core.solver import Solver
        return Solver
    if name == "Run":
        from pmpm.runner import Run
        return Run
    if name in ("run", "load_results", "Result"):
        from pmpm import api
        return getattr(api, name)
    raise AttributeError(name)
