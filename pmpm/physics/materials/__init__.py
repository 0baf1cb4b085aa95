"""Materials by name: ``lookup(Material, "linear_elastic")``.

Importing this package registers every model shipped with pmpm.
"""
from pmpm.registry import lookup, names
from pmpm.physics.materials.base import Material
from pmpm.physics.materials import linear_elastic  # noqa: F401  (registers)
from pmpm.physics.materials import smooth_vonmises, bilinear_vonmises  # noqa: F401
from pmpm.physics.materials import neo_hookean  # noqa: F401
from pmpm.errors import ConfigError

__all__ = ["Material", "make_material", "material_names"]


def material_names():
    """Names accepted by ``type`` under ``[materials.<label>]``."""
    return names(Material)


def make_material(table, key, formulation):
    """Build the material described by TOML ``table`` at dotted ``key``."""
    table = dict(table)
    kind = table.pop("type", None)
    if kind is None:
        raise ConfigError(f"{key}.type", f"missing; one of: {', '.join(material_names())}")
    try:
        cls = lookup(Material, kind)
    except KeyError:
        raise ConfigError(f"{key}.type", f"unknown material {kind!r}; one of: {', '.join(material_names())}") from None
    return cls(table, key, formulation)
