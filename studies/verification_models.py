"""The independent models of tests/verification, for the studies that compare with them.

The models (frame FE and beam models, the cantilever's FE model, ...) live beside the tests that
use them, not in the pmpm package: they share no code with pmpm on purpose. A study run from a
checkout imports one with :func:`load`; where pmpm is installed without its tests the study says
so in one line instead of failing deep in an import.
"""
import importlib
import os
import sys

__all__ = ["TESTS", "available", "load"]

#: tests/verification of the checkout this package sits in
TESTS = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "tests", "verification"))


def available(name):
    """Whether tests/verification/<name>.py is next to this package."""
    return os.path.exists(os.path.join(TESTS, f"{name}.py"))


def load(name):
    """The module tests/verification/<name>.py (imported once; the models import each other by
    their bare names, so the folder is on sys.path only while it loads)."""
    if not available(name):
        raise RuntimeError(f"tests/verification/{name}.py not found next to this package "
                           "(the studies that compare with an independent model need a checkout)")
    if name in sys.modules:
        return sys.modules[name]
    sys.path.insert(0, TESTS)
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(TESTS)
