"""``pmpm bench ranks``: it launches the frame on 1 and 2 ranks under its own background load,
prints the table and a JSON line, and leaves no busy loop behind."""
import json
import os
import shutil

import pytest

from pmpm.benchmarks import ranks
from pmpm.cli import main


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False


def test_background_load_is_one_busy_loop_per_core_and_ends_with_the_block():
    with ranks.BackgroundLoad() as load:
        pids = [p.pid for p in load.procs]
        assert len(pids) == (os.cpu_count() or 1) and all(_alive(p) for p in pids)
        assert all(os.getsid(p) == p for p in pids)   # each in a session of its own
        assert all(os.getpriority(os.PRIO_PROCESS, p) == 19 for p in pids)
    assert not any(_alive(p) for p in pids)


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="needs Open MPI's mpirun")
def test_bench_ranks_prints_the_table_and_a_json_line(capsys):
    assert main(["bench", "ranks", "--steps", "2", "--repeat", "1", "--load", "busy", "--no-output"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    result = json.loads(out[-1])
    runs = result["loads"]["busy"]
    assert set(runs) == {"1", "2"} and all(r["wall_s"] > 0 and r["cpu_s"] > 0 for r in runs.values())
    assert runs["1"]["speed_up"] == 1.0 and runs["2"]["speed_up"] > 0
    assert any(line.split()[:2] == ["busy", "2"] for line in out)
