"""Mass-proportional damping: ``[loads] damping = alpha`` (1/s), the nodal force -alpha m v of
the grid update (pmpm/core/kernels/grid_ops.py); its work is ``damping_work``. A mode of
circular frequency omega is damped at alpha / (2 omega) of critical.
"""
from pmpm.core.effects import Effect, register_energy

__all__ = ["MassDamping", "DAMPING_WORK"]

#: the energy mass-proportional damping dissipates (J; Rayleigh damping's mass part adds to it)
DAMPING_WORK = register_energy(
    "damping_work", "work done by mass-proportional damping (the mass part of Rayleigh damping), dissipated")


class MassDamping(Effect):
    """Mass-proportional damping ``[loads] damping = alpha`` (effect ``damping``): the nodal
    force -alpha m v of the grid-update kernel; its work is ``damping_work``."""

    name = "damping"
    energy_terms = (DAMPING_WORK,)

    @classmethod
    def create(cls, scene, setup):
        alpha = scene.loads.damping
        return cls(alpha) if alpha else None

    def __init__(self, alpha):
        self.nodal_damping = alpha
        self.damping_work = 0.0   # this rank's share (owned nodes), J

    def after_grid_update(self, s, damped_work):
        self.damping_work += damped_work

    def describe(self):
        return [f"mass-proportional damping ({self.nodal_damping:g} 1/s)"]
