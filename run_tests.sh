#!/usr/bin/env bash
# The whole test suite: serial tests, then the MPI tests under 2, 3 and 4 ranks.
# Needs the set-up of ./setup.sh (the README's second command runs both).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
. .venv/bin/activate
export PYTHONFAULTHANDLER=1
# numba compiles each kernel once into its cache; warm it from one process so that the MPI
# ranks started below do not race writing the same cache entries (design.md section 8)
python -m pmpm.warmup
python -m pytest -q tests/unit tests/verification tests/integration "$@"
for n in 2 3 4; do
    echo "== MPI tests on $n ranks =="
    mpirun -n "$n" --oversubscribe --bind-to none python -m pytest -q -p no:cacheprovider tests/mpi
done
