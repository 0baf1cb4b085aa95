"""Errors that pmpm reports to the user as one line and exit code 2."""

__all__ = ["ConfigError", "UnstableRunError", "ParticleExitError"]


class ConfigError(Exception):
    """Bad scene input: names the key (or file) and the reason.

    Parameters
    ----------
    key : str
        Dotted TOML key (``materials.steel.E``) or a file path.
    reason : str
        What is wrong, in a few words.
    """

    def __init__(self, key, reason):
        self.key = key
        self.reason = reason
        super().__init__(f"{key}: {reason}")


class UnstableRunError(RuntimeError):
    """The run stopped because it went unstable (non-finite values or energy growth)."""


class ParticleExitError(RuntimeError):
    """Particles left the grid and the scene asked for ``on_particle_exit = "error"``."""
