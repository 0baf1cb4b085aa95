"""Typed, validated reads from a TOML table; every error names its dotted key.

``Table(data, "solver").number("cfl", default=0.5, low=0, high=1)`` returns a float or raises
:class:`~pmpm.errors.ConfigError` with ``solver.cfl`` and the reason. ``finish()`` refuses keys
nobody read, so a typo never passes silently.
"""
import math

from pmpm.errors import ConfigError

__all__ = ["Table", "REQUIRED", "MAX_MAGNITUDE"]

REQUIRED = object()
#: largest magnitude of a coordinate, length, velocity, load or scale a scene may give: its
#: square, and its product with another such number, stay finite in double precision, so no
#: set-up computation or first step overflows (docs/scenes.md)
MAX_MAGNITUDE = 1e100


def _control(text):
    """The first control character (NUL, newline, ESC, ...) of ``text``, or None."""
    return next((c for c in text if ord(c) < 32 or 127 <= ord(c) < 160), None)


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class Table:
    """A TOML table being read.

    Parameters
    ----------
    data : dict
    key : str
        Dotted key of this table (``""`` for the top level).
    """

    def __init__(self, data, key):
        if not isinstance(data, dict):
            raise ConfigError(key, f"must be a table (got {type(data).__name__})")
        self.data = data
        self.key = key
        self.used = set()

    def path(self, name):
        return f"{self.key}.{name}" if self.key else name

    def has(self, name):
        return name in self.data

    def _get(self, name, default):
        self.used.add(name)
        if name in self.data:
            return self.data[name], True
        if default is REQUIRED:
            raise ConfigError(self.path(name), "missing (required)")
        return default, False

    def number(self, name, default=REQUIRED, low=None, high=None, low_open=False, high_open=False,
               magnitude=None):
        """A finite float, optionally bounded (``magnitude``: at most that in absolute value);
        ``None`` default allowed (returns None)."""
        value, given = self._get(name, default)
        if not given:
            return value
        if not _is_number(value) or not math.isfinite(value):
            raise ConfigError(self.path(name), f"must be a finite number (got {value!r})")
        value = float(value)
        if magnitude is not None and abs(value) > magnitude:
            raise ConfigError(self.path(name), f"must be at most {magnitude:g} in magnitude (got {value:g})")
        if low is not None and (value < low or (low_open and value == low)):
            raise ConfigError(self.path(name), f"must be {'>' if low_open else '>='} {low:g} (got {value:g})")
        if high is not None and (value > high or (high_open and value == high)):
            raise ConfigError(self.path(name), f"must be {'<' if high_open else '<='} {high:g} (got {value:g})")
        return value

    def integer(self, name, default=REQUIRED, low=None, high=None):
        """An int, optionally bounded."""
        value, given = self._get(name, default)
        if not given:
            return value
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(self.path(name), f"must be an integer (got {value!r})")
        if low is not None and value < low:
            raise ConfigError(self.path(name), f"must be >= {low} (got {value})")
        if high is not None and value > high:
            raise ConfigError(self.path(name), f"must be <= {high} (got {value})")
        return value

    def string(self, name, default=REQUIRED, choices=None):
        """A string, optionally one of ``choices``."""
        value, given = self._get(name, default)
        if not given:
            return value
        if not isinstance(value, str):
            raise ConfigError(self.path(name), f"must be a string (got {value!r})")
        bad = _control(value)
        if bad is not None:  # a NUL breaks HDF5 attributes, a newline or ESC the log and errors
            raise ConfigError(self.path(name), f"holds the control character {bad!r}")
        if choices is not None and value not in choices:
            raise ConfigError(self.path(name), f"must be one of {', '.join(choices)} (got {value!r})")
        return value

    def boolean(self, name, default=REQUIRED):
        value, given = self._get(name, default)
        if given and not isinstance(value, bool):
            raise ConfigError(self.path(name), f"must be true or false (got {value!r})")
        return value

    def vector(self, name, default=REQUIRED, length=2, positive=False, magnitude=MAX_MAGNITUDE):
        """A list of ``length`` finite numbers, each at most ``magnitude`` in absolute value,
        as a tuple of floats."""
        value, given = self._get(name, default)
        if not given:
            return value
        if (not isinstance(value, list) or len(value) != length
                or not all(_is_number(v) and math.isfinite(v) for v in value)):
            raise ConfigError(self.path(name), f"must be a list of {length} numbers (got {value!r})")
        if magnitude is not None and any(abs(v) > magnitude for v in value):
            raise ConfigError(self.path(name), f"every entry must be at most {magnitude:g} in "
                                               f"magnitude (got {value!r})")
        if positive and any(v <= 0 for v in value):
            raise ConfigError(self.path(name), f"must be positive (got {value!r})")
        return tuple(float(v) for v in value)

    def int_vector(self, name, default=REQUIRED, length=2, low=1):
        value, given = self._get(name, default)
        if not given:
            return value
        if (not isinstance(value, list) or len(value) != length
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
            raise ConfigError(self.path(name), f"must be a list of {length} integers (got {value!r})")
        if any(v < low for v in value):
            raise ConfigError(self.path(name), f"every entry must be >= {low} (got {value!r})")
        return tuple(value)

    def table(self, name, default=REQUIRED):
        """A sub-table as a :class:`Table` (``None`` if absent and optional)."""
        value, given = self._get(name, default)
        if not given:
            return None if value is None else Table(value, self.path(name))
        return Table(value, self.path(name))

    def tables(self, name):
        """An array of tables ``[[name]]`` as a list of :class:`Table` (empty if absent)."""
        value, given = self._get(name, [])
        if not given:
            return []
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise ConfigError(self.path(name), "must be an array of tables ([[...]])")
        return [Table(v, f"{self.path(name)}[{k}]") for k, v in enumerate(value)]

    def raw(self, name, default=REQUIRED):
        value, _ = self._get(name, default)
        return value

    def finish(self):
        """Refuse keys that nothing read."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise ConfigError(self.path(unknown[0]), "unknown key")
