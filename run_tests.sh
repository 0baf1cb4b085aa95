#!/usr/bin/env bash
# The whole test suite: serial tests, then the MPI tests under 2, 3 and 4 ranks, then the
# hard cases on 3 ranks. Needs the set-up of ./setup.sh (the README's second command runs both).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
. .venv/bin/activate
export PYTHONFAULTHANDLER=1
# numba compiles each kernel once into its cache; warm it from one process so that the MPI
# ranks started below do not race writing the same cache entries (design.md section 8)
python -m pmpm.warmup
serial=(tests/unit tests/verification tests/integration)
[ -d tests/hard ] && serial+=(tests/hard --ignore=tests/hard/mpi)
[ -d tests/slurm ] && serial+=(tests/slurm)
# the real-client tier: Debian's ParaView (installed by the test when missing, about 540 MB)
[ -d tests/paraview ] && serial+=(tests/paraview)
# the slowest tests are listed at the end, so that the suite's time can be watched (README: about 20 min)
python -m pytest -q -p no:cacheprovider --durations=15 "${serial[@]}" "$@"
echo "== serial tiers done after ${SECONDS} s =="
# under mpirun a test that hangs (ranks in different collectives) prints every rank's stacks
# after PMPM_MPI_TEST_TIMEOUT s and stops the tier (tests/conftest.py)
for n in 2 3 4; do
    echo "== MPI tests on $n ranks =="
    mpirun -n "$n" --oversubscribe --bind-to none python -m pytest -q --color=no -p no:cacheprovider --durations=5 tests/mpi
    echo "== done after ${SECONDS} s =="
done
if [ -d tests/hard/mpi ]; then
    echo "== hard cases on 3 ranks =="
    mpirun -n 3 --oversubscribe --bind-to none python -m pytest -q --color=no -p no:cacheprovider tests/hard/mpi
    echo "== done after ${SECONDS} s =="
fi
