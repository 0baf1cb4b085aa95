#!/bin/bash
# pmpm production run of one scene under Slurm:  mpirun --bind-to core -n $N pmpm $CASE
# The job's exit code is pmpm's (0 done, 2 bad input, 3 run went unstable / lost particles).
# A requeued job (scontrol requeue, node failure, preemption; see --requeue below) continues each
# run whose output already exists from its newest checkpoint (pmpm CASE --restart OUT.h5) and
# skips runs whose checkpoint is already at the end time. Checkpoints exist only when the scene's
# [output] sets checkpoint_interval (and when a run stops unstable); without one a requeued run
# starts over.
#
# Adapt the variables in the block below (each may also be set in the environment), then
#     bash jobs/slurm_run.sh     submits itself with the variables' values (sbatch options from
#                                NTASKS, TIME, PARTITION, ACCOUNT override the #SBATCH lines)
#     sbatch jobs/slurm_run.sh   submits with the #SBATCH lines as they are (keep them in step)
#
#SBATCH --job-name=pmpm
#SBATCH --ntasks=4
#SBATCH --time=02:00:00
#SBATCH --requeue
#SBATCH --open-mode=append
#SBATCH --output=pmpm-%j.out
##SBATCH --partition=compute
##SBATCH --account=myproject

# ---- edit these ---------------------------------------------------------------------------------
CASE="${CASE:-cases/portal_frame.toml}"  # scene file; relative paths are from the submit directory
VARIANT="${VARIANT:-}"                   # run only this [variants.<name>]; empty: every variant
NTASKS="${NTASKS:-4}"                    # MPI ranks (sbatch --ntasks when this script submits itself;
                                         # inside a job the allocation's task count is used)
TIME="${TIME:-02:00:00}"                 # wall-time limit when this script submits itself
PARTITION="${PARTITION:-}"               # empty: the cluster's default partition
ACCOUNT="${ACCOUNT:-}"                   # empty: your default account
PMPM_HOME="${PMPM_HOME:-}"               # pmpm checkout with .venv (./setup.sh); empty: this script's
                                         # checkout (bash jobs/...) or the submit directory (sbatch jobs/...)
MODULES="${MODULES:-}"                   # `module load` these first (e.g. "openmpi hdf5"); empty: none
OUTDIR="${OUTDIR:-runs}"                 # pmpm runs here and writes <stem>_results/ in it; relative
                                         # paths are from the submit directory
LAUNCHER="${LAUNCHER:-mpirun}"           # mpirun, or srun: `srun --mpi=pmix -n $N` (Slurm starts the
                                         # ranks itself; needs Slurm's PMIx plugin, `srun --mpi=list`)
# -------------------------------------------------------------------------------------------------

# Not inside a job yet: submit this script with the variables above.
if [ -z "${SLURM_JOB_ID:-}" ]; then
    here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
    PMPM_HOME="${PMPM_HOME:-$(dirname "$here")}"
    export CASE VARIANT NTASKS PMPM_HOME MODULES OUTDIR LAUNCHER
    opts=(--ntasks="$NTASKS" --time="$TIME" --export=ALL)
    [ -n "$PARTITION" ] && opts+=(--partition="$PARTITION")
    [ -n "$ACCOUNT" ] && opts+=(--account="$ACCOUNT")
    exec sbatch "${opts[@]}" "$0" "$@"
fi

# ---- inside the job (it starts in the submit directory, or in sbatch --chdir's) -----------------
PMPM_HOME="${PMPM_HOME:-${SLURM_SUBMIT_DIR:-$PWD}}"
if [ ! -f "$PMPM_HOME/.venv/bin/activate" ]; then
    echo "error: $PMPM_HOME/.venv/bin/activate not found: set PMPM_HOME to a pmpm checkout set up with ./setup.sh" >&2
    exit 2
fi
if [ -n "$MODULES" ]; then
    # shellcheck disable=SC2086
    module load $MODULES || exit 1
fi
# shellcheck disable=SC1091
. "$PMPM_HOME/.venv/bin/activate"
N="${SLURM_NTASKS:-$NTASKS}"
CASE="$(realpath -m "$CASE")"
mkdir -p "$OUTDIR" && cd "$OUTDIR" || exit 1
case "$LAUNCHER" in
    mpirun) launch=(mpirun --bind-to core -n "$N") ;;
    srun)   launch=(srun --mpi=pmix -n "$N") ;;
    *)      echo "error: LAUNCHER=$LAUNCHER: use mpirun or srun" >&2; exit 2 ;;
