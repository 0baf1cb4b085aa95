#!/bin/bash
# pmpm production run of one scene under PBS Pro / OpenPBS:  mpirun --bind-to core -n $N pmpm $CASE
# The job's exit code is pmpm's (0 done, 2 bad input, 3 run went unstable / lost particles).
# A rerun job (qrerun, node failure; rerunnable: -r y below) continues each run whose output
# already exists from its newest checkpoint (pmpm CASE --restart OUT.h5) and skips runs whose
# checkpoint is already at the end time. Checkpoints exist only when the scene's [output] sets
# checkpoint_interval (and when a run stops unstable); without one a rerun starts over.
#
# Adapt the variables in the block below (each may also be set in the environment), then
#     bash jobs/pbs_run.sh     submits itself with the variables' values (qsub options from
#                              NODES, NTASKS, TIME, QUEUE, ACCOUNT override the #PBS lines)
#     qsub jobs/pbs_run.sh     submits with the #PBS lines as they are (keep them in step)
# Torque instead of PBS Pro: replace "select=1:ncpus=4:mpiprocs=4" by "nodes=1:ppn=4".
#
#PBS -N pmpm
#PBS -l select=1:ncpus=4:mpiprocs=4
#PBS -l walltime=02:00:00
#PBS -r y
#PBS -j oe
##PBS -q workq
##PBS -A myproject

# ---- edit these ---------------------------------------------------------------------------------
CASE="${CASE:-cases/portal_frame.toml}"  # scene file; relative paths are from the submit directory
VARIANT="${VARIANT:-}"                   # run only this [variants.<name>]; empty: every variant
NTASKS="${NTASKS:-4}"                    # MPI ranks (inside a job: one per line of $PBS_NODEFILE)
NODES="${NODES:-1}"                      # nodes to spread NTASKS over when this script submits itself
TIME="${TIME:-02:00:00}"                 # walltime when this script submits itself
QUEUE="${QUEUE:-}"                       # empty: the server's default queue
ACCOUNT="${ACCOUNT:-}"                   # empty: no -A (project / account string)
PMPM_HOME="${PMPM_HOME:-}"               # pmpm checkout with .venv (./setup.sh); empty: this script's
                                         # checkout (bash jobs/...) or the submit directory (qsub jobs/...)
MODULES="${MODULES:-}"                   # `module load` these first (e.g. "openmpi hdf5"); empty: none
OUTDIR="${OUTDIR:-runs}"                 # pmpm runs here and writes <stem>_results/ in it; relative
                                         # paths are from the submit directory
# -------------------------------------------------------------------------------------------------

# Not inside a job yet: submit this script with the variables above.
if [ -z "${PBS_JOBID:-}" ]; then
    here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
    PMPM_HOME="${PMPM_HOME:-$(dirname "$here")}"
    export CASE VARIANT NTASKS PMPM_HOME MODULES OUTDIR
    per_node=$(( (NTASKS + NODES - 1) / NODES ))
    opts=(-l "select=$NODES:ncpus=$per_node:mpiprocs=$per_node" -l "walltime=$TIME" -V)
    [ -n "$QUEUE" ] && opts+=(-q "$QUEUE")
    [ -n "$ACCOUNT" ] && opts+=(-A "$ACCOUNT")
    exec qsub "${opts[@]}" "$0"
fi

# ---- inside the job (PBS starts it in $HOME: go to the submit directory) ------------------------
cd "${PBS_O_WORKDIR:-$PWD}" || exit 1
PMPM_HOME="${PMPM_HOME:-$PWD}"
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
hostfile=()
if [ -n "${PBS_NODEFILE:-}" ] && [ -s "$PBS_NODEFILE" ]; then
    N="$(wc -l < "$PBS_NODEFILE")"
    hostfile=(--hostfile "$PBS_NODEFILE")   # harmless where Open MPI has PBS (tm) support, needed where not
else
    N="$NTASKS"
fi
CASE="$(realpath -m "$CASE")"
mkdir -p "$OUTDIR" && cd "$OUTDIR" || exit 1
launch=(mpirun --bind-to core "${hostfile[@]}" -n "$N")
echo "pmpm run: job ${PBS_JOBID} on $(hostname), $N rank(s), case $CASE${VARIANT:+ variant $VARIANT}, in $PWD"

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
