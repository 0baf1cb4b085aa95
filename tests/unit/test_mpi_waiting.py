"""Open MPI settings chosen by pmpm (pmpm/mpidefaults.py) and the waits that sleep instead of
polling (decomposition/waiting.py); the waits between real ranks: tests/mpi/test_decomposition.py."""
import os
import subprocess
import sys
import types

import pytest

from decomposition import waiting
from pmpm import mpidefaults


def test_pmpm_sets_yield_when_idle_unless_the_user_did(monkeypatch):
    monkeypatch.delitem(sys.modules, "mpi4py.MPI", raising=False)  # as before MPI starts
    env = {}
    assert mpidefaults.choose_mpi_defaults(env) == {"OMPI_MCA_mpi_yield_when_idle": "1"}
    assert env["OMPI_MCA_mpi_yield_when_idle"] == "1"
    mine = {"OMPI_MCA_mpi_yield_when_idle": "0"}
    assert mpidefaults.choose_mpi_defaults(mine) == {} and mine["OMPI_MCA_mpi_yield_when_idle"] == "0"


def test_nothing_is_set_once_mpi_has_started(monkeypatch):
    monkeypatch.setitem(sys.modules, "mpi4py.MPI", types.ModuleType("mpi4py.MPI"))
    env = {}
    assert mpidefaults.choose_mpi_defaults(env) == {} and env == {}


def test_importing_pmpm_sets_it_before_mpi_starts():
    env = {k: v for k, v in os.environ.items() if k != "OMPI_MCA_mpi_yield_when_idle"}
    code = ("import os, sys, pmpm; assert 'mpi4py.MPI' not in sys.modules; "
            "print(os.environ.get('OMPI_MCA_mpi_yield_when_idle'))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"
    env["OMPI_MCA_mpi_yield_when_idle"] = "0"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "0"


class _Requests:
    """Stands in for mpi4py's Request.Testall: the requests complete at the ``done``-th test."""

    def __init__(self, done):
        self.tests, self.done = 0, done

    def Testall(self, requests):
        self.tests += 1
        return self.tests >= self.done


@pytest.mark.parametrize("policy", ["nap", "spin"])
def test_a_long_wait_spins_then_sleeps_in_growing_naps(monkeypatch, policy):
    fake = _Requests(done=10_000)
    monkeypatch.setattr(waiting, "MPI", types.SimpleNamespace(Request=fake))
    monkeypatch.setattr(waiting, "POLICY", policy)
    naps = []
    monkeypatch.setattr(waiting.time, "sleep", naps.append)
    now = [0.0]

    def clock():  # every reading 1 us later: the spin phase lasts SPIN_SECONDS of these
        now[0] += 1e-6
        return now[0]

    waiting.wait_all(["request"], clock=clock)
    assert fake.tests == fake.done
    if policy == "spin":
        assert naps == []
        return
    spun = fake.tests - len(naps)
    assert abs(spun - waiting.SPIN_SECONDS / 1e-6) <= 3  # the spin phase, then one test per nap
    assert naps[0] == waiting.NAP_MIN_SECONDS and max(naps) == waiting.NAP_MAX_SECONDS
    assert all(b == min(2 * a, waiting.NAP_MAX_SECONDS) for a, b in zip(naps, naps[1:]))


def test_a_short_wait_never_sleeps(monkeypatch):
    fake = _Requests(done=3)
    monkeypatch.setattr(waiting, "MPI", types.SimpleNamespace(Request=fake))
    naps = []
    monkeypatch.setattr(waiting.time, "sleep", naps.append)
    waiting.wait_all(["request"])
    waiting.wait_all([])
    assert fake.tests == 3 and naps == []
