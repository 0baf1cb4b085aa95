#!/bin/bash
# pmpm weak-scaling sweep under Slurm: `pmpm bench scaling --mode weak` for each rank count in
# RANKS, every rank keeping PARTICLES particles; each run's JSON line is appended to RESULTS.
# Then: python jobs/gather_scaling.py RESULTS -o OUTDIR   (table + plot; see docs/jobs.md)
#
# Adapt the variables in the block below (each may also be set in the environment), then
#     bash jobs/slurm_scaling_weak.sh     submits itself with the variables' values (sbatch options
#                                         from NTASKS, TIME, PARTITION, ACCOUNT override the lines below)
#     sbatch jobs/slurm_scaling_weak.sh   submits with the #SBATCH lines as they are
# Ask for as many tasks as the largest rank count (or set OVERSUBSCRIBE=1 to run more ranks than
# the allocation has cores: the work inflation stays meaningful, wall-clock figures do not).
#
#SBATCH --job-name=pmpm-weak
#SBATCH --ntasks=16
#SBATCH --time=00:30:00
#SBATCH --output=pmpm-weak-%j.out
#SBATCH --open-mode=append
##SBATCH --partition=compute
##SBATCH --account=myproject

# ---- edit these ---------------------------------------------------------------------------------
RANKS="${RANKS:-1 2 4 8 16}"          # rank counts of the sweep
PARTICLES="${PARTICLES:-100000}"      # particles PER RANK (weak scaling)
STEPS="${STEPS:-50}"                  # timed steps per repeat
REPEAT="${REPEAT:-3}"                 # repeats; the benchmark reports the median
OVERSUBSCRIBE="${OVERSUBSCRIBE:-0}"   # 1: allow more ranks than cores (mpirun --oversubscribe)
NTASKS="${NTASKS:-16}"                # tasks to ask for when this script submits itself (>= largest of RANKS)
TIME="${TIME:-00:30:00}"              # wall-time limit when this script submits itself
PARTITION="${PARTITION:-}"            # empty: the cluster's default partition
ACCOUNT="${ACCOUNT:-}"                # empty: your default account
PMPM_HOME="${PMPM_HOME:-}"            # pmpm checkout with .venv (./setup.sh); empty: this script's checkout
                                      # (bash jobs/...) or the submit directory (sbatch jobs/...)
MODULES="${MODULES:-}"                # `module load` these first (e.g. "openmpi hdf5"); empty: none
OUTDIR="${OUTDIR:-scaling}"           # run logs go here; relative paths are from the submit directory
RESULTS="${RESULTS:-}"                # JSON-lines file to append to; empty: OUTDIR/scaling_weak.jsonl
# -------------------------------------------------------------------------------------------------
MODE=weak

# Not inside a job yet: submit this script with the variables above.
if [ -z "${SLURM_JOB_ID:-}" ]; then
    here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
    PMPM_HOME="${PMPM_HOME:-$(dirname "$here")}"
    export RANKS PARTICLES STEPS REPEAT OVERSUBSCRIBE PMPM_HOME MODULES OUTDIR RESULTS
    opts=(--ntasks="$NTASKS" --time="$TIME" --export=ALL)
    [ -n "$PARTITION" ] && opts+=(--partition="$PARTITION")
    [ -n "$ACCOUNT" ] && opts+=(--account="$ACCOUNT")
    exec sbatch "${opts[@]}" "$0" "$@"
fi

# ---- inside the job -----------------------------------------------------------------------------
# (the job starts in the submit directory, or in sbatch --chdir's)
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
mkdir -p "$OUTDIR" || exit 1
OUTDIR="$(cd "$OUTDIR" && pwd)"
RESULTS="${RESULTS:-$OUTDIR/scaling_$MODE.jsonl}"

# Whether mpirun may place more ranks than cores is decided here, not by the environment
# (pmpm's .venv turns oversubscription on for its own tests).
if [ "$OVERSUBSCRIBE" = 1 ]; then
    export OMPI_MCA_rmaps_base_oversubscribe=1
    mpi_opts=(--oversubscribe --bind-to core:overload-allowed)
else
    unset OMPI_MCA_rmaps_base_oversubscribe
    mpi_opts=(--bind-to core)
fi

echo "pmpm scaling sweep ($MODE): job ${SLURM_JOB_ID:-?} on ${SLURM_JOB_NODELIST:-$(hostname)}, ${SLURM_NTASKS:-?} task(s);" \
     "ranks: $RANKS; $PARTICLES particles per rank, $STEPS steps x $REPEAT; results -> $RESULTS"
rc=0
for k in $RANKS; do
    log="$OUTDIR/scaling_${MODE}_${k}ranks.log"
    echo "== $k rank(s): mpirun ${mpi_opts[*]} -n $k pmpm bench scaling --mode $MODE --particles $PARTICLES --steps $STEPS --repeat $REPEAT"
    mpirun "${mpi_opts[@]}" -n "$k" pmpm bench scaling --mode "$MODE" --particles "$PARTICLES" \
        --steps "$STEPS" --repeat "$REPEAT" > "$log" 2>&1
    status=$?
    cat "$log"
    last="$(grep -a "^{" "$log" | tail -n 1)"   # the JSON line (a library may print escape codes after it)
    if [ "$status" -eq 0 ] && [ "${last:0:1}" = "{" ]; then
        printf '%s\n' "$last" >> "$RESULTS"
    else
        echo "error: the $k-rank run failed (exit $status); nothing appended (log: $log)" >&2
        [ "$rc" -eq 0 ] && rc=$(( status != 0 ? status : 1 ))
    fi
done
echo "pmpm scaling sweep ($MODE): done, exit $rc; gather with: python $PMPM_HOME/jobs/gather_scaling.py $RESULTS -o $OUTDIR"
exit "$rc"
