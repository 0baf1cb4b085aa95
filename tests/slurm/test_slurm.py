"""The job scripts of jobs/ under a real, one-node Slurm started by this test.

Needs root: installs Debian's Slurm daemons and munge with apt-get when they are missing
(skips with the reason when it cannot), writes a one-node, cgroup-free slurm.conf into a
temporary folder with its own munge key, ports, state, spool and logs, starts munged,
slurmctld and slurmd as children of this process and stops them (by pid) afterwards, along
with every process still carrying this cluster's SLURM_CONF in its environment.

Tests: the weak-scaling sweep (jobs/slurm_scaling_weak.sh, 1 and 2 ranks, tiny) gathered by
jobs/gather_scaling.py; jobs/slurm_run.sh running a tiny scene, continuing it from its
checkpoint after the end time grows, skipping it when complete, and passing pmpm's exit code;
a running job requeued with `scontrol requeue` continuing from its checkpoint;
jobs/slurm_frame_3storey.sh reaching slurm_run.sh from sbatch's copy with its case.
Runtime: 1-2 minutes here (2 vCPUs), after a first install of about 15 s.
Run alone:  python -m pytest -q tests/slurm   (in the checkout's .venv, as root)
"""
from __future__ import annotations

import contextlib
import csv
import ctypes
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
JOBS = REPO / "jobs"
VENV_PY = REPO / ".venv" / "bin" / "python"
PACKAGES = ["slurmctld", "slurmd", "slurm-client", "munge"]  # slurm-wlm's daemons and clients
BINARIES = ["slurmctld", "slurmd", "sbatch", "sinfo", "scontrol", "scancel", "munged", "munge", "unmunge"]
SYSTEM_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
FINAL_STATES = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "PREEMPTED", "BOOT_FAIL",
                "DEADLINE", "OUT_OF_MEMORY"}

JOB_TIMEOUT = 300       # s, a whole job, from submission (the sweep takes ~15 s here)
START_TIMEOUT = 60      # s, daemons up and the node idle


def _which(name):
    return shutil.which(name, path=os.environ.get("PATH", "") + ":" + SYSTEM_PATH)


def _tail(text, lines=40):
    text = text if isinstance(text, str) else text.decode(errors="replace")
    return "\n".join(text.rstrip().splitlines()[-lines:])


def _run(cmd, timeout, env=None, **kw):
    """subprocess.run with a timeout that never raises it: returncode 124 and a note instead."""
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, **kw)
    except subprocess.TimeoutExpired as exc:
        out = (exc.stdout or b"").decode(errors="replace") if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        return subprocess.CompletedProcess(cmd, 124, out, f"timed out after {timeout} s")


# -- installing ---------------------------------------------------------------------------------
@contextlib.contextmanager
def _services_not_started():
    """Keep package scripts from starting the packaged munge/slurm services (policy-rc.d 101)."""
    policy = Path("/usr/sbin/policy-rc.d")
    if policy.exists():
        yield
        return
    policy.write_text("#!/bin/sh\n# written by pmpm's tests/slurm while installing Slurm\nexit 101\n")
    policy.chmod(0o755)
    try:
        yield
    finally:
        policy.unlink(missing_ok=True)


