"""Benchmarks against other programs, run from a checkout (not installed with pmpm):
:mod:`bench.peer`, ``pmpm bench peer`` (Taichi peers, docs/performance.md)."""
