"""Registries keyed by the TOML name: materials, shape functions, schemes, writers.

A class joins a registry by subclassing its base and setting ``name``;
``lookup(Base, "name")`` finds it (the PyFR ``subclass_where`` pattern).
"""

__all__ = ["lookup", "names", "all_subclasses"]


def all_subclasses(base):
    """Every subclass of ``base``, depth first in definition order."""
    found = []
    for sub in base.__subclasses__():
        found.append(sub)
        found.extend(all_subclasses(sub))
    return found


def names(base):
    """Sorted registry names of every concrete subclass of ``base``."""
    return sorted({c.name for c in all_subclasses(base) if getattr(c, "name", None)})


def lookup(base, name):
    """Return the subclass of ``base`` whose ``name`` equals ``name``.

    Raises
    ------
    KeyError
        With the list of valid names, when nothing matches.
    """
    for cls in all_subclasses(base):
        if getattr(cls, "name", None) == name:
            return cls
    raise KeyError(f"unknown {base.__name__.lower()} {name!r}; valid: {', '.join(names(base))}")