def ensure_slurm():
    """Install the Slurm daemons and munge when missing; pytest.skip when that cannot be done."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the Slurm test runs on Linux only")
    if os.geteuid() != 0:
        pytest.skip("the Slurm test needs root (it installs Slurm with apt-get and runs its daemons)")
    if not VENV_PY.exists():
        pytest.skip(f"{VENV_PY} missing: run ./setup.sh first (the jobs activate the checkout's .venv)")
    if all(_which(b) for b in BINARIES):
        return
    if not _which("apt-get"):
        pytest.skip(f"Slurm is not installed ({', '.join(b for b in BINARIES if not _which(b))} missing) "
                    "and there is no apt-get to install it")
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive", PATH=os.environ.get("PATH", "") + ":" + SYSTEM_PATH)
    install = ["apt-get", "install", "-y", "-q", "--no-install-recommends",
               "-o", "DPkg::Lock::Timeout=120", *PACKAGES]
    with _services_not_started():
        r = _run(install, 600, env)
        if r.returncode != 0:  # perhaps stale package lists: refresh once
            u = _run(["apt-get", "update", "-q", "-o", "DPkg::Lock::Timeout=120"], 300, env)
            if u.returncode != 0:
                pytest.skip(f"cannot install Slurm: apt-get update failed (no network?):\n{_tail(u.stdout + u.stderr, 10)}")
            r = _run(install, 600, env)
        if r.returncode != 0:
            pytest.skip(f"cannot install Slurm: apt-get install {' '.join(PACKAGES)} failed:\n"
                        f"{_tail(r.stdout + r.stderr, 15)}")
    missing = [b for b in BINARIES if not _which(b)]
    assert not missing, f"installed {PACKAGES} but still missing {missing}"


# -- the cluster ----------------------------------------------------------------------------------
def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _die_with_parent():
    """preexec_fn: the daemon gets SIGTERM if this test process dies without cleaning up."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _environ(pid):
    try:
        with open(f"/proc/{pid}/environ", "rb") as fh:
            return set(fh.read().split(b"\0"))
    except OSError:
        return set()


def _comm(pid):
    try:
        with open(f"/proc/{pid}/comm", "rb") as fh:
            return fh.read().strip().decode(errors="replace")
    except OSError:
        return ""


