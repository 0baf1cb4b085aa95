"""Write scene data (what ``tomllib`` reads) back as TOML text, for ``pmpm expand``.

Only what scene files hold: tables, arrays of tables, strings, booleans, integers, finite
floats (written with ``repr``, so they read back to the same float) and lists of these or of
inline tables. ``tomllib.loads(dumps(data)) == data`` for such data (tested). Tables come out
as ``[a.b]`` headers and arrays of tables as ``[[a.b]]``; inside an array-of-tables entry a
nested table is written inline (``time_function = { type = "step" }``).
"""
import json
import math
import re

__all__ = ["dumps"]

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _key(k):
    return k if _BARE.fullmatch(k) else json.dumps(k)


def _value(v):
    """One value as TOML (inline form)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write the non-finite number {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a TOML basic string: JSON escapes are valid TOML
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    raise ValueError(f"cannot write a {type(v).__name__} as TOML")


def _is_table_array(v):
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _table(data, path, lines):
    """Plain keys first, then sub-tables, then arrays of tables (TOML's order rules)."""
    for k, v in data.items():
        if not isinstance(v, dict) and not _is_table_array(v):
            lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in data.items():
        if isinstance(v, dict):
            sub = path + [_key(k)]
            plain = [x for x in v.values() if not isinstance(x, dict) and not _is_table_array(x)]
            if plain or not v:  # a table holding only tables needs no header of its own
                lines += ["", f"[{'.'.join(sub)}]"]
            _table(v, sub, lines)
    for k, v in data.items():
        if _is_table_array(v):
            sub = path + [_key(k)]
            for entry in v:
                lines += ["", f"[[{'.'.join(sub)}]]"]
                for ek, ev in entry.items():
                    lines.append(f"{_key(ek)} = {_value(ev)}")


def dumps(data, header=""):
    """TOML text of ``data`` (a dict), after the comment lines of ``header``."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    _table(data, [], lines)
    return "\n".join(lines).lstrip("\n") + "\n"
