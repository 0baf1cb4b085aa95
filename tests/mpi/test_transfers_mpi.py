"""APIC and XPIC(m) give the same answer on any rank count (the XPIC smoothing passes sum their
momenta across the slab boundaries with a halo round each; APIC's affine matrix migrates with its
particle). Under ``mpirun -n K``; tolerance as tests/mpi/test_same_answer.py."""
import dataclasses
import os
import sys

import pytest
from mpi4py import MPI

sys.path.insert(0, os.path.dirname(__file__))
from test_same_answer import _compare, _everywhere  # noqa: E402

from pmpm.scene.config import load_scene  # noqa: E402


@pytest.mark.parametrize("transfer, order, scheme", [("apic", None, "usl"), ("xpic", 3, "musl")])
def test_transfer_same_on_any_rank_count(transfer, order, scheme):
    scene = load_scene("cases/bar.toml")[0]
    extra = {"xpic_order": order} if order else {}
    scene = dataclasses.replace(scene, solver=dataclasses.replace(
        scene.solver, end_time=2.5, transfer=transfer, scheme=scheme, **extra))
    ok, s = _compare(scene)
    assert _everywhere(ok)
    if MPI.COMM_WORLD.Get_size() > 1:
        assert s.decomp.size > 1   # the bar is split: the transfers cross a slab boundary