esac
echo "pmpm run: job ${SLURM_JOB_ID} (restart count ${SLURM_RESTART_COUNT:-0}) on ${SLURM_JOB_NODELIST:-$(hostname)}," \
     "$N rank(s), case $CASE${VARIANT:+ variant $VARIANT}, in $PWD"

run_pmpm() {  # run_pmpm ARGS...: one pmpm run on all ranks; returns pmpm's exit code
    echo "+ ${launch[*]} pmpm $*"
    "${launch[@]}" pmpm "$@" < /dev/null
}

# What is there already: per run (variant) "variant<TAB>fresh|restart|done<TAB>output<TAB>time".
# The names follow pmpm: <output.directory>/<stem>[_<variant>].h5, checkpoints <...>.ckpt[01].h5.
# A scene that cannot be read gives no plan, and pmpm itself then reports the bad input.
mapfile -t plan < <(python - "$CASE" "$VARIANT" <<'PY'
import os
import sys

try:
    from pmpm.scene.config import load_scene
    scenes = load_scene(sys.argv[1], sys.argv[2] or None)
except Exception as exc:  # noqa: BLE001 - pmpm reports it properly when it runs
    print(f"note: could not read {sys.argv[1]} ahead of the run: {exc}", file=sys.stderr)
    sys.exit(0)
import h5py

for s in scenes:
    out = os.path.join(s.output.directory, s.stem + (f"_{s.variant}" if s.variant else "") + ".h5")
    newest = None  # (step, time) of the newest complete checkpoint
    for i in (0, 1):
        try:
            with h5py.File(f"{out[:-3]}.ckpt{i}.h5", "r") as f:
                if bool(f.attrs.get("complete", False)) and "particles/id" in f:
                    newest = max(newest or (-1, 0.0), (int(f.attrs["step"]), float(f.attrs["time"])))
        except (OSError, KeyError, ValueError):
            pass
    if newest is None:
        state = "fresh"
        if os.path.exists(out):
            print(f"note: {out} exists but has no complete checkpoint: that run starts over", file=sys.stderr)
    elif newest[1] >= s.solver.end_time * (1 - 1e-9) or (s.solver.max_steps and newest[0] >= s.solver.max_steps):
        state = "done"
    else:
        state = "restart"
    print(s.variant or "-", state, out, "" if newest is None else repr(newest[1]), sep="\t")
PY
)

rc=0
if ! printf '%s\n' "${plan[@]}" | grep -qE $'\t(restart|done)\t'; then
    # Nothing to continue: one pmpm run of the scene (every variant, compared in one set of plots).
    run_pmpm "$CASE" ${VARIANT:+--variant "$VARIANT"}
    rc=$?
else
    outs=()
    ran=0
    for line in "${plan[@]}"; do
        IFS=$'\t' read -r variant state out t <<< "$line"
        outs+=("$out")
        vopt=()
        [ "$variant" != "-" ] && vopt=(--variant "$variant")
        case "$state" in
            done)    echo "pmpm run: $out is complete (checkpoint at t = $t): skipped" ;;
            restart) echo "pmpm run: $out: restarting from its newest checkpoint (t = $t)"
                     run_pmpm "$CASE" "${vopt[@]}" --restart "$out"; rc=$?; ran=1 ;;
            fresh)   run_pmpm "$CASE" "${vopt[@]}"; rc=$?; ran=1 ;;
        esac
        [ "$rc" -ne 0 ] && break
    done
    # Runs made one variant at a time plot one variant each: redraw the comparison of all of them.
    if [ "$rc" -eq 0 ] && [ "$ran" = 1 ] && [ "${#outs[@]}" -gt 1 ]; then
        mpirun -n 1 pmpm plot "${outs[@]}" -o "$(dirname "${outs[0]}")" < /dev/null \
            || echo "warning: could not redraw the comparison plots (pmpm plot)" >&2
    fi
fi
echo "pmpm run: exit $rc"
exit "$rc"
