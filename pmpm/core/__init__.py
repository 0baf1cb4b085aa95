"""The core MPM step: the solver and its named phases (solver), the USF/USL/MUSL strategies
(schemes), the rank's grid window (grid), the particle arrays (particles), the B-spline shape
functions (shape) and the numba kernels with their NumPy reference twins (kernels)."""
