#!/bin/bash
# The three-storey SAC frame (cases/frame_3storey.toml, issue 22) at its full resolution under
# Slurm: a thin wrapper over jobs/slurm_run.sh, which does the work (submission, restarts, exit
# code); only the case and the job's size are set here.
#     bash jobs/slurm_frame_3storey.sh     submits (NTASKS, TIME, VARIANT, ... from the environment)
#     sbatch jobs/slurm_frame_3storey.sh   submits with the #SBATCH lines below
#
# COST (an ESTIMATE, not a measured full run): 0.05 m cells, 2 x 2 particles per cell: 85,512
# particles; the stable step is 8.5e-6 s, so about 235,000 steps for each 2 s step-load variant
# (elastic, elastoplastic; ~176,000 per 1.5 s), 470,000 for ground_motion (4 s) and 1.76 million
# for northridge (15 s of the real record): 2.7 million steps in all. At the ~420-520 ns per
# particle-step measured here on one core (the lower figure the bare step, the higher pmpm's own
# "left ~78,000 s" after 300 steps of northridge, with its histories) that is ~2.3-2.7 core-hours
# per step-load variant, ~5 for ground_motion and ~18-22 for northridge, ~28-34 core-hours in
# all; the 8 ranks below make it ~4 h if the ranks scaled perfectly (they do not, and their
# scaling on this case is not measured: TIME leaves room for ~35% efficiency). One variant:
# VARIANT=elastic TIME=04:00:00 bash jobs/slurm_frame_3storey.sh. The case sets no
# checkpoint_interval: a requeued run starts over (see slurm_run.sh).
#
#SBATCH --job-name=pmpm-frame3
#SBATCH --ntasks=8
#SBATCH --time=12:00:00
#SBATCH --requeue
#SBATCH --open-mode=append
#SBATCH --output=pmpm-%j.out
##SBATCH --partition=compute
##SBATCH --account=myproject

# slurm_run.sh beside this script, or (sbatch runs a copy of this script from its spool
# directory) in the checkout PMPM_HOME names, or in the submit directory
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if [ -z "${PMPM_HOME:-}" ]; then
    if [ -f "$here/slurm_run.sh" ]; then PMPM_HOME="$(dirname "$here")"; else PMPM_HOME="${SLURM_SUBMIT_DIR:-$PWD}"; fi
fi
if [ ! -f "$PMPM_HOME/jobs/slurm_run.sh" ]; then
    echo "error: $PMPM_HOME/jobs/slurm_run.sh not found: set PMPM_HOME to the pmpm checkout" >&2
    exit 2
fi
export PMPM_HOME
export CASE="$PMPM_HOME/cases/frame_3storey.toml"   # absolute: the job may start elsewhere
export NTASKS="${NTASKS:-8}"
export TIME="${TIME:-12:00:00}"
exec bash "$PMPM_HOME/jobs/slurm_run.sh" "$@"
