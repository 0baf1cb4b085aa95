"""pmpm: explicit dynamic Material Point Method for elastoplastic structures, over MPI.

Public API::

    from pmpm import load_scene, Solver, Run
    scene = load_scene("cases/bar.toml")[0]
    Run(scene).execute()
"""
__version__ = "0.1.0"

__all__ = ["__version__", "load_scene", "Solver", "Run"]

from pmpm.jitcache import use_versioned_cache as _use_versioned_cache  # noqa: E402

# before any kernel module is imported: numba's cache, one directory per version of the kernel
# sources, so that no stale kernel can load (pmpm/jitcache.py)
_use_versioned_cache()


def __getattr__(name):
    # lazy: `pmpm --help` and scene validation must not pay for numba compilation
    if name == "load_scene":
        from pmpm.scene.config import load_scene
        return load_scene
    if name == "Solver":
        from pmpm.core.solver import Solver
        return Solver
    if name == "Run":
        from pmpm.run import Run
        return Run
    raise AttributeError(name)