def _cmdline(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace").strip()[:120]
    except OSError:
        return "?"


class Cluster:
    """munged, slurmctld and slurmd on 127.0.0.1, all files under ``root``."""

    def __init__(self, root: Path):
        self.root = root
        self.node = socket.gethostname().split(".")[0]
        self.conf = root / "slurm.conf"
        self.logs = root / "log"
        self.munge_socket = root / "munge" / "munge.socket"
        self.procs = {}  # name -> Popen
        self.jobs = []
        self.env = dict(os.environ, SLURM_CONF=str(self.conf),
                        PATH=os.environ.get("PATH", "") + ":" + SYSTEM_PATH)
        # Slurm's own variables of an enclosing job (CI inside Slurm) must not leak into ours.
        for k in [k for k in self.env if k.startswith(("SLURM_", "SBATCH_", "SRUN_", "SALLOC_"))]:
            if k != "SLURM_CONF":
                del self.env[k]
        self.marker = f"SLURM_CONF={self.conf}".encode()

    # start ------------------------------------------------------------------------------------
    def start(self):
        for d in ("state", "spool", "log", "munge", "jobs"):
            (self.root / d).mkdir(parents=True, exist_ok=True)
        (self.root / "munge").chmod(0o755)  # munged wants its socket folder traversable by all
        key = self.root / "munge" / "munge.key"
        key.write_bytes(os.urandom(1024))
        key.chmod(0o400)
        self._spawn("munged", ["munged", "--foreground", "--force", f"--socket={self.munge_socket}",
                               f"--key-file={key}", f"--pid-file={self.root / 'munge' / 'munged.pid'}",
                               f"--log-file={self.logs / 'munged.log'}",
                               f"--seed-file={self.root / 'munge' / 'munged.seed'}"])
        self._wait(lambda: self._munge_ok(), 20, "munged to answer on its socket")
        self.conf.write_text(self._slurm_conf())
        self._spawn("slurmctld", ["slurmctld", "-D", "-f", str(self.conf)])
        self._wait(lambda: self._cmd(["scontrol", "ping"], 10).stdout.count("UP") > 0, START_TIMEOUT,
                   "slurmctld to answer scontrol ping")
        self._spawn("slurmd", ["slurmd", "-D", "-f", str(self.conf), "-N", self.node])
        self._wait(lambda: self._cmd(["sinfo", "-h", "-N", "-o", "%T"], 10).stdout.strip() == "idle",
                   START_TIMEOUT, f"node {self.node} to be idle in sinfo")

    def _slurm_conf(self):
        r = self.root
        return f"""# one-node Slurm for pmpm's tests/slurm (no cgroups, no accounting)
ClusterName=pmpmtest
SlurmctldHost={self.node}(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={self.munge_socket},cred_expire=10
CredType=cred/munge
StateSaveLocation={r / 'state'}
SlurmdSpoolDir={r / 'spool'}
SlurmctldPidFile={r / 'slurmctld.pid'}
SlurmdPidFile={r / 'slurmd.pid'}
SlurmctldLogFile={self.logs / 'slurmctld.log'}
SlurmdLogFile={self.logs / 'slurmd.log'}
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
SwitchType=switch/none
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SlurmdParameters=config_overrides
ReturnToService=2
MinJobAge=600
KillWait=5
InactiveLimit=0
SlurmctldTimeout=60
SlurmdTimeout=60
NodeName={self.node} NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN
PartitionName=test Nodes={self.node} Default=YES MaxTime=30 State=UP
"""

    def _spawn(self, name, cmd):
        out = open(self.logs / f"{name}.stdout", "wb")
        try:
            self.procs[name] = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                                env=self.env, cwd=self.root, preexec_fn=_die_with_parent)
        finally:
            out.close()

    def _munge_ok(self):
        enc = self._cmd(["munge", "-n", "-S", str(self.munge_socket)], 10)
        if enc.returncode != 0:
            return False
        dec = self._cmd(["unmunge", "-S", str(self.munge_socket)], 10, input=enc.stdout)
        return dec.returncode == 0

    def _cmd(self, cmd, timeout, **kw):
        return _run(cmd, timeout, self.env, **kw)

    def _wait(self, ok, timeout, what):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            dead = [n for n, p in self.procs.items() if p.poll() is not None]
            if dead:
                pytest.fail(f"{', '.join(dead)} exited while waiting for {what}\n{self.diagnostics()}")
            if ok():
                return
            time.sleep(0.5)
        pytest.fail(f"timed out after {timeout} s waiting for {what}\n{self.diagnostics()}")

    # jobs -------------------------------------------------------------------------------------
    def sbatch(self, script, args, export, workdir):
        """Submit ``script``; returns the job id. ``export``: variables for the job environment."""
        workdir.mkdir(parents=True, exist_ok=True)
        exports = ",".join(["ALL"] + [f"{k}={v}" for k, v in export.items()])
        r = self._cmd(["sbatch", "--parsable", f"--export={exports}", f"--chdir={workdir}",
                       f"--output={workdir}/job-%j.out", *args, str(script)], 30)
        assert r.returncode == 0 and r.stdout.strip(), \
            f"sbatch {script.name} failed ({r.returncode}):\n{r.stdout}{r.stderr}\n{self.diagnostics()}"
        job = r.stdout.strip().split(";")[0]
        self.jobs.append(job)
        return job

    def job_info(self, job):
        r = self._cmd(["scontrol", "show", "job", "-o", job], 10)
        return dict(re.findall(r"(\w+)=(\S*)", r.stdout)) if r.returncode == 0 else {}

    def wait(self, job, workdir, timeout=JOB_TIMEOUT):
        """Wait for the job to end; returns (state, exit code, the job's output)."""
        deadline = time.monotonic() + timeout
        info = {}
        while time.monotonic() < deadline:
            info = self.job_info(job)
            if info.get("JobState") in FINAL_STATES:
                break
            time.sleep(1.0)
        else:
            self._cmd(["scancel", job], 10)
            pytest.fail(f"job {job} not finished after {timeout} s (state {info.get('JobState')}); "
                        f"cancelled\n{self.job_output(job, workdir)}\n{self.diagnostics()}")
        time.sleep(0.2)  # the output file is complete once the batch step is over
        return info["JobState"], info.get("ExitCode", "?"), self.job_output(job, workdir)

    @staticmethod
    def job_output(job, workdir):
        path = workdir / f"job-{job}.out"
        return f"--- {path} ---\n" + (path.read_text(errors="replace") if path.exists() else "(missing)")

    def diagnostics(self):
        parts = [f"--- scontrol show node ---\n{self._cmd(['scontrol', 'show', 'node'], 10).stdout}"]
        for name in ("munged.log", "slurmctld.log", "slurmd.log", "munged.stdout", "slurmctld.stdout",
                     "slurmd.stdout"):
            p = self.logs / name
            if p.exists():
                parts.append(f"--- {p} (tail) ---\n{_tail(p.read_text(errors='replace'), 30)}")
        return "\n".join(parts)

    # stop -------------------------------------------------------------------------------------
    def stop(self):
        """Cancel our jobs, stop the daemons by pid, then end whatever else ran under this cluster."""
        if self.jobs and "slurmctld" in self.procs and self.procs["slurmctld"].poll() is None:
            self._cmd(["scancel", *self.jobs], 10)
        for name in ("slurmd", "slurmctld", "munged"):
            p = self.procs.get(name)
            if p is None or p.poll() is not None:
                continue
            p.terminate()
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)
        left = self.leftovers()
        if left:
            print(f"\nslurm test cluster: ending {len(left)} leftover process(es): "
                  + "; ".join(f"{pid} {_cmdline(pid)}" for pid in left))
        for sig in (signal.SIGTERM, signal.SIGKILL):
            for pid in left:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.kill(pid, sig)
            deadline = time.monotonic() + 5
            while left and time.monotonic() < deadline:
                time.sleep(0.2)
                left = self.leftovers()
        return left

    def leftovers(self):
        """Pids of processes started under this cluster: its daemons and step daemons, and the
        processes of its jobs (job scripts, mpirun, ranks), all carrying this cluster's SLURM_CONF."""
        me = os.getpid()
        jobs = {f"SLURM_JOB_ID={j}".encode() for j in self.jobs}
        pids = []
        for entry in os.listdir("/proc"):
            if not entry.isdigit() or int(entry) == me:
                continue
            env = _environ(entry)
            if self.marker in env and (env & jobs or _comm(entry) in ("slurmstepd", "slurmd", "slurmctld", "munged")):
                pids.append(int(entry))
        return pids


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    ensure_slurm()
    root = tmp_path_factory.mktemp("slurm")
    c = Cluster(root)
    try:
        c.start()
        yield c
    finally:
        try:
            left = c.stop()
        finally:
            shutil.rmtree(root, ignore_errors=True)
        assert not left, f"processes of the test cluster still running after the shutdown: {left}"


