"""Time functions that scale loads: step, ramp, harmonic, table."""
import math

import numpy as np

from pmpm.errors import ConfigError

__all__ = ["parse_time_function", "evaluate"]

KINDS = ("step", "ramp", "harmonic", "table")


def parse_time_function(t):
    """Validate a ``time_function`` table and return it as a plain dict."""
    kind = t.string("type", "step", choices=KINDS)
    tf = {"type": kind, "start": t.number("start", 0.0, low=0.0)}
    if kind == "ramp":
        tf["duration"] = t.number("duration", low=0.0, low_open=True)
    elif kind == "harmonic":
        tf["frequency"] = t.number("frequency", low=0.0, low_open=True)
        tf["phase"] = t.number("phase", 0.0)
    elif kind == "table":
        times, values = t.raw("t"), t.raw("value")
        ok = (isinstance(times, list) and isinstance(values, list) and len(times) == len(values) >= 2
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                      for v in times + values))
        if not ok:
            raise ConfigError(t.path("t"), "t and value must be lists of numbers of equal length (>= 2)")
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ConfigError(t.path("t"), "times must increase")
        tf["t"], tf["value"] = [float(v) for v in times], [float(v) for v in values]
    t.finish()
    return tf


def evaluate(tf, time):
    """Value of time function ``tf`` (a dict from :func:`parse_time_function`) at ``time``."""
    tau = time - tf["start"]
    kind = tf["type"]
    if kind == "table":
        return float(np.interp(time, tf["t"], tf["value"]))
    if tau < 0:
        return 0.0
    if kind == "step":
        return 1.0
    if kind == "ramp":
        return min(tau / tf["duration"], 1.0)
    return math.sin(2 * math.pi * tf["frequency"] * tau + tf["phase"])
