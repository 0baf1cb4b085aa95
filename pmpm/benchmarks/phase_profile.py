"""Where a step's time goes: every kernel call of a running solver timed (``pmpm bench
throughput --phases``).

The kernels are wrapped for the duration of the measurement only: the solver calls them through
the ``pmpm.core.kernels`` module and through its materials' ``update_stress`` (or
``update_stress_power``, counted as ``update_stress``), so those are the
names replaced, then restored. So are the places where the ranks wait for each other: the halo
rounds (``sum_halo``: on several ranks mostly the wait for the neighbour), the step-end
reduction's wait (``wait_all`` in the solver) and the migration; on one rank they cost next to
nothing (``pmpm bench ranks --phases`` runs this on 1 and 2 ranks, idle and loaded).
"""
import collections
import contextlib
import time

from pmpm.core import kernels as K
import pmpm.core.mls as mls_module
import pmpm.core.solver as solver_module

__all__ = ["phase_times", "timed_kernels", "timed", "PHASE_KERNELS"]

#: the kernels the solver calls each step (the others run at set-up or output only)
PHASE_KERNELS = ("p2g", "g2p_velocity", "g2p_kinematics", "stress_power", "count_strays",
                 "grid_update", "momentum_to_velocity", "jaumann_rotate", "rotate", "cell_order",
                 "scatter_point_loads", "point_load_work", "check_deformation", "in_plane_trace",
                 "advance_thickness_stretch")


@contextlib.contextmanager
def _timed(obj, name, totals, key=None):
    key = key or name
    had_own = name in getattr(obj, "__dict__", {})  # a module's function, not a bound method
    original = getattr(obj, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            totals[key] += time.perf_counter() - t0

    setattr(obj, name, wrapper)
    try:
        yield
    finally:
        if had_own:
            setattr(obj, name, original)
        else:  # a method: drop the instance attribute, the class's method shows again
            delattr(obj, name)


@contextlib.contextmanager
def timed_kernels(solver, totals):
    """Within the context, every kernel call of ``solver``'s step (and its materials' stress
    updates, the halo rounds, the step-end wait, the migration) adds its wall seconds to
    ``totals[name]`` (a defaultdict(float)); restored on the way out."""
    with contextlib.ExitStack() as stack:
        for name in PHASE_KERNELS:
            stack.enter_context(_timed(K, name, totals))
        for name in ("p2g_mls", "g2p_mls"):   # the MLS scheme's transfer calls its kernels by name
            stack.enter_context(_timed(mls_module, name, totals))
        for material in solver.materials:
            stack.enter_context(_timed(material, "update_stress", totals))
            if material.sums_power:   # its update with the work half: timed as the update
                stack.enter_context(_timed(material, "update_stress_power", totals, "update_stress"))
        stack.enter_context(_timed(solver_module, "wait_all", totals))   # the step-end reduction
        for name in ("sum_halo", "migrate"):
            stack.enter_context(_timed(solver.decomp, name, totals))
        yield totals


def timed(obj, name, totals):
    """Context: calls of ``obj.name`` add their wall seconds to ``totals[name]`` (a module's
    function or an instance's method, restored on the way out)."""
    return _timed(obj, name, totals)


def phase_times(solver, steps):
    """Run ``steps`` steps with every kernel call timed. Returns (total seconds, {phase:
    seconds}); the phase "other" is the rest (Python, exchanges, checks)."""
    totals = collections.defaultdict(float)
    with timed_kernels(solver, totals):
        t0 = time.perf_counter()
        for _ in range(steps):
            solver.step()
        total = time.perf_counter() - t0
    phases = {k: v for k, v in totals.items() if v > 0}
    phases["other"] = max(total - sum(phases.values()), 0.0)
    return total, phases