def _job_env(**extra):
    env = {"PMPM_HOME": str(REPO), "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    env.update({k: str(v) for k, v in extra.items()})
    return env


def _assert_job(cluster, job, result, expect_state="COMPLETED", expect_exit="0:0"):
    """``result``: (state, exit code, output) from Cluster.wait; returns the output."""
    state, exit_code, output = result
    assert (state, exit_code) == (expect_state, expect_exit), (
        f"job {job}: {state} exit {exit_code}, expected {expect_state} exit {expect_exit}\n"
        f"{output}\n{cluster.diagnostics()}")
    return output


# -- the tests ----------------------------------------------------------------------------------
def test_weak_scaling_sweep_and_gather(cluster):
    work = cluster.root / "jobs" / "weak"
    out = work / "out"
    job = cluster.sbatch(JOBS / "slurm_scaling_weak.sh", ["-n", "2", "--time=10"],
                         _job_env(RANKS="1 2", PARTICLES=20000, STEPS=5, REPEAT=1, OVERSUBSCRIBE=0,
                                  OUTDIR=out), work)
    output = _assert_job(cluster, job, cluster.wait(job, work))
    results = out / "scaling_weak.jsonl"
    assert results.exists(), f"no {results}\n{output}"
    lines = [ln for ln in results.read_text().splitlines() if ln.strip()]
    assert len(lines) == 2, f"expected 2 JSON lines (1 and 2 ranks) in {results}:\n{lines}\n{output}"

    table_dir = cluster.root / "table"
    r = _run([str(VENV_PY), str(JOBS / "gather_scaling.py"), str(results), "-o", str(table_dir)], 120)
    assert r.returncode == 0, f"gather_scaling.py failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    print(r.stdout)  # the Markdown table, shown with pytest -s
    with open(table_dir / "scaling.csv", newline="") as fh:
        rows = {int(row["ranks"]): row for row in csv.DictReader(fh)}
    assert sorted(rows) == [1, 2], f"table rows for ranks {sorted(rows)}, expected [1, 2]\n{r.stdout}"
    for k, row in rows.items():
        assert row["mode"] == "weak"
        # The benchmark's compute time is CPU time less the wall time inside MPI calls, floored at 0:
        # when other work shares the 2 vCPUs, a rank descheduled inside an MPI wait can drive it to 0
        # at 2 ranks. CPU time including the MPI calls is always positive.
        infl, with_comm = float(row["work_inflation"]), float(row["work_inflation_with_comm"])
        assert math.isfinite(infl) and (infl > 0 or k > 1 and infl == 0), f"{k} rank(s): work inflation {infl}\n{r.stdout}"
        assert math.isfinite(with_comm) and with_comm > 0, f"{k} rank(s): inflation with comm {with_comm}\n{r.stdout}"
        assert math.isfinite(float(row["wall_efficiency"])) and float(row["wall_efficiency"]) > 0, r.stdout
    assert float(rows[1]["halo_bytes_per_step"]) == 0, r.stdout
    assert float(rows[2]["halo_bytes_per_step"]) > 0, r.stdout
    assert abs(float(rows[1]["wall_efficiency"]) - 1.0) < 1e-12
    assert float(rows[2]["particles"]) > 1.5 * float(rows[1]["particles"]), "weak: 2 ranks hold twice the particles"
    png = table_dir / "scaling_efficiency.png"
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"no PNG plot at {png}"
    md = (table_dir / "scaling.md").read_text()
    assert md.startswith("| series |") and md.count("\n| weak") == 2, md


SCENE = """# the fixed-free bar of cases/bar.toml (200 particles), checkpointed
title = "bar for the Slurm job test"
formulation = "plane_stress"
particles_per_cell = 2

[grid]
origin = [0.0, 0.0]
cell_size = 0.5
cells = [54, 3]

[materials.bar]
type = "linear_elastic"
E = 100.0
nu = 0.0
density = 1.0

[[bodies]]
name = "bar"
shape = "rectangle"
material = "bar"
lower = [0.0, 0.0]
upper = [25.0, 0.5]
velocity = ["0.1 * sin(pi * x / 50)", 0.0]

[[boundary]]
name = "fixed end"
type = "fixed"
lower = [0.0, 0.0]
upper = [0.0, 1.5]

[solver]
shape_function = "cubic"
scheme = "musl"
cfl = 0.5
end_time = {end_time}

[output]
interval = {interval}
history_interval = {history_interval}
checkpoint_interval = {checkpoint_interval}
fields = ["x", "v"]

[[output.track]]
name = "free_end"
point = [25.0, 0.25]
"""


def _scene(end_time, interval=0.25, history_interval=0.05, checkpoint_interval=0.25):
    return SCENE.format(end_time=end_time, interval=interval, history_interval=history_interval,
                        checkpoint_interval=checkpoint_interval)


def _checkpoint_time(results_dir):
    import h5py
    times = []
    for p in sorted(results_dir.glob("*.ckpt*.h5")):
        with h5py.File(p, "r") as f:
            if f.attrs.get("complete", False):
                times.append(float(f.attrs["time"]))
    return max(times) if times else None


def test_run_script_restarts_skips_and_passes_exit_code(cluster):
    work = cluster.root / "jobs" / "run"
    work.mkdir(parents=True, exist_ok=True)
    scene = work / "tinybar.toml"
    results_dir = work / "runs" / "tinybar_results"
    env = _job_env(CASE=scene, OUTDIR=work / "runs")

    # 1. a fresh run to t = 0.5 on 2 ranks
    scene.write_text(_scene(end_time=0.5))
    job = cluster.sbatch(JOBS / "slurm_run.sh", ["-n", "2", "--time=10"], env, work)
    out1 = _assert_job(cluster, job, cluster.wait(job, work))
    assert "--restart" not in out1, out1
    assert (results_dir / "tinybar.h5").exists(), f"no output in {results_dir}\n{out1}"
    t1 = _checkpoint_time(results_dir)
    assert t1 is not None and abs(t1 - 0.5) < 1e-6, f"newest checkpoint at t = {t1}, expected 0.5\n{out1}"

    # 2. the same job again after the end time grew: it continues from the checkpoint at 0.5
    scene.write_text(_scene(end_time=1.0))
    job = cluster.sbatch(JOBS / "slurm_run.sh", ["-n", "2", "--time=10"], env, work)
    out2 = _assert_job(cluster, job, cluster.wait(job, work))
    assert "--restart" in out2 and "restarted from" in out2, f"expected a restart\n{out2}"
    t2 = _checkpoint_time(results_dir)
    assert t2 is not None and abs(t2 - 1.0) < 1e-6, f"newest checkpoint at t = {t2}, expected 1.0\n{out2}"

    # 3. and again: complete, nothing to run
    job = cluster.sbatch(JOBS / "slurm_run.sh", ["-n", "2", "--time=10"], env, work)
    out3 = _assert_job(cluster, job, cluster.wait(job, work))
    assert "is complete" in out3 and "+ mpirun" not in out3, out3

    # 4. pmpm's exit code is the job's: a missing scene is bad input, exit 2
    job = cluster.sbatch(JOBS / "slurm_run.sh", ["-n", "1", "--time=10"],
                         _job_env(CASE=work / "missing.toml", OUTDIR=work / "runs"), work)
    _assert_job(cluster, job, cluster.wait(job, work), expect_state="FAILED", expect_exit="2:0")


def test_frame_3storey_wrapper_runs_its_case_through_slurm_run(cluster):
    """The wrapper, submitted with sbatch (which runs a copy of it), hands the three-storey case
    to slurm_run.sh; an unknown variant keeps the job to pmpm's bad-input exit (2), not a run."""
    work = cluster.root / "jobs" / "frame3"
    job = cluster.sbatch(JOBS / "slurm_frame_3storey.sh", ["-n", "1", "--time=10"],
                         _job_env(VARIANT="nope", OUTDIR=work / "runs"), work)
    out = _assert_job(cluster, job, cluster.wait(job, work), expect_state="FAILED", expect_exit="2:0")
    assert f"case {REPO / 'cases' / 'frame_3storey.toml'} variant nope" in out, out
    assert "no variant 'nope'" in out, out


def _wait_for_text(cluster, job, workdir, pattern, timeout, after=""):
    """Wait until the job's output matches ``pattern`` (searched after the text ``after``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out = cluster.job_output(job, workdir)
        tail = out.split(after, 1)[1] if after and after in out else ("" if after else out)
        if re.search(pattern, tail):
            return out
        if cluster.job_info(job).get("JobState") in FINAL_STATES:
            break
        time.sleep(0.5)
    cluster._cmd(["scancel", job], 10)
    pytest.fail(f"job {job}: no {pattern!r} in its output within {timeout} s "
                f"(state {cluster.job_info(job).get('JobState')})\n{cluster.job_output(job, workdir)}\n"
                f"{cluster.diagnostics()}")


def test_requeued_run_continues_from_checkpoint(cluster):
    """scontrol requeue of a running job: the job starts again and continues from the checkpoint."""
    work = cluster.root / "jobs" / "requeue"
    work.mkdir(parents=True, exist_ok=True)
    scene = work / "longbar.toml"
    # far longer than the test waits: the job is cancelled once it has restarted
    scene.write_text(_scene(end_time=1e5, interval=1e4, history_interval=1.0, checkpoint_interval=1.0))
    job = cluster.sbatch(JOBS / "slurm_run.sh", ["-n", "1", "--time=10"],
                         _job_env(CASE=scene, OUTDIR=work / "runs"), work)
    _wait_for_text(cluster, job, work, r"checkpoint step \d+ .*written", JOB_TIMEOUT)
    r = cluster._cmd(["scontrol", "requeue", job], 10)
    assert r.returncode == 0, f"scontrol requeue {job}: {r.stdout}{r.stderr}"
    out = _wait_for_text(cluster, job, work, r"restarted from .* at t = ", JOB_TIMEOUT, after="restart count 1")
    cluster._cmd(["scancel", job], 10)
    state, _, out = cluster.wait(job, work, 60)
    second = out.split("restart count 1", 1)[1]
    assert "restarting from its newest checkpoint" in second and "--restart" in second, out
    assert cluster.job_info(job).get("Restarts") == "1", out
