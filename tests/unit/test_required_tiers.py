"""tests/conftest.py: under PMPM_REQUIRE_TIERS=1 (set by .ci/run) a skip in a tier that CI must
run (tests/mpi, tests/slurm, tests/paraview) is a failure; locally it stays a skip, and skips
elsewhere, and expected failures in a tier, are left alone.

Checked on a generated tree (the real conftest.py copied beside small test files) run by pytest
in a subprocess, so the mechanism is exercised as CI meets it: a skip from a test body, from a
fixture's set-up (how the Slurm tier skips when it cannot install Slurm) and from a skipif mark
(how the MPI tier skips without ranks)."""
import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

CONFTEST = pathlib.Path(__file__).resolve().parents[1] / "conftest.py"

TIER_TESTS = '''
import pytest

@pytest.fixture
def cluster():
    pytest.skip("cannot install Slurm")

def test_body_skips():
    pytest.skip("no ranks")

def test_fixture_skips(cluster):
    pass

@pytest.mark.skipif(True, reason="needs mpirun -n 2")
def test_mark_skips():
    pass

@pytest.mark.xfail(reason="a known open finding", strict=True)
def test_expected_failure():
    assert False

def test_passes():
    pass
'''

PLAIN_TESTS = '''
import pytest

def test_optional_dependency_missing():
    pytest.skip("optional")
'''


def _outcomes(tmp_path, require):
    """{test name: outcome} of the generated tree under PMPM_REQUIRE_TIERS=require."""
    tests = tmp_path / "tests"
    (tests / "slurm").mkdir(parents=True, exist_ok=True)
    (tests / "unit").mkdir(exist_ok=True)
    shutil.copy(CONFTEST, tests / "conftest.py")
    (tests / "slurm" / "test_tier.py").write_text(TIER_TESTS)
    (tests / "unit" / "test_plain.py").write_text(PLAIN_TESTS)
    # a tiny plugin that writes each test's final outcome (after conftest's hook) to a file
    (tmp_path / "record_outcomes.py").write_text(
        "import json, os\n"
        "seen = {}\n"
        "def pytest_runtest_logreport(report):\n"
        "    name = report.nodeid.split('::')[-1]\n"
        "    if report.when == 'call' or report.outcome != 'passed':\n"
        "        seen[name] = 'xfailed' if hasattr(report, 'wasxfail') else report.outcome\n"
        "def pytest_sessionfinish(session):\n"
        "    open(os.environ['OUTCOMES'], 'w').write(json.dumps(seen))\n")
    env = dict(os.environ, PMPM_REQUIRE_TIERS=require, OUTCOMES=str(tmp_path / "outcomes.json"),
               PYTHONPATH=str(tmp_path))
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "record_outcomes",
                           "-o", "addopts=", str(tests)], cwd=tmp_path, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=120)
    return proc.returncode, json.loads((tmp_path / "outcomes.json").read_text()), proc.stdout


def test_locally_tier_skips_stay_skips(tmp_path):
    code, seen, out = _outcomes(tmp_path, "")
    assert code == 0, out
    assert seen == {"test_body_skips": "skipped", "test_fixture_skips": "skipped", "test_mark_skips": "skipped",
                    "test_expected_failure": "xfailed", "test_passes": "passed",
                    "test_optional_dependency_missing": "skipped"}, out


def test_under_require_tiers_every_tier_skip_fails(tmp_path):
    code, seen, out = _outcomes(tmp_path, "1")
    assert code == 1, out
    assert seen == {"test_body_skips": "failed", "test_fixture_skips": "failed", "test_mark_skips": "failed",
                    "test_expected_failure": "xfailed", "test_passes": "passed",
                    "test_optional_dependency_missing": "skipped"}, out
    # the failure names the tier and keeps the skip's reason
    assert "required tier 'slurm' skipped under PMPM_REQUIRE_TIERS (CI): Skipped: cannot install Slurm" in out


@pytest.mark.parametrize("value", ["0", ""])
def test_zero_or_empty_means_off(tmp_path, value):
    code, seen, out = _outcomes(tmp_path, value)
    assert code == 0 and seen["test_fixture_skips"] == "skipped", out
