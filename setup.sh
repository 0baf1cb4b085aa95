#!/usr/bin/env bash
# Set up pmpm on a fresh Debian 12 machine (as root) or refresh an existing set-up. Idempotent.
#   - Open MPI and parallel HDF5 from Debian
#   - a virtual environment in ./.venv with mpi4py (binary wheel), numba, meshio, matplotlib, pytest,
#     scipy and scikit-fem (the portal frame's independent finite-element model in the tests)
#   - h5py built against Debian's parallel HDF5 (never in an isolated build: that compiles mpi4py, ~21 GB)
#   - PETSc 3.18 from Debian (petsc-dev: built against Debian's Open MPI, with MUMPS, hypre, SuperLU)
#     and petsc4py 3.18.5 compiled against it for the venv's numpy (the implicit integrator's
#     linear solver, docs/implicit.md; about 5 minutes of one core, once)
#   - pmpm installed in editable mode, numba's kernel cache warmed from one process
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"
venv="$here/.venv"

need_apt=0
for pkg in openmpi-bin libopenmpi-dev libhdf5-openmpi-dev pkg-config petsc-dev; do
    dpkg -s "$pkg" >/dev/null 2>&1 || need_apt=1
done
if [ "$need_apt" = 1 ]; then
    echo "setup: installing Open MPI and parallel HDF5 from Debian"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq openmpi-bin libopenmpi-dev libhdf5-openmpi-dev pkg-config python3-venv >/dev/null
    apt-get install -y -qq --no-install-recommends petsc-dev >/dev/null
fi

if [ ! -x "$venv/bin/python" ]; then
    echo "setup: creating $venv"
    python3 -m venv "$venv"
fi
py="$venv/bin/python"
pip="$py -m pip --disable-pip-version-check -q"
$pip install --upgrade pip >/dev/null
$pip install "numpy>=1.26,<2.4" "mpi4py>=4.0" "numba>=0.60" meshio matplotlib "pytest>=7" hypothesis scipy scikit-fem \
    Cython pkgconfig "setuptools>=77" wheel

if ! "$py" -c 'import h5py, sys; sys.exit(0 if h5py.get_config().mpi else 1)' 2>/dev/null; then
    echo "setup: building h5py against parallel HDF5 (about 2 minutes)"
    $pip uninstall -y h5py >/dev/null 2>&1 || true
    CC=mpicc HDF5_MPI=ON HDF5_PKGCONFIG_NAME=hdf5-openmpi \
        $pip install --no-binary=h5py --no-build-isolation --no-cache-dir h5py
fi
"$py" -c 'import h5py; assert h5py.get_config().mpi, "h5py was built without MPI"'

# petsc4py for Debian's PETSc (3.18): its sdist ships the Cython output, so only a C compile,
# against the venv's numpy (any numpy >= 1.25 builds for numpy 2 and 1.x alike). Debian's own
# python3-petsc4py is built for Debian's numpy 1.24 and cannot load with the venv's numpy 2.
# petsc4py 3.18's build script predates setuptools' current linker API, so it is built in a
# throw-away venv with setuptools < 70, then installed here as a wheel.
if ! "$py" -c 'import petsc4py; from petsc4py import PETSc' 2>/dev/null; then
    echo "setup: building petsc4py 3.18.5 against Debian's PETSc (about 5 minutes)"
    build="$(mktemp -d)"
    "$py" -m venv "$build/venv"
    numpy_version="$("$py" -c 'import numpy; print(numpy.__version__)')"
    "$build/venv/bin/python" -m pip --disable-pip-version-check -q install "setuptools<70" wheel "numpy==$numpy_version"
    PETSC_DIR=/usr/lib/petsc "$build/venv/bin/python" -m pip --disable-pip-version-check -q wheel \
        --no-build-isolation --no-deps --no-binary=petsc4py --no-cache-dir "petsc4py==3.18.5" -w "$build"
    $pip install --no-deps "$build"/petsc4py-*.whl
    rm -rf "$build"
fi
"$py" -c 'from petsc4py import PETSc; assert PETSc.Sys.getVersion()[:2] == (3, 18)'

$pip install --no-build-isolation --no-deps -e "$here"

# Open MPI refuses to run as root unless told; the venv's activate script says it once for every command.
if ! grep -q OMPI_ALLOW_RUN_AS_ROOT "$venv/bin/activate"; then
    cat >> "$venv/bin/activate" <<'ACT'
# pmpm: let Open MPI run as root (CI and containers run as root)
export OMPI_ALLOW_RUN_AS_ROOT=1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_rmaps_base_oversubscribe=1
ACT
fi

# Compile the numba kernels once, from one process, so that MPI ranks find a warm cache.
if [ -f "$here/pmpm/__init__.py" ]; then
    "$py" -m pmpm.warmup || { echo "setup: kernel warm-up failed" >&2; exit 1; }
fi
echo "setup: done ($("$py" -c 'import mpi4py, h5py, numba; import petsc4py; print("mpi4py", mpi4py.__version__, "h5py", h5py.__version__, "numba", numba.__version__, "petsc4py", petsc4py.__version__)'))"
