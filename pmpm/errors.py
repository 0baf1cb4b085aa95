"""Errors that pmpm reports to the user as one line and exit code 2."""

__all__ = ["ConfigError", "UnstableRunError", "ParticleExitError", "OutputWriteError", "one_line"]


def one_line(text):
    """``text`` as one printable line: every control character (newline, carriage return, NUL,
    the ESC of a terminal escape sequence, ...) written as its escape (``\\n``, ``\\x1b``), so a
    name or key from a file can neither split an error line nor drive the terminal."""
    text = str(text)
    if all(c.isprintable() for c in text):
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


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
        super().__init__(one_line(f"{key}: {reason}"))


class UnstableRunError(RuntimeError):
    """The run stopped because it went unstable (non-finite values or energy growth)."""


class ParticleExitError(RuntimeError):
    """Particles left the grid and the scene asked for ``on_particle_exit = "error"``."""


class OutputWriteError(RuntimeError):
    """An output or checkpoint file could not be written (full disk, quota, I/O error).

    Raised on every rank together; the command line prints one line naming the file and
    exits with its own code (4). The previous checkpoint is left as it was.

    Parameters
    ----------
    path : str
        The file being written.
    reason : str
        Short reason, e.g. ``No space left on device``.
    """

    def __init__(self, path, reason):
        self.path = path
        self.reason = reason
        super().__init__(one_line(f"{path}: cannot write ({reason})"))
